// The compare page, #/compare?ids=1,2,… (2 to 8 jobs): their noise tables side by side (RMS % ± SE
// per strategy, one column per job, under each job's key parameters, the recommended and unstable
// rows marked), the server's comparison against the first job (ratios and differences ± SE, z),
// and their weights tables' w₁ against r₃ overlaid (one series per job, ± 1 SE bars,
// open markers for cells without a data SE, an r₂ bin selector, the spots' r₃ = a): each job's
// recommended table, or — when it recommends a per-path strategy — its table optimum at
// optimal_cv's λ, labelled as not recommended (fig2.js). CSV, SVG and PNG downloads. Polled while a
// job still runs. The paper's "weights are not local" comparison is a spot job beside a uniform
// one (preset uniform-illumination).

import { TERMINAL, api } from './api.js';
import { axis, legendValue } from './axes.js';
import { errorBars, extent, guides, markers } from './chartkit.js';
import { chartDownloads } from './chartfiles.js';
import { csvButton } from './csv.js';
import { compareCsv, compareWeightsCsv } from './csvtables.js';
import { figure2, figureSource, tableOptimumLambda, weightValue } from './fig2.js';
import {
  badge, fixed, formatCount, formatLuminance, formatParameter, formatRms, h, instantiate, showMessage, withError,
} from './format.js';
import { MAX_COMPARED } from './list.js';
import { PlotSlot, binsOf, formatInterval, spotGuide, strategiesIn, weightRange } from './plots.js';
import { fieldLabel, flattenSpec, formatField, varyingFields } from './specfields.js';

const POLL_MS = 3000;
// The parameters every comparison shows, varying or not; any other field is shown when it differs.
const ALWAYS_SHOWN = ['engine', 'light_paths', 'camera_paths', 'merge_radius', 'scene.l2', 'scene.l3', 'scene.beta_deg', 'seed'];
const JOB_COLORS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf'];

/** The job ids of `?ids=1,2,…`, or a message saying what is wrong with them. */
export function parseIds(query) {
  const text = new URLSearchParams(query).get('ids') ?? '';
  const ids = text.split(',').map((s) => s.trim()).filter(Boolean);
  if (!ids.every((s) => /^\d+$/.test(s) && Number(s) > 0)) return { error: `“${text}” is not a list of job ids such as 1,2.` };
  const unique = [...new Set(ids.map(Number))];
  if (unique.length < 2 || unique.length > MAX_COMPARED) {
    return { error: `Compare 2 to ${MAX_COMPARED} different jobs (got ${unique.length}). Tick them in the job list.` };
  }
  return { ids: unique };
}

/** `v ± se` (scaled, three decimals), or — when the figure is missing. */
const plusMinus = (v, se, scale = 1) => (v === null || v === undefined ? '—'
  : withError(v * scale, se === null || se === undefined ? null : se * scale, (x) => fixed(x, 3)));

/** The illumination in a few words: `spot a = 0.02`, `uniform`. */
const describeLight = (ill) => (ill.kind === 'spot' ? `spot a = ${formatParameter(ill.a)}` : ill.kind);

