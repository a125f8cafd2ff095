// The optimis dashboard: a hash-routed client of the public API (/v1/jobs…).
//
// No framework and no build step: pages are <template>s from index.html filled in here. The page is
// served under a Content-Security-Policy that forbids inline script, so every event handler is
// attached from this file.

/* global uPlot */

const PAGE_SIZE = 25;
const LIST_POLL_MS = 3000;
const RETRY_MS = 3000;
// Each event stream holds one of the browser's six HTTP/1.1 connections to this origin, so the list
// streams at most this many running jobs live and polls for the rest.
const MAX_LIST_STREAMS = 2;
const TERMINAL = new Set(['succeeded', 'failed', 'cancelled']);
const STRATEGIES = ['plane1', 'plane2', 'plane3', 'switch', 'optimal', 'optimal_holdout', 'optimal_cv', 'balance', 'power'];
const STRATEGY_COLORS = {
  plane1: '#8c564b', plane2: '#1f77b4', plane3: '#2ca02c', switch: '#9467bd', optimal: '#d62728',
  optimal_holdout: '#ff7f0e', optimal_cv: '#e377c2', balance: '#17becf', power: '#7f7f7f',
};
// The weights plot clips the y axis to this range: with few samples a cell's fitted weights can be
// in the hundreds, which would flatten every other cell to a line.
const WEIGHT_RANGE = [-1, 2];

const app = document.getElementById('app');
// Kept across page changes so that coming back from a job shows the same page of the list.
const listView = { filter: '', cursors: [null] };
let leavePage = () => {};

function route() {
  leavePage();
  const match = /^#\/jobs\/(\d+)$/.exec(location.hash);
  leavePage = match ? showJob(Number(match[1])) : showList();
  window.scrollTo(0, 0);
}

// ---------------------------------------------------------------------------------------------
// API

class ApiError extends Error {
  constructor(message, status, field) {
    super(message);
    this.status = status;
    this.field = field;
  }
}

// A server started with a token (OPTIMIS_TOKEN) wants `Authorization: Bearer …` on every API call.
// The token lives in sessionStorage: it is asked for once per tab and forgotten with it.
const TOKEN_KEY = 'optimis-token';

function authHeaders() {
  const token = sessionStorage.getItem(TOKEN_KEY);
  return token ? { Authorization: `Bearer ${token}` } : {};
}

/** Calls the API; throws an ApiError in plain words (the problem's `detail`) on any failure. */
async function api(path, { method = 'GET', body } = {}) {
  const init = { method, headers: { Accept: 'application/json', ...authHeaders() } };
  if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let response, text;
  try {
    response = await fetch(path, init);
    text = await response.text();
  } catch {
    throw new ApiError(`Cannot reach the server at ${location.host}. Check that optimis is running, then try again.`, 0);
  }
  const data = parseJson(text);
  if (response.status === 401) askForToken(data?.detail);
  if (!response.ok) {
    const detail = data?.detail || data?.title || `${response.status} ${response.statusText}`;
    throw new ApiError(detail, response.status, data?.field);
  }
  return data;
}

/** Shows the sign-in banner (once): the server wants a token this tab does not have, or a better one. */
function askForToken(reason) {
  if (document.getElementById('sign-in')) return;
  const input = h('input', { id: 'token-input', type: 'password', autocomplete: 'current-password', placeholder: 'token' });
  const form = h('form', { id: 'sign-in', class: 'sign-in', role: 'alert' },
    h('label', { for: 'token-input' }, 'This server needs its access token',
      reason ? h('span', { class: 'hint' }, ` (${reason})`) : null),
    input,
    h('button', { type: 'submit' }, 'Sign in'));
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    sessionStorage.setItem(TOKEN_KEY, input.value.trim());
    form.remove();
    route();
  });
  document.body.prepend(form);
  input.focus();
}

function parseJson(text) {
  try {
    return JSON.parse(text);
  } catch {
    return null;
  }
}

/**
 * Streams one job's resource by Server-Sent Events, read with fetch so that the request can carry
 * the bearer token (EventSource cannot send headers). Stops once the job is finished (the server
 * then ends the stream). Calls `onLost` if the connection fails, drops or the server shuts down,
 * after which the caller decides how to recover.
 */
