// The compare page, #/compare?ids=1,2,… (2 to 8 jobs): their noise tables side by side (RMS % ± SE
// per strategy, one column per job, under each job's key parameters) and their recommended w₁
// against r₃ overlaid (one series per job, ± 1 SE bars, an r₂ bin selector, the spots' r₃ = a),
// with CSV, SVG and PNG downloads. Polled while a job still runs. The paper's "weights are not
// local" comparison is a spot job beside a uniform one (preset uniform-illumination).

import { TERMINAL, api } from './api.js';
import { errorBars, extent, guides } from './chartkit.js';
import { chartDownloads } from './chartfiles.js';
import { csvButton } from './csv.js';
import {
  badge, fixed, formatCount, formatLuminance, formatParameter, formatRms, h, instantiate, showMessage, withError,
} from './format.js';
import { MAX_COMPARED } from './list.js';
import { PlotSlot, STRATEGIES, binsOf, figure2, formatInterval, spotGuide, weightRange } from './plots.js';

const POLL_MS = 3000;
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
  const slot = new PlotSlot(refs['w1-plot'], `Recommended w₁ against r₃, jobs ${ids.join(', ')}`);
  const name = `optimis-compare-${ids.join('-')}`;
  let entries = []; // per id: { id, job, result, error }
  let r2 = null; // the lower edge of the r₂ bin shown
  let timer = null;
  let alive = true;

  refs['table-downloads'].append(
    csvButton('Compare table (CSV)', `${name}.csv`, () => compareCsv(entries)),
    csvButton('Weights (CSV)', `${name}-weights.csv`, () => weightsCsv(entries)));
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
        return { id, job, result };
      } catch (error) {
        return { id, job: null, result: null, error: error.status === 404 ? `Job ${id} does not exist.` : error.message };
      }
    }));
    if (!alive) return;
    refs.body.hidden = false;
    const problems = entries.filter((e) => e.error).map((e) => e.error);
    showMessage(refs['load-error'], problems.join(' '));
    renderTable();
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
    const param = (key, label, value) => h('tr', { 'data-param': key }, h('th', { scope: 'row' }, label),
      shown.map((e) => h('td', { class: 'num' }, value(e))));
    const symbol = (name, sub) => h('var', {}, name, sub ? h('sub', {}, sub) : null);
    refs.params.replaceChildren(
      param('preset', 'Preset', (e) => e.job.spec.preset),
      param('illumination', 'Illumination', (e) => describeLight(e.job.spec.scene.illumination)),
      param('engine', 'Engine', (e) => e.job.spec.engine || 'brute'),
      param('light_paths', ['Light paths ', symbol('N', 'F')], (e) => formatCount(e.job.spec.light_paths)),
      param('camera_paths', ['Camera paths ', symbol('N', 'B')], (e) => formatCount(e.job.spec.camera_paths)),
      param('merge_radius', ['Merge radius ', symbol('R')], (e) => formatParameter(e.job.spec.merge_radius)),
      param('iterations', 'Iterations', (e) => (e.result ? `${formatCount(e.result.iterations)}${e.result.partial ? ' (partial)' : ''}` : '—')),
      param('seed', 'Seed', (e) => String(e.job.spec.seed)),
      param('reference', 'Reference L·10⁵', (e) => (e.job.reference_luminance === null ? '—' : formatLuminance(e.job.reference_luminance))));
    const strategies = STRATEGIES.filter((s) => shown.some((e) => e.result?.noise_table.some((r) => r.strategy === s)));
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
          recommended ? h('span', { class: 'recommended-mark', title: 'The weights drawn below' }, 'recommended') : null);
      }))));
  }

  /** The r₂ bins of the first job with weights; keeps the chosen one while it exists. */
  function renderSelector() {
    const weights = entries.find((e) => e.result?.weights.length)?.result.weights ?? [];
    const bins = binsOf(weights, 'r2');
    if (r2 === null || !bins.some((b) => b[0] === r2)) r2 = bins[0]?.[0] ?? null;
    const options = bins.map((b) => h('option', { value: b[0] }, `r₂ ∈ ${formatInterval(b)}`));
    if (refs.r2.options.length !== options.length) refs.r2.replaceChildren(...options);
    refs.r2.value = String(r2);
    refs['r2-label'].hidden = bins.length < 2;
  }

  function drawOverlay() {
    const withWeights = entries.filter((e) => e.result?.weights.length);
    if (withWeights.length === 0) {
      slot.clear('No weights yet: they appear with the first checkpoint of a job.');
      showMessage(refs['w1-note'], '');
      return;
    }
    const figures = withWeights.map((e) => ({ e, fig: figure2(e.result.weights) }));
    const x = [...new Set(figures.flatMap(({ fig }) => fig.x))].sort((a, b) => a - b);
    const series = figures.map(({ e, fig }) => {
      const bin = fig.series.find((s) => s.r2[0] === r2) ?? fig.series[0];
      const at = new Map(fig.x.map((v, i) => [v, i]));
      return { e, y: x.map((v) => (at.has(v) ? bin.y[at.get(v)] : null)), err: x.map((v) => (at.has(v) ? bin.err[at.get(v)] : null)) };
    });
    const colorOf = (e) => JOB_COLORS[entries.filter((n) => n.job).indexOf(e) % JOB_COLORS.length];
    slot.bars = series.map((s) => ({ err: s.err, color: colorOf(s.e) }));
    const spots = new Map(); // a → the ids of the jobs lit by a spot of that radius
    for (const { e } of series) {
      for (const g of spotGuide(e.job.spec.scene.illumination)) spots.set(g.value, [...(spots.get(g.value) ?? []), e.id]);
    }
    slot.guides = { x: [...spots].map(([a, lit]) => ({ value: a, label: `a = ${formatParameter(a)} (#${lit.join(', #')})` })), y: [] };
    slot.draw({
      series: [{ label: 'r₃', value: (u, v) => (v === null ? '—' : formatParameter(v)) },
        ...series.map((s, k) => ({
          label: `#${s.e.id} ${s.e.job.spec.preset} (${describeLight(s.e.job.spec.scene.illumination)})`,
          stroke: slot.bars[k].color, width: 2, points: { show: true, size: 5 },
          value: (u, v, si, i) => {
            const err = slot.bars[k]?.err[i];
            return v === null ? '—' : `${fixed(v, 3)}${err === null || err === undefined ? '' : ` ± ${fixed(err, 3)}`}`;
          },
        }))],
      scales: { x: { time: false }, y: { range: (u, min, max) => weightRange(u, ...(extent(u, slot, false) ?? [min, max])) } },
      axes: [{ label: `r₃ (cell midpoint), r₂ ∈ ${formatInterval(binsOf(withWeights[0].result.weights, 'r2').find((b) => b[0] === r2))}` }, { label: 'w₁' }],
      plugins: [errorBars(slot), guides(slot)],
    }, [x, ...series.map((s) => s.y)]);
    const missing = entries.length - withWeights.length;
    const kinds = new Set(withWeights.map((e) => e.job.spec.scene.illumination.kind));
    const parts = [`Each job's recommended weights (first φ bin); bars: ± 1 jackknife standard error${spots.size ? '; dashed: the spot radius a' : ''}. The open tail cell of r₃ is left out.`];
    if (missing) parts.push(`${missing} job${missing > 1 ? 's have' : ' has'} no weights yet.`);
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

/** The compare table as CSV: one row per job and strategy, with the job's key parameters. */
function compareCsv(entries) {
  const columns = ['job_id', 'preset', 'illumination', 'spot_a', 'engine', 'light_paths', 'camera_paths', 'merge_radius', 'iterations', 'seed',
    'reference_luminance_model_units', 'strategy', 'luminance_model_units', 'luminance_stderr_model_units', 'rms_percent', 'rms_percent_stderr',
    'in_sample', 'recommended', 'error'];
  const rows = entries.filter((e) => e.job && e.result).flatMap(({ job, result }) => result.noise_table.map((row) => ({
    job_id: job.id,
    preset: job.spec.preset,
    illumination: job.spec.scene.illumination.kind,
    spot_a: job.spec.scene.illumination.kind === 'spot' ? job.spec.scene.illumination.a : null,
    engine: job.spec.engine || 'brute',
    light_paths: job.spec.light_paths,
    camera_paths: job.spec.camera_paths,
    merge_radius: job.spec.merge_radius,
    iterations: result.iterations,
    seed: job.spec.seed,
    reference_luminance_model_units: result.reference_luminance,
    strategy: row.strategy,
    luminance_model_units: row.luminance,
    luminance_stderr_model_units: row.luminance_stderr,
    rms_percent: row.rms_percent,
    rms_percent_stderr: row.rms_percent_stderr,
    in_sample: row.in_sample,
    recommended: result.recommended?.strategy === row.strategy,
    error: row.error,
  })));
  return { columns, rows };
}

/** Every compared job's recommended weights, one row per job and cell. */
function weightsCsv(entries) {
  const columns = ['job_id', 'r2_lo', 'r2_hi', 'r3_lo', 'r3_hi', 'phi_lo', 'phi_hi', 'w0', 'w1', 'w2', 'w1_stderr', 'samples', 'status'];
  const rows = entries.filter((e) => e.result).flatMap(({ id, result }) => result.weights.map((w) => ({
    job_id: id, r2_lo: w.r2[0], r2_hi: w.r2[1], r3_lo: w.r3[0], r3_hi: w.r3[1], phi_lo: w.phi[0], phi_hi: w.phi[1],
    w0: w.w0, w1: w.w1, w2: w.w2, w1_stderr: w.w1_stderr, samples: w.samples, status: w.status,
  })));
  return { columns, rows };
}
