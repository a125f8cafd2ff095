// The job list page, a runs table: one page of jobs (with each one's name and labels, and whether
// it is a shard, a merge or a run of a sweep), its state and progress, and its parameters as
// sortable columns — engine, N_F, N_B and seed always, and every other spec field that differs
// between the jobs of the page (specfields.js), W&B style; polled, with the first running ones
// streamed live. The state, label and sweep filters, the sort and the page are in the URL
// (#/?state=…&label=…&sweep=…&sort=…&order=…&cursor=…), so a filtered view survives a reload and
// can be shared. A label chip filters by itself; the selection of jobs to compare
// (#/compare?ids=…); the submit form (form.js).

import { TERMINAL, api, streamJob } from './api.js';
import {
  badge, describeBest, formatDuration, formatRate, formatRms, formatShortTime, formatTime, h, instantiate,
  isNewer, progressBar, showMessage, updateProgress,
} from './format.js';
import { setupSubmitForm } from './form.js';
import { compareValues, fieldLabel, fieldText, flattenSpec, formatField, varyingFields } from './specfields.js';

const PAGE_SIZE = 25;
const LIST_POLL_MS = 3000;
// Each event stream holds one of the browser's six HTTP/1.1 connections to this origin, so the list
// streams at most this many running jobs live and polls for the rest.
const MAX_LIST_STREAMS = 2;
// The compare page shows 2 to this many jobs side by side.
export const MAX_COMPARED = 8;
// Always columns (today's list); the fields that vary on the page come after them.
const ALWAYS = ['engine', 'light_paths', 'camera_paths', 'seed'];
// Beyond this many varying fields the rest are named in the caption, not given a column.
const MAX_VARYING_COLUMNS = 6;
// The sortable columns that are not spec fields.
const OTHER_SORTS = { created: (job) => job.created_at, state: (job) => job.state, id: (job) => job.id };

/** A parameter column's classes: numbers right-aligned, the varying ones marked. */
const columnClass = (path) => [path === 'engine' ? '' : 'num', ALWAYS.includes(path) ? '' : 'varying'].filter(Boolean).join(' ') || null;

// The jobs ticked for comparison, kept across pages and filters of the list.
const selected = new Set();

/** The list's state from the hash's query (`#/?state=running&label=k=v`), checked; unknowns dropped. */
export function parseListQuery(query) {
  const params = new URLSearchParams(query);
  const view = { state: '', label: '', sweep: '', sort: '', order: 'asc', cursors: [null] };
  const state = params.get('state') ?? '';
  if (['queued', 'running', 'succeeded', 'failed', 'cancelled'].includes(state)) view.state = state;
  view.label = (params.get('label') ?? '').trim().slice(0, 300);
  if (/^[1-9]\d{0,18}$/.test(params.get('sweep') ?? '')) view.sweep = params.get('sweep');
  if (/^[A-Za-z0-9_.]{1,80}$/.test(params.get('sort') ?? '')) view.sort = params.get('sort');
  if (params.get('order') === 'desc') view.order = 'desc';
  if (/^[1-9]\d{0,18}$/.test(params.get('cursor') ?? '')) view.cursors.push(params.get('cursor'));
  return view;
}

/** The hash that shows `view` (what the address bar and the Jobs link hold). */
export function listHash(view) {
  const params = new URLSearchParams();
  for (const key of ['state', 'label', 'sweep', 'sort']) if (view[key]) params.set(key, view[key]);
  if (view.sort && view.order === 'desc') params.set('order', 'desc');
  const cursor = view.cursors.at(-1);
  if (cursor) params.set('cursor', cursor);
  const query = params.toString();
  return query ? `#/?${query}` : '#/';
}