function streamJob(id, { onJob, onLost }) {
  const abort = new AbortController();
  let done = false;
  const finish = (lost) => {
    if (done) return;
    done = true;
    abort.abort();
    if (lost) onLost();
  };
  const dispatch = (block) => {
    let name = 'message';
    const data = [];
    for (const line of block.split('\n')) {
      if (line.startsWith('event:')) name = line.slice(6).trim();
      else if (line.startsWith('data:')) data.push(line.slice(5).replace(/^ /, ''));
    }
    if (name === 'shutdown') return finish(true);
    if (name !== 'job' || data.length === 0) return;
    const job = JSON.parse(data.join('\n'));
    onJob(job);
    if (TERMINAL.has(job.state)) finish(false);
  };
  (async () => {
    const response = await fetch(`/v1/jobs/${id}/events`, {
      headers: { Accept: 'text/event-stream', ...authHeaders() },
      signal: abort.signal,
    });
    if (!response.ok || !response.body) throw new Error(`events: ${response.status}`);
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = '';
    while (!done) {
      const { value, done: ended } = await reader.read();
      if (ended) break;
      buffer += value.replace(/\r\n?/g, '\n');
      let cut;
      while (!done && (cut = buffer.indexOf('\n\n')) >= 0) {
        dispatch(buffer.slice(0, cut));
        buffer = buffer.slice(cut + 2);
      }
    }
    finish(true);
  })().catch(() => finish(true));
  return () => finish(false);
}

// ---------------------------------------------------------------------------------------------
// DOM and formatting helpers

/** Creates an element; `props` are attributes except `class`, `text` and `style` (an object). */
function h(tag, props = {}, ...children) {
  const el = document.createElement(tag);
  for (const [key, value] of Object.entries(props)) {
    if (value === null || value === undefined || value === false) continue;
    if (key === 'class') el.className = value;
    else if (key === 'style') Object.assign(el.style, value);
    else el.setAttribute(key, value === true ? '' : String(value));
  }
  el.append(...children.flat().filter((c) => c !== null && c !== undefined && c !== false));
  return el;
}

/** Clones a <template> and collects its `data-ref` elements by name. */
function instantiate(id) {
  const fragment = document.getElementById(id).content.cloneNode(true);
  const refs = {};
  for (const el of fragment.querySelectorAll('[data-ref]')) refs[el.dataset.ref] = el;
  return { fragment, refs };
}

function showMessage(el, text) {
  el.textContent = text || '';
  el.hidden = !text;
}

const integerFormat = new Intl.NumberFormat(undefined, { maximumFractionDigits: 0 });
const compactFormat = new Intl.NumberFormat(undefined, { notation: 'compact', maximumSignificantDigits: 3 });
const timeFormat = new Intl.DateTimeFormat(undefined, { dateStyle: 'medium', timeStyle: 'medium' });

function fixed(x, digits) {
  return x.toLocaleString(undefined, { minimumFractionDigits: digits, maximumFractionDigits: digits });
}

const formatCount = (n) => integerFormat.format(n);
const formatRate = (perSecond) => (perSecond === null ? '—' : compactFormat.format(perSecond));
const formatTime = (iso) => timeFormat.format(new Date(iso));

/** Month, day and minute, plus the year when it is not this one: for the narrow list column. */
function formatShortTime(iso) {
  const date = new Date(iso);
  const options = { month: 'short', day: 'numeric', hour: '2-digit', minute: '2-digit' };
  if (date.getFullYear() !== new Date().getFullYear()) options.year = 'numeric';
  return date.toLocaleString(undefined, options);
}
/** Luminance in units of 10⁻⁵, as the paper's Table 1 prints it. */
const formatLuminance = (l) => fixed(l * 1e5, 2);
/** RMS in percent: one decimal is plenty above 10 %, two below. */
const formatRms = (rms) => fixed(rms, rms >= 10 ? 1 : 2);

function formatDuration(seconds) {
  if (seconds === null) return '—';
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  const pad = (n) => String(n).padStart(2, '0');
  if (s < 3600) return `${Math.floor(s / 60)} min ${pad(s % 60)} s`;
  if (s < 86400) return `${Math.floor(s / 3600)} h ${pad(Math.floor(s / 60) % 60)} min`;
  return `${Math.floor(s / 86400)} d ${Math.floor(s / 3600) % 24} h`;
}

const SUPERSCRIPTS = { '-': '⁻', 0: '⁰', 1: '¹', 2: '²', 3: '³', 4: '⁴', 5: '⁵', 6: '⁶', 7: '⁷', 8: '⁸', 9: '⁹' };

/** A plain number, with powers of ten written as 10⁻⁵ (λ grids are usually decades). */
function formatParameter(x) {
  const exponent = Math.log10(Math.abs(x));
  if (x !== 0 && Number.isInteger(exponent) && Math.abs(exponent) >= 3) {
    const power = `10${[...String(exponent)].map((c) => SUPERSCRIPTS[c]).join('')}`;
    return x < 0 ? `−${power}` : power;
  }
  return String(Number(x.toPrecision(6)));
}

