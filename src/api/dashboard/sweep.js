// The sweep page: one sweep, polled while it runs — its progress (runs by state, iterations), its
// specification, the table of its points with their jobs, the CSV download, cancel, and the charts
// (sweepplots.js, sweepw1.js) with their SVG/PNG downloads; links to its runs in the job list
// (#/?sweep=ID, their varying fields as columns) and to the compare page of its runs.

import { TERMINAL, api, download, hasToken } from './api.js';
import {
  badge, formatCount, formatParameter, formatRms, formatTime, h, instantiate, showMessage, updateProgress, withError,
} from './format.js';
import { MAX_COMPARED } from './list.js';
import { describeValue } from './sweepdata.js';
import { RmsChart } from './sweepplots.js';
import { W1Grid } from './sweepw1.js';

const POLL_MS = 2000;

/** Shows sweep `id` in `app` (the page's #app element); returns what leaving the page does. */
export function showSweep(app, id) {
  const { fragment, refs } = instantiate('tpl-sweep');
  app.replaceChildren(fragment);
  document.title = `Sweep ${id} · optimis`;

  const csv = `/v1/sweeps/${id}/table?format=csv`;
  refs.csv.href = csv;
  refs.csv.download = `sweep-${id}.csv`;
  const w1 = new W1Grid(id, refs['w1-plot'], refs['w1-note']);
  let charts = null; // one RmsChart per swept field, made with the first answer
  let rows = null; // point index → its <tr>
  let timer = null;
  let seq = 0; // only the latest request answers (a cancel reloads while a poll may be on its way)
  let alive = true;

  async function load() {
    clearTimeout(timer);
    const mine = ++seq;
    try {
      const sweep = await api(`/v1/sweeps/${id}`);
      if (!alive || mine !== seq) return;
      showMessage(refs['load-error'], '');
      render(sweep);
      if (TERMINAL.has(sweep.state)) return;
    } catch (error) {
      if (!alive || mine !== seq) return;
      if (error.status === 404) {
        showMessage(refs['load-error'], `Sweep ${id} does not exist (it may have been deleted).`);
        refs.body.hidden = true;
        return;
      }
      showMessage(refs['load-error'], `${error.message} Retrying every ${POLL_MS / 1000} s.`);
    }
    timer = setTimeout(load, POLL_MS);
  }

  function render(sweep) {
    refs.body.hidden = false;
    refs.id.textContent = sweep.id;
    refs.state.replaceChildren(badge(sweep.state));
    const running = !TERMINAL.has(sweep.state);
    refs.live.textContent = running ? `updating every ${POLL_MS / 1000} s` : '';
    document.title = `Sweep ${sweep.id} · ${sweep.state} · optimis`;
    updateProgress(refs.progress, sweep);
    renderRuns(refs, sweep);
    refs.cancel.hidden = !running;
    renderRunLinks(refs, sweep);
    if (!rows) {
      renderSpec(refs.spec, sweep);
      rows = makePointRows(refs, sweep);
      charts = sweep.fields.map((_, a) => new RmsChart(sweep, a));
      refs.plots.prepend(...charts.map((c) => c.card));
    }
    for (const point of sweep.points) fillPointRow(rows.get(point.index), point);
    for (const chart of charts) chart.update(sweep);
    w1.update(sweep);
  }

  refs.cancel.addEventListener('click', async () => {
    showMessage(refs['action-error'], '');
    refs.cancel.disabled = true;
    try {
      await api(`/v1/sweeps/${id}/cancel`, { method: 'POST' });
      if (alive) await load();
    } catch (error) {
      if (alive) showMessage(refs['action-error'], error.message);
    } finally {
      refs.cancel.disabled = false;
    }
  });
  // A server with a token refuses a plain link: the file is then fetched with the token.
  refs.csv.addEventListener('click', (event) => {
    if (!hasToken()) return; // the plain link works
    event.preventDefault();
    showMessage(refs['action-error'], '');
    download(csv, refs.csv.download)
      .catch((error) => alive && showMessage(refs['action-error'], `Cannot download the table: ${error.message}`));
  });
  load();

  return () => {
    alive = false;
    clearTimeout(timer);
    w1.destroy();
    for (const chart of charts ?? []) chart.destroy();
  };
}

