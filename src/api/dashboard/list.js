// The job list page: one page of jobs (with each one's name and labels, engine, N_F, N_B, seed, and
// whether it is a shard, a merge or a run of a sweep — a sweep's runs are named after their swept
// values), polled, with the first running ones streamed live, the state and label filters (a
// label chip filters by itself) and paging, the selection of jobs to compare (#/compare?ids=…), and the submit form (form.js).

import { TERMINAL, api, streamJob } from './api.js';
import {
  badge, describeBest, formatCount, formatDuration, formatParameter, formatRate, formatShortTime, formatTime, h, instantiate,
  isNewer, progressBar, showMessage, updateProgress,
} from './format.js';
import { setupSubmitForm } from './form.js';

const PAGE_SIZE = 25;
const LIST_POLL_MS = 3000;
// Each event stream holds one of the browser's six HTTP/1.1 connections to this origin, so the list
// streams at most this many running jobs live and polls for the rest.
const MAX_LIST_STREAMS = 2;
// The compare page shows 2 to this many jobs side by side.
export const MAX_COMPARED = 8;

// Kept across page changes so that coming back from a job shows the same page of the list.
const listView = { filter: '', label: '', cursors: [null], selected: new Set() };

/** Shows the list in `app` (the page's #app element); returns what leaving the page does. */
export function showList(app) {
  const { fragment, refs } = instantiate('tpl-list');
  app.replaceChildren(fragment);
  document.title = 'Jobs · optimis';

  const streams = new Map(); // job id → close()
  let jobs = [];
  let nextCursor = null;
  let pollTimer = null;
  let requestSeq = 0;
  let alive = true;

  async function load() {
    clearTimeout(pollTimer);
    const seq = ++requestSeq;
    const params = new URLSearchParams({ limit: PAGE_SIZE });
    if (listView.filter) params.set('state', listView.filter);
    if (listView.label) params.set('label', listView.label);
    const cursor = listView.cursors.at(-1);
    if (cursor) params.set('cursor', cursor);
    try {
      const page = await api(`/v1/jobs?${params}`);
      if (!alive || seq !== requestSeq) return;
      showMessage(refs['list-error'], '');
      jobs = page.jobs.map((job) => keepNewest(job));
      nextCursor = page.next_cursor;
      render();
    } catch (error) {
      if (!alive || seq !== requestSeq) return;
      showMessage(refs['list-error'], `${error.message} Retrying every ${LIST_POLL_MS / 1000} s.`);
    }
    pollTimer = setTimeout(load, LIST_POLL_MS);
  }

  // A row streamed live may be newer than the page the poll just fetched.
  function keepNewest(job) {
    const shown = jobs.find((j) => j.id === job.id);
    return shown && streams.has(job.id) && isNewer(shown, job) ? shown : job;
  }

  function render() {
    renderRows();
    const first = listView.cursors.length === 1;
    refs.table.hidden = jobs.length === 0;
    showMessage(refs.empty, jobs.length > 0 ? '' : emptyText(first));
    refs.prev.disabled = first;
    refs.next.disabled = nextCursor === null;
    refs['page-label'].textContent = `Page ${listView.cursors.length}`;
    reconcileStreams();
  }

  function emptyText(firstPage) {
    if (!firstPage) return 'No more jobs on this page.';
    const which = [listView.filter, listView.label ? `labelled ${listView.label}` : ''].filter(Boolean).join(' ');
    return which ? `No ${which} jobs.` : 'No jobs yet. Submit one with the form.';
  }

  // Rows are updated in place, and moved only when the order changes: a row taken out of the
  // page loses the keyboard focus, and every poll would otherwise do that.
  function renderRows() {
    const shown = new Map([...refs.rows.rows].map((tr) => [Number(tr.dataset.job), tr]));
    const rows = jobs.map((job) => fillRow(shown.get(job.id) ?? jobRow(job), job));
    const sameOrder = rows.length === refs.rows.rows.length && rows.every((tr, i) => refs.rows.rows[i] === tr);
    if (!sameOrder) refs.rows.replaceChildren(...rows);
  }

  function jobRow(job) {
    const { spec } = job;
    const pick = h('input', { type: 'checkbox', name: 'compare', value: job.id, 'aria-label': `Compare job ${job.id}` });
    pick.checked = listView.selected.has(job.id);
    return h('tr', { 'data-job': job.id },
      h('td', { class: 'col-pick' }, pick),
      h('td', { class: 'col-job' }, h('a', { href: `#/jobs/${job.id}` }, `#${job.id}`),
        spec.name ? h('span', { class: 'job-name', 'data-col': 'name', title: spec.notes ?? spec.name }, spec.name) : null,
        h('span', { class: 'sub' }, describeKind(job)),
        labelChips(spec.labels)),
      h('td'),
      h('td', { class: 'col-progress' }, progressBar()),
      h('td', { 'data-col': 'engine' }, spec.engine || 'brute'),
      h('td', { class: 'num', 'data-col': 'light_paths' }, formatSize(spec.light_paths)),
      h('td', { class: 'num', 'data-col': 'camera_paths' }, formatSize(spec.camera_paths)),
      h('td', { class: 'num', 'data-col': 'seed' }, String(spec.seed)),
      h('td', { class: 'num' }),
      h('td', { class: 'num' }),
      h('td'),
      h('td', { title: formatTime(job.created_at) }, formatShortTime(job.created_at)));
  }

  function fillRow(tr, job) {
    const [, , state, progress, , , , , rate, eta, best] = tr.cells;
    const running = job.state === 'running';
    if (state.textContent !== job.state) state.replaceChildren(badge(job.state));
    updateProgress(progress.firstChild, job);
    rate.textContent = running ? formatRate(job.progress.light_paths_per_second) : '—';
    eta.textContent = running ? formatDuration(job.progress.eta_seconds) : '—';
    best.textContent = describeBest(job.progress.best);
    return tr;
  }

  function updateRow(job) {
    const index = jobs.findIndex((j) => j.id === job.id);
    if (index < 0) return;
    jobs[index] = job;
    const tr = refs.rows.querySelector(`tr[data-job="${job.id}"]`);
    if (tr) fillRow(tr, job);
  }

  // Streams the first running jobs of the page; polling covers the rest.
  function reconcileStreams() {
    const wanted = new Set(jobs.filter((j) => j.state === 'running').slice(0, MAX_LIST_STREAMS).map((j) => j.id));
    for (const [id, close] of streams) {
      if (!wanted.has(id)) {
        close();
        streams.delete(id);
      }
    }
    for (const id of wanted) {
      if (streams.has(id)) continue;
      const forget = () => streams.delete(id);
      streams.set(id, streamJob(id, {
        onJob: (job) => {
          if (TERMINAL.has(job.state)) forget();
          updateRow(job);
        },
        onLost: forget, // the next poll opens it again
      }));
    }
  }

  refs.filter.value = listView.filter;
  refs.filter.addEventListener('change', () => {
    listView.filter = refs.filter.value;
    listView.cursors = [null];
    load();
  });
  // The label filter: KEY=VALUE as typed (the server says if it is not one), or a chip clicked.
  const filterByLabel = (label) => {
    listView.label = label.trim();
    refs['label-filter'].value = listView.label;
    listView.cursors = [null];
    load();
  };
  refs['label-filter'].value = listView.label;
  refs['label-filter'].addEventListener('change', () => filterByLabel(refs['label-filter'].value));
  refs.rows.addEventListener('click', (event) => {
    const chip = event.target.closest('button.label-chip');
    if (chip) filterByLabel(chip.dataset.label);
  });
  refs.next.addEventListener('click', () => {
    listView.cursors.push(nextCursor);
    load();
  });
  refs.prev.addEventListener('click', () => {
    listView.cursors.pop();
    load();
  });
  // The whole row leads to the job, not only its id (but not its checkbox or a label chip).
  refs.rows.addEventListener('click', (event) => {
    const row = event.target.closest('tr[data-job]');
    if (row && !event.target.closest('a, input, button, .col-pick')) location.hash = `#/jobs/${row.dataset.job}`;
  });
  refs.rows.addEventListener('change', (event) => {
    if (event.target.name !== 'compare') return;
    const id = Number(event.target.value);
    if (event.target.checked) listView.selected.add(id);
    else listView.selected.delete(id);
    renderCompare();
  });
  refs.compare.addEventListener('click', () => {
    location.hash = `#/compare?ids=${[...listView.selected].sort((a, b) => a - b).join(',')}`;
  });
  refs['compare-clear'].addEventListener('click', () => {
    listView.selected.clear();
    for (const box of refs.rows.querySelectorAll('input[name="compare"]')) box.checked = false;
    renderCompare();
  });

  /** The Compare button: enabled for 2 to MAX_COMPARED selected jobs (kept across pages). */
  function renderCompare() {
    const n = listView.selected.size;
    refs.compare.disabled = n < 2 || n > MAX_COMPARED;
    refs.compare.textContent = `Compare${n ? ` (${n})` : ''}`;
    refs['compare-clear'].hidden = n === 0;
    refs['compare-hint'].textContent = n > MAX_COMPARED ? `At most ${MAX_COMPARED} jobs at once.`
      : n < 2 ? 'Tick 2 to 8 jobs to compare their noise and weights.' : '';
  }
  renderCompare();
  setupSubmitForm(refs);
  load();

  return () => {
    alive = false;
    clearTimeout(pollTimer);
    for (const close of streams.values()) close();
  };
}