function withError(value, error, format) {
  return error === null || error === undefined ? format(value) : `${format(value)} ± ${format(error)}`;
}

function badge(state) {
  return h('span', { class: `badge badge-${state}` }, state);
}

/** A progress bar element; `updateProgress` fills it in. */
function progressBar() {
  return h('div', { class: 'progress', role: 'progressbar', 'aria-label': 'Iterations done', 'aria-valuemin': 0 },
    h('div', { class: 'progress-fill' }), h('span', { class: 'progress-text' }));
}

function updateProgress(bar, job) {
  const { iterations_done: done, iterations_total: total } = job.progress;
  bar.setAttribute('aria-valuenow', done);
  bar.setAttribute('aria-valuemax', total);
  bar.dataset.state = job.state;
  bar.querySelector('.progress-fill').style.width = `${total > 0 ? Math.min(100, (100 * done) / total) : 0}%`;
  bar.querySelector('.progress-text').textContent = `${formatCount(done)} / ${formatCount(total)}`;
}

function describeBest(best) {
  return best ? `${best.strategy} · ${formatRms(best.rms_percent)} %` : '—';
}

/** Whether resource `a` is at least as recent as `b` (poll answers can overtake stream events). */
function isNewer(a, b) {
  if (a.updated_at !== b.updated_at) return a.updated_at > b.updated_at;
  return a.progress.iterations_done >= b.progress.iterations_done;
}

// ---------------------------------------------------------------------------------------------
// Job list page

function showList() {
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
    return listView.filter ? `No ${listView.filter} jobs.` : 'No jobs yet. Submit one with the form.';
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
    return h('tr', { 'data-job': job.id },
      h('td', {}, h('a', { href: `#/jobs/${job.id}` }, `#${job.id}`), h('span', { class: 'sub' }, job.spec.preset)),
      h('td'),
      h('td', { class: 'col-progress' }, progressBar()),
      h('td', { class: 'num' }),
      h('td', { class: 'num' }),
      h('td'),
      h('td', { title: formatTime(job.created_at) }, formatShortTime(job.created_at)));
  }

  function fillRow(tr, job) {
    const [, state, progress, rate, eta, best] = tr.cells;
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
  refs.next.addEventListener('click', () => {
    listView.cursors.push(nextCursor);
    load();
  });
  refs.prev.addEventListener('click', () => {
    listView.cursors.pop();
    load();
  });
  // The whole row leads to the job, not only its id.
  refs.rows.addEventListener('click', (event) => {
    const row = event.target.closest('tr[data-job]');
    if (row && !event.target.closest('a')) location.hash = `#/jobs/${row.dataset.job}`;
  });
  setupSubmitForm(refs);
  load();

  return () => {
    alive = false;
    clearTimeout(pollTimer);
    for (const close of streams.values()) close();
  };
}

// ---------------------------------------------------------------------------------------------
// Submit form

class FormError extends Error {
  constructor(message, field) {
    super(message);
    this.field = field;
  }
}

function setupSubmitForm(refs) {
  const form = refs.form;
  form.addEventListener('input', (event) => event.target.removeAttribute('aria-invalid'));
  form.addEventListener('submit', async (event) => {
    event.preventDefault();
    clearFormError(form, refs['form-error']);
    let submission;
    try {
      submission = buildSubmission(form);
    } catch (error) {
      showFormError(form, refs['form-error'], error.message, error.field);
      return;
    }
    refs.submit.disabled = true;
    refs.submit.textContent = 'Submitting…';
    try {
      const job = await api('/v1/jobs', { method: 'POST', body: submission });
      location.hash = `#/jobs/${job.id}`;
    } catch (error) {
      const prefix = error.status === 0 ? '' : 'The server rejected the job: ';
      showFormError(form, refs['form-error'], prefix + error.message, error.field);
    } finally {
      refs.submit.disabled = false;
      refs.submit.textContent = 'Submit job';
    }
  });
}

/** The submitted document: the preset, the filled-in fields, and the extra overrides. */
function buildSubmission(form) {
  const extra = parseExtra(form.elements.extra.value);
  const fields = { preset: form.elements.preset.value, engine: form.elements.engine.value };
  for (const input of form.querySelectorAll('input[data-kind]')) {
    const text = input.value.trim();
    if (text) setPath(fields, input.name.split('.'), parseField(input.name, text, input.dataset.kind));
  }
  for (const path of leafPaths(fields)) {
    if (getPath(extra, path) !== undefined) {
      const name = path.join('.');
      throw new FormError(`${name} is set both in its own field and in the extra overrides; keep only one.`, name);
    }
  }
  return deepMerge(extra, fields);
}