/** Shows the list in `app` (the page's #app element) in the state of `query`; returns what leaving the page does. */
export function showList(app, query = '') {
  const { fragment, refs } = instantiate('tpl-list');
  app.replaceChildren(fragment);
  document.title = 'Jobs · optimis';
  const listView = parseListQuery(query);

  const streams = new Map(); // job id → close()
  let jobs = [];
  let nextCursor = null;
  let pollTimer = null;
  let requestSeq = 0;
  let alive = true;
  let columns = []; // the spec fields shown, in order
  let columnsKey = '';

  // The address bar follows the view without a page change (replaceState fires no hashchange);
  // the Jobs link of the top bar comes back to it.
  function remember() {
    const hash = listHash(listView);
    if (location.hash !== hash && !(hash === '#/' && location.hash === '')) history.replaceState(null, '', hash);
    document.querySelector('.topnav a[data-nav="jobs"]')?.setAttribute('href', hash);
  }

  async function load() {
    clearTimeout(pollTimer);
    remember();
    const seq = ++requestSeq;
    const params = new URLSearchParams({ limit: PAGE_SIZE });
    if (listView.state) params.set('state', listView.state);
    if (listView.label) params.set('label', listView.label);
    if (listView.sweep) params.set('sweep', listView.sweep);
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
    chooseColumns();
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
    const which = [listView.state, listView.label ? `labelled ${listView.label}` : '', listView.sweep ? `of sweep ${listView.sweep}` : '']
      .filter(Boolean).join(' ');
    return which ? `No ${which} jobs.` : 'No jobs yet. Submit one with the form.';
  }

  // The columns: the always ones, then the fields that differ on this page; the header is rebuilt
  // (and the rows with it) only when they change.
  function chooseColumns() {
    const varying = varyingFields(jobs.map((j) => j.spec)).filter((p) => !ALWAYS.includes(p));
    const shown = varying.slice(0, MAX_VARYING_COLUMNS);
    const key = JSON.stringify([shown, listView.sort, listView.order]);
    refs['varying-note'].textContent = varying.length === 0 ? ''
      : `Differing on this page: ${varying.map(fieldText).join(', ')}${varying.length > shown.length
        ? ` (the first ${shown.length} as columns)` : ''}.`;
    if (key === columnsKey) return;
    columnsKey = key;
    columns = [...ALWAYS, ...shown];
    const sortable = (sortKey, label, numeric, extra = {}) => {
      const active = listView.sort === sortKey;
      const arrow = active ? (listView.order === 'desc' ? ' ▼' : ' ▲') : '';
      return h('th', { scope: 'col', class: numeric ? 'num' : null, 'aria-sort': active ? (listView.order === 'desc' ? 'descending' : 'ascending') : null, ...extra },
        h('button', { type: 'button', class: 'sort', 'data-sort': sortKey, title: `Sort this page by ${typeof label === 'string' ? label : fieldText(sortKey)}` }, label, arrow));
    };
    refs.head.replaceChildren(h('tr', {},
      h('th', { scope: 'col', class: 'col-pick' }, h('span', { class: 'visually-hidden' }, 'Compare')),
      sortable('id', 'Job', false),
      sortable('state', 'State', false),
      h('th', { scope: 'col', class: 'col-progress' }, 'Progress (iterations)'),
      columns.map((path) => sortable(path, fieldLabel(path), path !== 'engine',
        { 'data-col': path, class: columnClass(path) })),
      h('th', { scope: 'col', class: 'num' }, 'Rate · ETA'),
      h('th', { scope: 'col' }, 'Best (RMS %)'),
      sortable('created', 'Created', false)));
    refs.rows.replaceChildren(); // rows are rebuilt with the new columns
  }

  function sorted() {
    if (!listView.sort) return jobs;
    const other = OTHER_SORTS[listView.sort];
    const value = other ?? ((job) => flattenSpec(job.spec).get(listView.sort));
    const sign = listView.order === 'desc' ? -1 : 1;
    return [...jobs].sort((a, b) => sign * compareValues(value(a), value(b)) || b.id - a.id);
  }

  // Rows are updated in place, and moved only when the order changes: a row taken out of the
  // page loses the keyboard focus, and every poll would otherwise do that.
  function renderRows() {
    const shown = new Map([...refs.rows.rows].map((tr) => [Number(tr.dataset.job), tr]));
    const rows = sorted().map((job) => fillRow(shown.get(job.id) ?? jobRow(job), job));
    const sameOrder = rows.length === refs.rows.rows.length && rows.every((tr, i) => refs.rows.rows[i] === tr);
    if (!sameOrder) refs.rows.replaceChildren(...rows);
  }

  function jobRow(job) {
    const { spec } = job;
    const flat = flattenSpec(spec);
    const pick = h('input', { type: 'checkbox', name: 'compare', value: job.id, 'aria-label': `Compare job ${job.id}` });
    pick.checked = selected.has(job.id);
    return h('tr', { 'data-job': job.id },
      h('td', { class: 'col-pick' }, pick),
      h('td', { class: 'col-job' }, h('a', { href: `#/jobs/${job.id}` }, `#${job.id}`),
        spec.name ? h('span', { class: 'job-name', 'data-col': 'name', title: spec.notes ?? spec.name }, spec.name) : null,
        h('span', { class: 'sub' }, describeKind(job)),
        labelChips(spec.labels)),
      h('td', { 'data-cell': 'state' }),
      h('td', { class: 'col-progress', 'data-cell': 'progress' }, progressBar()),
      columns.map((path) => h('td', { class: columnClass(path), 'data-col': path }, formatField(path, flat.get(path)))),
      h('td', { class: 'num', 'data-cell': 'rate' }),
      h('td', { 'data-cell': 'best', class: 'col-best' }),
      h('td', { title: formatTime(job.created_at), class: 'col-created' }, formatShortTime(job.created_at)));
  }

  function fillRow(tr, job) {
    const cell = (name) => tr.querySelector(`td[data-cell="${name}"]`);
    const running = job.state === 'running';
    const state = cell('state');
    if (state.textContent !== job.state) state.replaceChildren(badge(job.state));
    updateProgress(cell('progress').firstChild, job);
    cell('rate').textContent = running
      ? `${formatRate(job.progress.light_paths_per_second)}/s · ${formatDuration(job.progress.eta_seconds)}` : '—';
    const best = job.progress.best;
    const text = describeBest(best);
    if (cell('best').title !== text) {
      // The strategy's name may break after an underscore; its RMS on the line below.
      cell('best').title = text;
      cell('best').replaceChildren(...(best ? [h('code', {}, best.strategy.split('_').flatMap((w, i) => (i ? [h('wbr'), `_${w}`] : [w]))),
        h('br'), `${formatRms(best.rms_percent)} %`] : ['—']));
    }
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

  const restart = () => {
    listView.cursors = [null];
    load();
  };
  refs.filter.value = listView.state;
  refs.filter.addEventListener('change', () => {
    listView.state = refs.filter.value;
    restart();
  });
  // The label filter: KEY=VALUE as typed (the server says if it is not one), or a chip clicked.
  const filterByLabel = (label) => {
    listView.label = label.trim();
    refs['label-filter'].value = listView.label;
    restart();
  };
  refs['label-filter'].value = listView.label;
  refs['label-filter'].addEventListener('change', () => filterByLabel(refs['label-filter'].value));
  // The sweep filter comes from a sweep page's link; it shows as a chip that removes it.
  const renderSweepFilter = () => {
    refs['sweep-filter'].hidden = !listView.sweep;
    refs['sweep-filter'].textContent = listView.sweep ? `sweep ${listView.sweep} ✕` : '';
  };
  renderSweepFilter();
  refs['sweep-filter'].addEventListener('click', () => {
    listView.sweep = '';
    renderSweepFilter();
    restart();
  });
  refs.head.addEventListener('click', (event) => {
    const button = event.target.closest('button[data-sort]');
    if (!button) return;
    // Ascending, descending, then the server's order (newest first) again.
    const key = button.dataset.sort;
    if (listView.sort !== key) [listView.sort, listView.order] = [key, 'asc'];
    else if (listView.order === 'asc') listView.order = 'desc';
    else [listView.sort, listView.order] = ['', 'asc'];
    remember();
    render();
  });
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
    if (event.target.checked) selected.add(id);
    else selected.delete(id);
    renderCompare();
  });
  refs.compare.addEventListener('click', () => {
    location.hash = `#/compare?ids=${[...selected].sort((a, b) => a - b).join(',')}`;
  });
  refs['compare-clear'].addEventListener('click', () => {
    selected.clear();
    for (const box of refs.rows.querySelectorAll('input[name="compare"]')) box.checked = false;
    renderCompare();
  });

  /** The Compare button: enabled for 2 to MAX_COMPARED selected jobs (kept across pages). */
  function renderCompare() {
    const n = selected.size;
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
