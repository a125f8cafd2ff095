// The sweep list page: one page of sweeps (newest first), polled, with paging. A sweep is created
// through the API (POST /v1/sweeps); its page is sweep.js.

import { api } from './api.js';
import { badge, formatCount, formatShortTime, formatTime, h, instantiate, progressBar, showMessage, updateProgress } from './format.js';

const PAGE_SIZE = 20;
const POLL_MS = 3000;

// Kept across page changes so that coming back from a sweep shows the same page of the list.
const listView = { cursors: [null] };

/** Shows the sweep list in `app` (the page's #app element); returns what leaving the page does. */
export function showSweeps(app) {
  const { fragment, refs } = instantiate('tpl-sweeps');
  app.replaceChildren(fragment);
  document.title = 'Sweeps · optimis';

  let nextCursor = null;
  let timer = null;
  let seq = 0;
  let alive = true;

  async function load() {
    clearTimeout(timer);
    const mine = ++seq;
    const params = new URLSearchParams({ limit: PAGE_SIZE });
    const cursor = listView.cursors.at(-1);
    if (cursor) params.set('cursor', cursor);
    try {
      const page = await api(`/v1/sweeps?${params}`);
      if (!alive || mine !== seq) return;
      showMessage(refs['list-error'], '');
      nextCursor = page.next_cursor;
      render(page.sweeps);
    } catch (error) {
      if (!alive || mine !== seq) return;
      showMessage(refs['list-error'], `${error.message} Retrying every ${POLL_MS / 1000} s.`);
    }
    timer = setTimeout(load, POLL_MS);
  }

  // Rows are updated in place (a row taken out of the page would lose the keyboard focus).
  function render(sweeps) {
    const shown = new Map([...refs.rows.rows].map((tr) => [Number(tr.dataset.sweep), tr]));
    const rows = sweeps.map((s) => fillRow(shown.get(s.id) ?? sweepRow(s), s));
    const same = rows.length === refs.rows.rows.length && rows.every((tr, i) => refs.rows.rows[i] === tr);
    if (!same) refs.rows.replaceChildren(...rows);
    const first = listView.cursors.length === 1;
    refs.table.hidden = sweeps.length === 0;
    showMessage(refs.empty, sweeps.length > 0 ? ''
      : first ? 'No sweeps yet. Create one with POST /v1/sweeps (see the API description).' : 'No more sweeps on this page.');
    refs.prev.disabled = first;
    refs.next.disabled = nextCursor === null;
    refs['page-label'].textContent = `Page ${listView.cursors.length}`;
  }

  refs.next.addEventListener('click', () => {
    listView.cursors.push(nextCursor);
    load();
  });
  refs.prev.addEventListener('click', () => {
    listView.cursors.pop();
    load();
  });
  refs.rows.addEventListener('click', (event) => {
    const row = event.target.closest('tr[data-sweep]');
    if (row && !event.target.closest('a')) location.hash = `#/sweeps/${row.dataset.sweep}`;
  });
  load();

  return () => {
    alive = false;
    clearTimeout(timer);
  };
}

/** The swept fields and their number of values: `merge_radius (3) × scene.l3 (2)`. */
function describeAxes(spec) {
  const parts = spec.axes.map((a) => h('span', {}, h('code', {}, a.field), ` (${a.values.length}${a.by === 'prediction' ? ', predicted' : ''})`));
  const joiner = spec.mode === 'zip' ? ' with ' : ' × ';
  return parts.flatMap((p, i) => (i === 0 ? [p] : [joiner, p]));
}

function sweepRow(sweep) {
  return h('tr', { 'data-sweep': sweep.id },
    h('td', {}, h('a', { href: `#/sweeps/${sweep.id}` }, `#${sweep.id}`),
      h('span', { class: 'sub' }, `${sweep.spec.mode} · ${formatCount(sweep.points.length)} point${sweep.points.length === 1 ? '' : 's'}`)),
    h('td'),
    h('td', {}, describeAxes(sweep.spec)),
    h('td', { class: 'col-progress' }, progressBar()),
    h('td'),
    h('td', { title: formatTime(sweep.created_at) }, formatShortTime(sweep.created_at)));
}

function fillRow(tr, sweep) {
  const [, state, , progress, runs] = tr.cells;
  if (state.textContent !== sweep.state) state.replaceChildren(badge(sweep.state));
  updateProgress(progress.firstChild, sweep);
  runs.textContent = Object.entries(sweep.progress.runs_by_state).map(([s, n]) => `${n} ${s}`).join(', ');
  return tr;
}