function parseExtra(text) {
  if (!text.trim()) return {};
  let value;
  try {
    value = JSON.parse(text);
  } catch (error) {
    throw new FormError(`The extra overrides are not valid JSON: ${error.message}`, 'extra');
  }
  if (typeof value !== 'object' || value === null || Array.isArray(value)) {
    throw new FormError('The extra overrides must be a JSON object, such as {"seed": 7}.', 'extra');
  }
  return value;
}

function parseField(name, text, kind) {
  const value = Number(text);
  if (!Number.isFinite(value)) throw new FormError(`${name}: “${text}” is not a number.`, name);
  // Counts are sent as JSON numbers, exact only up to 2⁵³.
  if (kind === 'integer' && !Number.isSafeInteger(value)) {
    throw new FormError(`${name}: must be a whole number up to ${formatCount(Number.MAX_SAFE_INTEGER)}, got “${text}”.`, name);
  }
  return value;
}

const isObject = (v) => typeof v === 'object' && v !== null && !Array.isArray(v);

function getPath(object, path) {
  return path.reduce((node, key) => (isObject(node) ? node[key] : undefined), object);
}

function setPath(object, path, value) {
  const last = path.at(-1);
  const parent = path.slice(0, -1).reduce((node, key) => (node[key] ??= {}), object);
  parent[last] = value;
}

function leafPaths(object, prefix = []) {
  return Object.entries(object).flatMap(([key, value]) =>
    isObject(value) ? leafPaths(value, [...prefix, key]) : [[...prefix, key]]);
}

function deepMerge(target, source) {
  for (const [key, value] of Object.entries(source)) {
    target[key] = isObject(value) && isObject(target[key]) ? deepMerge(target[key], value) : value;
  }
  return target;
}

function clearFormError(form, message) {
  showMessage(message, '');
  for (const el of form.querySelectorAll('[aria-invalid]')) el.removeAttribute('aria-invalid');
}

/** Shows `text` and marks the input named by the problem's `field` (or the JSON box for others). */
function showFormError(form, message, text, field) {
  showMessage(message, text);
  if (!field) return;
  const input = form.elements.namedItem(field) ?? (form.elements.extra.value.trim() ? form.elements.extra : null);
  if (input) {
    input.setAttribute('aria-invalid', 'true');
    input.setAttribute('aria-describedby', message.id);
    input.focus();
  }
}

// ---------------------------------------------------------------------------------------------
// Job page

function showJob(id) {
  const { fragment, refs } = instantiate('tpl-job');
  app.replaceChildren(fragment);
  document.title = `Job ${id} · optimis`;

  const weightsPlot = new PlotSlot(refs['weights-plot']);
  const historyPlot = new PlotSlot(refs['history-plot']);
  const results = new ResultsLoader(id, refs, weightsPlot, historyPlot);
  let job = null;
  let closeStream = null;
  let retryTimer = null;
  let alive = true;

  function render(next) {
    job = next;
    refs.body.hidden = false;
    refs.id.textContent = job.id;
    refs.state.replaceChildren(badge(job.state));
    updateProgress(refs.progress, job);
    renderStats(refs, job);
    renderSpec(refs.spec, job);
    renderActions(refs, job);
    showMessage(refs['job-error'], job.error ? `The job failed: ${job.error}` : '');
    const { iterations_done: done, iterations_total: total } = job.progress;
    document.title = `Job ${job.id} · ${job.state}${TERMINAL.has(job.state) ? '' : ` ${done}/${total}`} · optimis`;
    results.update(job);
    if (TERMINAL.has(job.state)) setLive('');
    else openStream();
  }

  function openStream() {
    if (closeStream) return;
    setLive('live');
    closeStream = streamJob(id, {
      onJob: (next) => {
        if (TERMINAL.has(next.state)) closeStream = null;
        if (alive) render(next);
      },
      onLost: () => {
        closeStream = null;
        setLive('reconnecting');
        retryTimer = setTimeout(reload, RETRY_MS);
      },
    });
  }

  function setLive(status) {
    refs.live.dataset.status = status;
    refs.live.textContent = { live: 'live', reconnecting: 'connection lost — reconnecting…', '': '' }[status];
  }

  async function reload() {
    try {
      const next = await api(`/v1/jobs/${id}`);
      if (!alive) return;
      showMessage(refs['load-error'], '');
      render(next);
    } catch (error) {
      if (!alive) return;
      if (error.status === 404) {
        showMessage(refs['load-error'], `Job ${id} does not exist (it may have been deleted).`);
        refs.body.hidden = true;
        return;
      }
      showMessage(refs['load-error'], `${error.message} Retrying every ${RETRY_MS / 1000} s.`);
      retryTimer = setTimeout(reload, RETRY_MS);
    }
  }

  async function act(button, path, body) {
    showMessage(refs['action-error'], '');
    button.disabled = true;
    try {
      const next = await api(path, { method: 'POST', body });
      if (alive) render(next);
      return true;
    } catch (error) {
      if (alive) showMessage(refs['action-error'], error.message);
      return false;
    } finally {
      button.disabled = false;
      if (job) renderActions(refs, job);
    }
  }

  refs.cancel.addEventListener('click', () => act(refs.cancel, `/v1/jobs/${id}/cancel`));
  refs['extend-form'].addEventListener('submit', async (event) => {
    event.preventDefault();
    const input = refs['extend-form'].elements.iterations;
    const iterations = Number(input.value.trim());
    if (!Number.isSafeInteger(iterations) || iterations < 1) {
      showMessage(refs['action-error'], 'Enter how many iterations to add: a whole number of at least 1.');
      input.focus();
      return;
    }
    if (await act(refs.extend, `/v1/jobs/${id}/extend`, { iterations })) input.value = '';
  });
  reload();

  return () => {
    alive = false;
    clearTimeout(retryTimer);
    if (closeStream) closeStream();
    results.stop();
    weightsPlot.destroy();
    historyPlot.destroy();
  };
}