/** Its runs in the job list (their varying fields as columns), and side by side when 2 to 8. */
function renderRunLinks(refs, sweep) {
  refs['runs-link'].href = `#/?sweep=${sweep.id}`;
  const jobs = [...new Set(sweep.points.map((p) => p.job_id).filter((j) => j !== null && j !== undefined))].sort((a, b) => a - b);
  refs['compare-link'].hidden = jobs.length < 2 || jobs.length > MAX_COMPARED;
  refs['compare-link'].href = `#/compare?ids=${jobs.join(',')}`;
}

function renderRuns(refs, sweep) {
  const p = sweep.progress;
  refs.runs.textContent = formatCount(p.runs);
  refs['point-count'].textContent = formatCount(sweep.points.length);
  refs.created.textContent = formatTime(sweep.created_at);
  refs['runs-by-state'].replaceChildren(...Object.entries(p.runs_by_state).map(([state, n]) =>
    h('span', { class: 'run-count', 'data-state': state }, badge(state), ` ${formatCount(n)}`)));
}

function renderSpec(dl, sweep) {
  const { spec } = sweep;
  const rows = [['Mode', spec.mode === 'zip' ? 'zip: the i-th values of all axes together' : 'grid: every combination']];
  for (const axis of spec.axes) {
    const by = axis.by === 'prediction' ? ' (predicted from one run)' : '';
    rows.push([h('code', {}, axis.field), `${axis.values.map((v) => describeValue(v, Infinity)).join(', ')}${by}`]);
  }
  rows.push(['Base job', h('code', {}, JSON.stringify(spec.base))]);
  dl.replaceChildren(...rows.map(([term, value]) => h('div', {}, h('dt', {}, term), h('dd', {}, value))));
}

/** The points table's header and one row per point, filled in by `fillPointRow` on every answer. */
function makePointRows(refs, sweep) {
  refs['points-head'].replaceChildren(h('tr', {},
    h('th', { scope: 'col', class: 'num' }, 'Point'),
    sweep.fields.map((f) => h('th', { scope: 'col' }, h('code', {}, f))),
    h('th', { scope: 'col' }, 'Job'),
    h('th', { scope: 'col' }, 'State'),
    h('th', { scope: 'col' }, 'Figures'),
    h('th', { scope: 'col', class: 'num' }, 'Recommended RMS % ± SE')));
  const rows = new Map(sweep.points.map((point) => [point.index, h('tr', { 'data-point': point.index },
    h('td', { class: 'num' }, String(point.index)),
    sweep.fields.map((f) => h('td', { title: describeValue(point.values[f], Infinity) }, describeValue(point.values[f]))),
    h('td'), h('td'), h('td'), h('td', { class: 'num' }))]));
  refs['points-rows'].replaceChildren(...rows.values());
  return rows;
}

function fillPointRow(tr, point) {
  const cells = [...tr.cells];
  const [job, state, source, rms] = cells.slice(-4);
  const link = point.job_id === null ? '—' : `#${point.job_id}`;
  if (job.textContent !== link) {
    job.replaceChildren(point.job_id === null ? '—' : h('a', { href: `#/jobs/${point.job_id}` }, link));
  }
  const stateText = point.state ?? 'deleted';
  if (state.textContent !== stateText) state.replaceChildren(point.state ? badge(point.state) : 'deleted');
  const f = point.figures;
  source.textContent = f ? `${f.source}${f.partial ? ', partial' : ''} · ${formatCount(f.iterations)} iterations` : '—';
  const rec = f?.recommended;
  const chosen = rec && f.noise_table.find((r) => r.strategy === rec.strategy);
  if (chosen && chosen.rms_percent !== null) {
    // A per-path strategy has no λ (and no weights table).
    const how = rec.lambda === null || rec.lambda === undefined ? 'per path' : `λ = ${formatParameter(rec.lambda)}`;
    rms.textContent = `${withError(chosen.rms_percent, chosen.rms_percent_stderr, formatRms)} (${chosen.strategy}, ${how})`;
    rms.title = rec.reason ?? '';
  } else {
    rms.textContent = f?.error ? 'no weights' : '—';
    rms.title = f?.error ?? '';
  }
}
