// API: every call to the server (/v1/jobs…, /v1/sweeps…, the job event stream, downloads) and the
// bearer token they carry; saving a file made in the page.
// Imports nothing of ours: the sign-in banner a 401 asks for is app.js's, hooked in with
// `whenUnauthorized`.

/** The states a job never leaves. */
export const TERMINAL = new Set(['succeeded', 'failed', 'cancelled']);

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

// What a 401 answer does: app.js (which owns the page) sets it to show the sign-in banner.
let onUnauthorized = () => {};

/** Sets what a 401 answer does (with the problem's `detail` as its argument). */
export function whenUnauthorized(handler) {
  onUnauthorized = handler;
}

/** Keeps the token for this tab: every later call carries it. */
export function saveToken(token) {
  sessionStorage.setItem(TOKEN_KEY, token);
}

/** Whether this tab carries a token (then a plain link to the API would be refused). */
export function hasToken() {
  return Boolean(sessionStorage.getItem(TOKEN_KEY));
}

/**
 * Fetches `path` with the token and saves it (for downloads a plain link cannot carry the token
 * to), under the name the server's Content-Disposition gives, else `filename`.
 */
export async function download(path, filename) {
  const response = await fetch(path, { headers: authHeaders() });
  if (response.status === 401) onUnauthorized();
  if (!response.ok) throw new ApiError(`${response.status} ${response.statusText}`, response.status);
  const named = /filename="([^"]+)"/.exec(response.headers.get('content-disposition') ?? '')?.[1];
  saveBlob(await response.blob(), named || filename);
}

/** Saves `blob` as a file named `filename` (a download made in the page, such as a CSV or a chart). */
export function saveBlob(blob, filename) {
  const url = URL.createObjectURL(blob);
  const link = Object.assign(document.createElement('a'), { href: url, download: filename });
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

/** Calls the API; throws an ApiError in plain words (the problem's `detail`) on any failure. */
export async function api(path, { method = 'GET', body } = {}) {
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
  if (response.status === 401) onUnauthorized(data?.detail);
  if (!response.ok) {
    const detail = data?.detail || data?.title || `${response.status} ${response.statusText}`;
    throw new ApiError(detail, response.status, data?.field);
  }
  return data;
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
export function streamJob(id, { onJob, onLost }) {
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