function renderStats(refs, job) {
  const p = job.progress;
  const running = job.state === 'running';
  refs.rate.textContent = running ? formatRate(p.light_paths_per_second) : '—';
  refs.eta.textContent = running ? formatDuration(p.eta_seconds) : '—';
  refs.checkpointed.textContent = `${formatCount(p.iterations_checkpointed)} iterations`;
  refs.best.textContent = describeBest(p.best);
  refs.created.textContent = formatTime(job.created_at);
  refs.updated.textContent = formatTime(job.updated_at);
}

function renderSpec(dl, job) {
  const spec = job.spec;
  const rows = [
    ['Preset', spec.preset],
    ['Engine', spec.engine || 'brute'],
    [['Light paths ', symbol('N', 'F')], formatCount(spec.light_paths)],
    [['Camera paths ', symbol('N', 'B')], formatCount(spec.camera_paths)],
    [['Merge radius ', symbol('R')], formatParameter(spec.merge_radius)],
    [['Lobe width ', symbol('β')], `${formatParameter(spec.scene.beta_deg)}°`],
    [['Iterations ', symbol('M')], formatCount(spec.iterations)],
    ['Seed', String(spec.seed)],
    ['Illumination', describeIllumination(spec.scene.illumination)],
    ['Cells (r₂ × r₃ × φ)', `${spec.cells.r2_edges.length} × ${spec.cells.r3_edges.length} × ${spec.cells.phi_bins}`],
    [['Gradient penalty ', symbol('λ')], formatParameter(spec.solver.lambda)],
  ];
  if (spec.shard) rows.push(['Shard', `${spec.shard.index + 1} of ${spec.shard.count}`]);
  if (spec.first_iteration !== undefined) rows.push(['First iteration', formatCount(spec.first_iteration)]);
  if (job.merged) rows.push(['Merged', 'yes: the moments of several jobs added together']);
  dl.replaceChildren(...rows.map(([term, value]) => h('div', {}, h('dt', {}, term), h('dd', {}, value))));
}

/** A variable of the paper, such as N_F, in italics with its subscript. */
function symbol(name, subscript) {
  return h('var', {}, name, subscript ? h('sub', {}, subscript) : null);
}

function describeIllumination(ill) {
  switch (ill.kind) {
    case 'spot':
      return `spot: a = ${formatParameter(ill.a)}, r_ls = ${formatParameter(ill.r_ls)}, contrast ${formatParameter(ill.contrast)}`;
    case 'uniform':
      return `uniform: r_ls = ${formatParameter(ill.r_ls)}`;
    default:
      return `${ill.rings.length} rings`;
  }
}

/** Cancel while the job can still stop; Extend unless the server is known to refuse it. */
function renderActions(refs, job) {
  refs.cancel.hidden = TERMINAL.has(job.state);
  const refusal = job.state === 'failed' ? 'A failed job cannot be extended; submit a new one.'
    : job.merged ? 'A merged job cannot be extended; extend its parts and merge again.'
      : job.spec.shard ? 'A shard cannot be extended; extend the study instead.' : '';
  refs['extend-form'].hidden = Boolean(refusal);
  showMessage(refs['extend-note'], refusal);
}