/** Shows the jobs of the query `?ids=…` in `app`; returns what leaving the page does. */
export function showCompare(app, query) {
  const { fragment, refs } = instantiate('tpl-compare');
  app.replaceChildren(fragment);
  const parsed = parseIds(query);
  document.title = 'Compare · optimis';
  if (parsed.error) {
    showMessage(refs['load-error'], parsed.error);
    return () => {};
  }
  const { ids } = parsed;
  refs.title.textContent = ids.map((id) => `#${id}`).join(', ');
  document.title = `Compare ${ids.join(', ')} · optimis`;
  const slot = new PlotSlot(refs['w1-plot'], `w₁ against r₃ of each job's recommended table (or table optimum), jobs ${ids.join(', ')}`);
  const name = `optimis-compare-${ids.join('-')}`;
  let entries = []; // per id: { id, job, result, figure (fig2.js's figureSource), error }
  const optima = new Map(); // per id: the table optimum fetched last, { key, value }
  let r2 = null; // the lower edge of the r₂ bin shown
  let timer = null;
  let alive = true;

  refs['table-downloads'].append(
    csvButton('Compare table (CSV)', `${name}.csv`, () => compareCsv(entries)),
    csvButton('Weights (CSV)', `${name}-weights.csv`, () => compareWeightsCsv(entries)));
  refs['w1-downloads'].append(chartDownloads(slot, () => `${name}-w1`));
  refs.r2.addEventListener('change', () => {
    r2 = Number(refs.r2.value);
    drawOverlay();
  });

  async function load() {
    clearTimeout(timer);
    entries = await Promise.all(ids.map(async (id) => {
      try {
        const job = await api(`/v1/jobs/${id}`);
        const result = job.progress.iterations_checkpointed > 0 ? await api(`/v1/jobs/${id}/result`).catch(() => null) : null;
        return { id, job, result, figure: result ? figureSource(result, await tableOptimum(id, result, optima), true) : null };
      } catch (error) {
        return { id, job: null, result: null, error: error.status === 404 ? `Job ${id} does not exist.` : error.message };
      }
    }));
    if (!alive) return;
    refs.body.hidden = false;
    const problems = entries.filter((e) => e.error).map((e) => e.error);
    showMessage(refs['load-error'], problems.join(' '));
    renderTable();
    await renderRatios();
    if (!alive) return;
    renderSelector();
    drawOverlay();
    if (entries.some((e) => e.job && !TERMINAL.has(e.job.state))) timer = setTimeout(load, POLL_MS);
  }

  function renderTable() {
    const shown = entries.filter((e) => e.job);
    refs.head.replaceChildren(h('tr', {}, h('th', { scope: 'col' }, 'Job'),
      shown.map((e, k) => h('th', { scope: 'col', class: 'num', 'data-job': e.id },
        h('span', { class: 'swatch', style: { background: JOB_COLORS[k % JOB_COLORS.length] } }),
        h('a', { href: `#/jobs/${e.id}` }, `#${e.id}`), ' ', badge(e.job.state)))));
    // The spec's fields: name and notes, the key parameters always, then every other field that
    // differs between the jobs (specfields.js); a row whose value differs is marked `varying`.
    const specs = shown.map((e) => e.job.spec);
    const varying = new Set(varyingFields(specs));
    const flat = specs.map(flattenSpec);
    const param = (key, label, value, differs = varying.has(key), cell = 'num') => h('tr',
      { 'data-param': key, class: differs ? 'varying' : null, title: differs ? 'Differs between these jobs' : null },
      h('th', { scope: 'row' }, label), shown.map((e, k) => h('td', { class: cell }, value(e, k))));
    const field = (path) => param(path, fieldLabel(path), (e, k) => formatField(path, flat[k].get(path)));
    const text = (key) => (e) => e.job.spec[key] ?? '—';
    const differ = (key) => new Set(specs.map((s) => s[key] ?? '')).size > 1;
    refs.params.replaceChildren(...[
      // Names and notes are prose: they wrap in their column rather than widen the table.
      param('name', 'Name', text('name'), differ('name'), 'prose'),
      specs.some((s) => s.notes) ? param('notes', 'Notes', text('notes'), differ('notes'), 'prose') : null,
      field('preset'),
      param('illumination', 'Illumination', (e) => describeLight(e.job.spec.scene.illumination),
        [...varying].some((p) => p.startsWith('scene.illumination'))),
      ...ALWAYS_SHOWN.map(field),
      ...[...varying].filter((p) => !ALWAYS_SHOWN.includes(p) && p !== 'preset' && !p.startsWith('scene.illumination')).map(field),
      param('iterations_done', 'Iterations done', (e) => (e.result ? `${formatCount(e.result.iterations)}${e.result.partial ? ' (partial)' : ''}` : '—'), false),
      param('reference', 'Reference L·10⁵', (e) => (e.job.reference_luminance === null ? '—' : formatLuminance(e.job.reference_luminance)), false),
    ].filter(Boolean));
    const strategies = strategiesIn(shown.map((e) => e.result?.noise_table ?? []));
    refs.rows.replaceChildren(...strategies.map((s) => h('tr', { 'data-strategy': s },
      h('th', { scope: 'row' }, h('code', {}, s)),
      shown.map((e) => {
        const row = e.result?.noise_table.find((r) => r.strategy === s);
        const recommended = e.result?.recommended?.strategy === s;
        if (!row) return h('td', { class: 'num' }, e.result ? '—' : 'no results yet');
        if (row.error) return h('td', { class: 'num row-error', title: row.error }, 'no fit');
        return h('td', { class: `num${recommended ? ' recommended-cell' : ''}`, 'data-job': e.id },
          withError(row.rms_percent, row.rms_percent_stderr, formatRms),
          row.in_sample ? h('span', { class: 'in-sample-mark', title: 'Fitted and scored on the same iterations: optimistic' }, 'in-sample') : null,
          row.unstable ? h('span', { class: 'unstable-mark', title: 'Its fitted weights change from fold to fold by more than 0.25: never recommended' }, 'unstable') : null,
          recommended ? h('span', { class: 'recommended-mark', title: e.result.recommended.reason ?? 'The recommended row' }, 'recommended') : null);
      }))));
  }

  /**
   * The server's comparison (`GET /v1/compare`): per strategy and later job, L and RMS against
   * the first job's — ratios and the difference of L, each ± its standard error, and z.
   */
  async function renderRatios() {
    const ready = entries.filter((e) => e.result);
    if (ready.length < 2 || ready[0].id !== ids[0]) {
      refs['ratios-head'].replaceChildren();
      refs['ratios-rows'].replaceChildren();
      showMessage(refs['ratios-note'], `The first job (#${ids[0]}) and at least one other need results to compare against it.`);
      return;
    }
    let comparison;
    try {
      comparison = await api(`/v1/compare?ids=${ready.map((e) => e.id).join(',')}`);
    } catch (error) {
      showMessage(refs['ratios-note'], error.message);
      return;
    }
    const others = comparison.runs.slice(1);
    refs['ratios-head'].replaceChildren(h('tr', {}, h('th', { scope: 'col' }, 'Strategy'), h('th', { scope: 'col' }, 'Job'),
      h('th', { scope: 'col', class: 'num' }, 'L / L₁ ± SE'), h('th', { scope: 'col', class: 'num' }, 'ΔL·10⁵ ± SE'),
      h('th', { scope: 'col', class: 'num' }, 'z'), h('th', { scope: 'col', class: 'num' }, 'RMS / RMS₁ ± SE')));
    refs['ratios-rows'].replaceChildren(...comparison.strategies.flatMap((s) => s.runs.slice(1).map((f, k) => h('tr',
      { 'data-strategy': s.strategy, 'data-job': ready[k + 1].id },
      k === 0 ? h('th', { scope: 'row', rowspan: others.length }, h('code', {}, s.strategy), s.in_sample ? ' (in-sample)' : '') : null,
      h('td', {}, `#${ready[k + 1].id}`),
      h('td', { class: 'num', 'data-col': 'luminance-ratio' }, plusMinus(f.luminance_ratio, f.luminance_ratio_stderr)),
      h('td', { class: 'num', 'data-col': 'luminance-difference' },
        plusMinus(f.luminance_difference, f.luminance_difference_stderr, 1e5)),
      h('td', { class: 'num', 'data-col': 'z' }, f.z === null ? '—' : fixed(f.z, 2)),
      h('td', { class: 'num', 'data-col': 'rms-ratio' }, plusMinus(f.rms_ratio, f.rms_ratio_stderr))))));
    showMessage(refs['ratios-note'], comparison.notes.join(' '));
  }

  /** The r₂ bins of the first job with weights; keeps the chosen one while it exists. */
  function renderSelector() {
    const weights = entries.find((e) => e.figure?.weights)?.figure.weights ?? [];
    const bins = binsOf(weights, 'r2');
    if (r2 === null || !bins.some((b) => b[0] === r2)) r2 = bins[0]?.[0] ?? null;
    const options = bins.map((b) => h('option', { value: b[0] }, `r₂ ∈ ${formatInterval(b)}`));
    if (refs.r2.options.length !== options.length) refs.r2.replaceChildren(...options);
    refs.r2.value = String(r2);
    refs['r2-label'].hidden = bins.length < 2;
  }

  function drawOverlay() {
    const withWeights = entries.filter((e) => e.figure?.weights);
    // Why a job has no table to draw (fig2.js's message), or that it has no results yet.
    const missing = entries.filter((e) => e.job && !e.figure?.weights).map((e) => `#${e.id}: ${e.figure?.message ?? 'no results yet.'}`);
    if (withWeights.length === 0) {
      slot.clear(entries.some((e) => e.result) ? 'No weights table to draw.' : 'No weights yet: they appear with the first checkpoint of a job.');
      showMessage(refs['w1-note'], missing.join(' '));
      return;
    }
    const figures = withWeights.map((e) => ({ e, fig: figure2(e.figure.weights) }));
    const x = [...new Set(figures.flatMap(({ fig }) => fig.x))].sort((a, b) => a - b);
    const series = figures.map(({ e, fig }) => {
      const bin = fig.series.find((s) => s.r2[0] === r2) ?? fig.series[0];
      const at = new Map(fig.x.map((v, i) => [v, i]));
      const pick = (list, none) => x.map((v) => (at.has(v) ? list[at.get(v)] : none));
      return { e, y: pick(bin.y, null), err: pick(bin.err, null), open: pick(bin.open, false) };
    });
    const colorOf = (e) => JOB_COLORS[entries.filter((n) => n.job).indexOf(e) % JOB_COLORS.length];
    slot.bars = series.map((s) => ({ err: s.err, color: colorOf(s.e) }));
    slot.markers = series.map((s) => ({ open: s.open, color: colorOf(s.e) }));
    const open = series.reduce((n, s) => n + s.open.filter((o, i) => o && s.y[i] !== null).length, 0);
    slot.notes = open ? [{ marker: 'open', text: 'open: no data SE (smoothed: set by its neighbours through λ), no bar' }] : [];
    const spots = new Map(); // a → the ids of the jobs lit by a spot of that radius
    for (const { e } of series) {
      for (const g of spotGuide(e.job.spec.scene.illumination)) spots.set(g.value, [...(spots.get(g.value) ?? []), e.id]);
    }
    slot.guides = { x: [...spots].map(([a, lit]) => ({ value: a, label: `a = ${formatParameter(a)} (#${lit.join(', #')})` })), y: [] };
    slot.draw({
      series: [{ label: 'r₃', value: legendValue(formatParameter) },
        ...series.map((s, k) => ({
          label: `#${s.e.id} ${s.e.job.spec.preset} (${describeLight(s.e.job.spec.scene.illumination)})${describeTable(s.e.figure)}`,
          stroke: slot.bars[k].color, width: 2, points: { show: false }, value: weightValue(slot, k),
        }))],
      // From r₃ = 0 to the last finite cell's edge, so that the ticks start at 0.
      scales: { x: { time: false, range: (u, min, max) => [0, Math.max(max, ...figures.map(({ fig }) => fig.edge ?? max))] },
        y: { range: (u, min, max) => weightRange(u, ...(extent(u, slot, false) ?? [min, max])) } },
      axes: [axis({ label: `r₃ (cell midpoint), r₂ ∈ ${formatInterval(binsOf(withWeights[0].figure.weights, 'r2').find((b) => b[0] === r2))}` }),
        axis({ label: 'w₁' })],
      plugins: [errorBars(slot), markers(slot), guides(slot)],
    }, [x, ...series.map((s) => s.y)]);
    const kinds = new Set(withWeights.map((e) => e.job.spec.scene.illumination.kind));
    const parts = [`Each job's recommended weights table (first φ bin) or, where a per-path strategy is recommended, its table optimum at optimal_cv's λ, drawn for reference and labelled "table optimum, not recommended"; a stacked table is its table part T₁. Bars: ± 1 jackknife standard error${open ? '; open markers: cells without a data standard error (smoothed), no bars' : ''}${spots.size ? '; dashed: the spot radius a' : ''}. The open tail cell of r₃ is left out.`];
    parts.push(...missing);
    // The paper's closing comparison: the same join path gets different weights under different light.
    if (kinds.has('spot') && kinds.has('uniform')) parts.push('A spot and a uniform light: where their w₁ differ at the same r₃, the optimal weight of a join path depends on the light elsewhere — the paper\'s "weights are not local".');
    showMessage(refs['w1-note'], parts.join(' '));
  }

  load();
  return () => {
    alive = false;
    clearTimeout(timer);
    slot.destroy();
  };
}

/**
 * The table optimum of job `id` when its `result` recommends a per-path strategy (fig2.js):
 * { result } or { error }; null when not wanted. Kept in `optima` until the iterations or λ change.
 */
async function tableOptimum(id, result, optima) {
  const lambda = tableOptimumLambda(result);
  if (lambda === null) return null;
  const key = `${result.iterations}:${result.partial}:${lambda}`;
  if (optima.get(id)?.key !== key) {
    const value = await api(`/v1/jobs/${id}/result?lambda=${lambda}`).then((optimum) => ({ result: optimum }), (error) => ({ error: error.message }));
    optima.set(id, { key, value });
  }
  return optima.get(id).value;
}

/** Which table of a job the overlay draws, after its name in the legend. */
function describeTable(figure) {
  if (figure.kind === 'table-optimum') return `: table optimum (optimal_cv, λ = ${formatParameter(figure.lambda)}), not recommended`;
  return `: recommended ${figure.strategy}${figure.heuristics.length ? ' (table part)' : ''}`;
}