/** A whole number, powers of ten as 10ⁿ: 10⁷ light paths, 100 camera paths. */
function formatSize(n) {
  return Number.isInteger(Math.log10(n)) && n >= 1000 ? formatParameter(n) : formatCount(n);
}

/** A job's labels as chips; clicking one lists the jobs with that label. */
function labelChips(labels) {
  const entries = Object.entries(labels ?? {});
  if (entries.length === 0) return null;
  return h('span', { class: 'labels' }, ...entries.map(([key, value]) => h('button',
    { type: 'button', class: 'label-chip', 'data-label': `${key}=${value}`, title: `Only jobs labelled ${key}=${value}` },
    `${key}=${value}`)));
}

/** The preset, and whether the job is a shard of a study, a merge, or a run of a sweep (linked). */
function describeKind(job) {
  const parts = [job.spec.preset];
  if (job.spec.shard) parts.push(h('span', { class: 'kind', 'data-kind': 'shard' }, `shard ${job.spec.shard.index + 1}/${job.spec.shard.count}`));
  if (job.merged) {
    // A merge holds every seed of its sources (its spec keeps the first source's).
    const seeds = job.provenance?.seeds ?? [];
    const sources = (job.provenance?.sources ?? []).map((s) => s.from).join(', ');
    parts.push(h('span', { class: 'kind', 'data-kind': 'merged', title: sources ? `Merged from ${sources}` : null },
      seeds.length > 1 ? `merged · seeds ${seeds.join(', ')}` : 'merged'));
  }
  if (job.sweep_id !== null && job.sweep_id !== undefined) {
    parts.push(h('a', { class: 'sweep-link', 'data-kind': 'sweep', href: `#/sweeps/${job.sweep_id}` }, `sweep ${job.sweep_id}`));
  }
  return parts.flatMap((p, i) => (i === 0 ? [p] : [' · ', p]));
}