// ---------------------------------------------------------------------------------------------
// Results: noise table and plots

/**
 * Fetches the result and history whenever a new checkpoint is written or the job ends, one fetch
 * at a time (a change during a fetch triggers one more).
 */
class ResultsLoader {
  constructor(id, refs, weightsPlot, historyPlot) {
    Object.assign(this, { id, refs, weightsPlot, historyPlot, shownKey: null, busy: false, again: false, stopped: false });
  }

  /** Leaves the page: answers still on their way are dropped. */
  stop() {
    this.stopped = true;
  }

  update(job) {
    this.job = job;
    const key = `${job.progress.iterations_checkpointed}:${TERMINAL.has(job.state)}`;
    if (key === this.shownKey) return;
    this.shownKey = key;
    if (job.progress.iterations_checkpointed === 0) {
      this.showNothing('No results yet: the job has not written its first checkpoint.');
    } else {
      this.fetch();
    }
  }

  async fetch() {
    if (this.busy) {
      this.again = true;
      return;
    }
    this.busy = true;
    try {
      const [result, history] = await Promise.all([
        api(`/v1/jobs/${this.id}/result`),
        api(`/v1/jobs/${this.id}/history`),
      ]);
      if (!this.stopped) this.show(result, history);
    } catch (error) {
      // 409: no checkpoint yet (or it is unreadable); the detail says which.
      // The next checkpoint tries again (not the next progress event: that would be 4 requests/s).
      if (!this.stopped) {
        this.showNothing(error.status === 409 ? `No results yet: ${error.message}` : `Cannot load the results: ${error.message}`);
      }
    } finally {
      this.busy = false;
      if (this.again && !this.stopped) {
        this.again = false;
        this.fetch();
      }
    }
  }

  showNothing(text) {
    const refs = this.refs;
    showMessage(refs['no-results'], text);
    refs['noise-table'].hidden = true;
    refs['result-status'].replaceChildren();
    showMessage(refs.reference, '');
    showMessage(refs['solve-error'], '');
    refs.merges.textContent = '';
    this.weightsPlot.clear('The weights appear after the first checkpoint.');
    this.historyPlot.clear('The RMS history appears after the first checkpoint.');
  }

  show(result, history) {
    const refs = this.refs;
    showMessage(refs['no-results'], '');
    refs['noise-table'].hidden = false;
    refs['result-status'].replaceChildren(result.partial
      ? h('span', { class: 'badge badge-partial', title: 'The numbers change as the job runs' },
        `partial · ${formatCount(result.iterations)} iterations`)
      : h('span', { class: 'badge badge-final' }, `final · ${formatCount(result.iterations)} iterations`));
    showMessage(refs.reference, result.reference_luminance === null ? ''
      : `Reference (quadrature): L·10⁵ = ${formatLuminance(result.reference_luminance)}`);
    const best = this.job.progress.best?.strategy;
    refs['noise-rows'].replaceChildren(...result.noise_table.map((row) => noiseRow(row, this.job.spec, best)));
    showMessage(refs['solve-error'], result.solve_error ? `The weight fit failed: ${result.solve_error}` : '');
    refs.merges.textContent = describeMerges(result.merges_per_iteration);
    drawWeights(this.weightsPlot, refs['weights-note'], result.weights, this.job.spec.cells.phi_bins);
    drawHistory(this.historyPlot, refs['history-note'], history.points);
  }
}

function noiseRow(row, spec, best) {
  const numbers = row.error
    ? [h('td', { class: 'row-error', colspan: 2 }, row.error)]
    : [
      h('td', { class: 'num' }, withError(row.luminance, row.luminance_stderr, formatLuminance)),
      h('td', { class: 'num' }, withError(row.rms_percent, row.rms_percent_stderr, formatRms)),
    ];
  return h('tr', { 'data-strategy': row.strategy, class: row.strategy === best ? 'best' : null },
    h('th', { scope: 'row' }, h('code', {}, row.strategy),
      row.strategy === best ? h('span', { class: 'best-mark', title: 'Lowest RMS among strategies that are not in-sample fits' }, 'best') : null),
    h('td', {}, describeWeights(row, spec)),
    ...numbers);
}

/** The weights of each strategy in words, as in the paper's Table 1. */
function describeWeights(row, spec) {
  switch (row.strategy) {
    case 'plane1': return 'w₀ = 1';
    case 'plane2': return 'w₁ = 1';
    case 'plane3': return 'w₂ = 1';
    case 'switch': return describeSwitch(spec.scene.illumination);
    case 'optimal': return `fitted (${describeSolver(spec.solver)})`;
    case 'optimal_holdout': return 'fitted, 2-fold hold-out';
    case 'optimal_cv': return describeCrossValidation(row);
    case 'balance': return 'balance heuristic';
    case 'power': return 'power heuristic';
    default: return '';
  }
}

/** Mirrors the server's switch radius: the spot's a, the innermost ring, none for uniform light. */
function describeSwitch(ill) {
  const a = ill.kind === 'spot' ? ill.a : ill.kind === 'rings' ? ill.rings[0].outer_radius : null;
  return a === null ? 'w₂ = 1 (no bright core to switch on)' : `w₁ = 1 if r₃ ≤ a, else w₂ = 1 (a = ${formatParameter(a)})`;
}

function describeSolver(solver) {
  const names = { w0: 'w₀', w1: 'w₁', w2: 'w₂' };
  const fixedWeights = Object.keys(names)
    .filter((w) => solver.fixed[w] !== undefined && solver.fixed[w] !== null)
    .map((w) => `${names[w]} = ${formatParameter(solver.fixed[w])}`);
  const parts = fixedWeights.length > 0 ? fixedWeights : ['all weights free'];
  if (solver.lambda > 0) parts.push(`λ = ${formatParameter(solver.lambda)}`);
  return parts.join(', ');
}

function describeCrossValidation(row) {
  const parts = [];
  if (row.lambda !== null) parts.push(`λ = ${formatParameter(row.lambda)}`);
  if (row.holdout_rms_percent !== null) parts.push(`hold-out RMS ${formatRms(row.holdout_rms_percent)} %`);
  return `fitted, λ by cross-validation${parts.length ? ` (${parts.join('; ')})` : ''}`;
}

function describeMerges(merges) {
  if (!merges) return '';
  const planes = ['plane1', 'plane2', 'plane3']
    .filter((p) => merges[p])
    .map((p) => `${p} ${withError(merges[p].mean, merges[p].stderr, (x) => fixed(x, x >= 10 ? 1 : 2))}`);
  return `Merges per iteration: ${planes.join(' · ')}`;
}

// ---------------------------------------------------------------------------------------------
// Plots

/** One uPlot chart in a container, rebuilt only when its series change; follows the page width. */
class PlotSlot {
  constructor(container) {
    this.container = container;
    this.plot = null;
    this.signature = '';
    this.onResize = () => this.plot?.setSize(this.size());
    window.addEventListener('resize', this.onResize);
  }

  size() {
    return { width: Math.max(280, this.container.clientWidth || 600), height: 300 };
  }

  draw(options, data) {
    const signature = JSON.stringify([options.series.map((s) => [s.label, s.points?.show]), options.axes.map((a) => a.label)]);
    if (this.plot && signature === this.signature) {
      this.plot.setData(data);
      return;
    }
    this.clear('');
    this.signature = signature;
    this.plot = new uPlot({ ...options, ...this.size() }, data, this.container);
  }

  clear(message) {
    this.plot?.destroy();
    this.plot = null;
    this.signature = '';
    this.container.replaceChildren(...(message ? [h('p', { class: 'empty' }, message)] : []));
  }

  destroy() {
    window.removeEventListener('resize', this.onResize);
    this.plot?.destroy();
  }
}

function formatInterval([lo, hi]) {
  return hi === null ? `≥ ${formatParameter(lo)}` : `∈ [${formatParameter(lo)}, ${formatParameter(hi)})`;
}

/** Unique intervals of one coordinate of the cells, in order. */
function intervals(cells, key) {
  const seen = new Map();
  for (const cell of cells) seen.set(cell[key][0], cell[key]);
  return [...seen.values()].sort((a, b) => a[0] - b[0]);
}

// Cells whose weights the server copied from a neighbour because the data say nothing about them.
const UNFITTED = new Set(['empty', 'uninformative']);

/**
 * The optimal w₁ and w₂ per (r₂ band, r₃ cell), the mean over the φ bins that were fitted (cells
 * without informative samples become gaps). x is the r₃ cell centre; the open tail cell [lo, ∞) is put
 * one previous-cell width past lo.
 */
function weightSeries(weights) {
  const r2Bands = intervals(weights, 'r2');
  const r3Cells = intervals(weights, 'r3');
  const x = r3Cells.map(([lo, hi], i) => {
    if (hi !== null) return (lo + hi) / 2;
    return i > 0 ? lo + (lo - r3Cells[i - 1][0]) : lo;
  });
  const bands = r2Bands.map((band) => {
    const mean = (component) => r3Cells.map((cell) => {
      const values = weights
        .filter((w) => w.r2[0] === band[0] && w.r3[0] === cell[0] && !UNFITTED.has(w.status))
        .map((w) => w[component]);
      return values.length ? values.reduce((a, b) => a + b, 0) / values.length : null;
    });
    return { band, w1: mean('w1'), w2: mean('w2') };
  });
  return { x, tail: r3Cells.at(-1), tailX: x.at(-1), bands };
}

const BAND_DASHES = [[], [8, 4], [2, 3], [12, 3, 2, 3]];
const W1_COLORS = ['#1f5fa8', '#5b9bd5', '#9cc3e6', '#0b3d6b'];
const W2_COLORS = ['#c4561d', '#f08c4a', '#f5b88d', '#7a3510'];

function drawWeights(slot, note, weights, phiBins) {
  if (weights.length === 0) {
    slot.clear('No fitted weights in this result.');
    showMessage(note, '');
    return;
  }
  const { x, tail, tailX, bands } = weightSeries(weights);
  const phi = phiBins > 1 ? ` · mean of ${phiBins} φ bins` : '';
  const series = [{ label: `r₃${phi}`, value: (u, v) => (v === null ? '—' : formatParameter(v)) }];
  const data = [x];
  bands.forEach(({ band, w1, w2 }, i) => {
    const dash = BAND_DASHES[i % BAND_DASHES.length];
    const r2 = `r₂ ${formatInterval(band)}`;
    series.push(weightLine(`w₁, ${r2}`, W1_COLORS[i % W1_COLORS.length], dash));
    series.push(weightLine(`w₂, ${r2}`, W2_COLORS[i % W2_COLORS.length], dash));
    data.push(w1, w2);
  });
  const tailLabel = tail[1] === null ? `; tail r₃ ≥ ${formatParameter(tail[0])} drawn at ${formatParameter(tailX)}` : '';
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: weightRange } },
    axes: [{ label: `r₃ (cell centre${tailLabel})` }, { label: 'weight' }],
    cursor: { drag: { x: true, y: false } },
  }, data);
  const clipped = data.slice(1).flat().filter((v) => v !== null && (v < WEIGHT_RANGE[0] || v > WEIGHT_RANGE[1])).length;
  const gaps = 'Gaps are cells without informative samples.';
  const cut = clipped ? ` ${clipped} value${clipped > 1 ? 's lie' : ' lies'} outside [${WEIGHT_RANGE.join(', ')}] and ${clipped > 1 ? 'are' : 'is'} cut off (usually cells with few samples).` : '';
  showMessage(note, gaps + cut);
}

function weightLine(label, stroke, dash) {
  return { label, stroke, dash, width: 2, points: { show: true, size: 4 }, value: (u, v) => (v === null ? '—' : fixed(v, 3)) };
}

/** Fits the data, but never beyond WEIGHT_RANGE, and always shows 0 and 1. */
function weightRange(u, min, max) {
  const lo = Math.max(WEIGHT_RANGE[0], Math.min(min ?? 0, 0));
  const hi = Math.min(WEIGHT_RANGE[1], Math.max(max ?? 1, 1));
  const pad = 0.05 * (hi - lo);
  return [lo - pad, hi + pad];
}

function drawHistory(slot, note, points) {
  if (points.length === 0) {
    slot.clear('No checkpoints yet.');
    showMessage(note, '');
    return;
  }
  const x = points.map((p) => p.iterations);
  const series = [{ label: 'iterations', value: (u, v) => (v === null ? '—' : formatCount(v)) }];
  const data = [x];
  for (const strategy of STRATEGIES) {
    // Log scale: a missing or non-positive RMS becomes a gap.
    data.push(points.map((p) => {
      const rms = p.strategies.find((s) => s.strategy === strategy)?.rms_percent;
      return rms > 0 ? rms : null;
    }));
    series.push({
      label: strategy, stroke: STRATEGY_COLORS[strategy], width: 2, points: { show: points.length < 40, size: 4 },
      value: (u, v) => (v === null ? '—' : `${formatRms(v)} %`),
    });
  }
  slot.draw({
    series,
    scales: { x: { time: false }, y: { distr: 3 } },
    axes: [{ label: 'iterations' }, { label: 'RMS error (%, log scale)', size: 60 }],
  }, data);
  showMessage(note, points.length === 1 ? 'One checkpoint so far: lines appear from the second on.' : '');
}

// ---------------------------------------------------------------------------------------------
// Start: last, so that every declaration above is initialised before a page uses it.

window.addEventListener('hashchange', route);
route();
