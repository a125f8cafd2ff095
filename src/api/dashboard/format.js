// DOM and formatting helpers: building elements, filling templates, and numbers, times and job
// states in words. Imports nothing of ours.

/** Creates an element; `props` are attributes except `class`, `text` and `style` (an object). */
export function h(tag, props = {}, ...children) {
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
export function instantiate(id) {
  const fragment = document.getElementById(id).content.cloneNode(true);
  const refs = {};
  for (const el of fragment.querySelectorAll('[data-ref]')) refs[el.dataset.ref] = el;
  return { fragment, refs };
}

export function showMessage(el, text) {
  el.textContent = text || '';
  el.hidden = !text;
}

const integerFormat = new Intl.NumberFormat(undefined, { maximumFractionDigits: 0 });
const compactFormat = new Intl.NumberFormat(undefined, { notation: 'compact', maximumSignificantDigits: 3 });
const timeFormat = new Intl.DateTimeFormat(undefined, { dateStyle: 'medium', timeStyle: 'medium' });

export function fixed(x, digits) {
  return x.toLocaleString(undefined, { minimumFractionDigits: digits, maximumFractionDigits: digits });
}

export const formatCount = (n) => integerFormat.format(n);
export const formatRate = (perSecond) => (perSecond === null ? '—' : compactFormat.format(perSecond));
export const formatTime = (iso) => timeFormat.format(new Date(iso));

/** Month, day and minute, plus the year when it is not this one: for the narrow list column. */
export function formatShortTime(iso) {
  const date = new Date(iso);
  const options = { month: 'short', day: 'numeric', hour: '2-digit', minute: '2-digit' };
  if (date.getFullYear() !== new Date().getFullYear()) options.year = 'numeric';
  return date.toLocaleString(undefined, options);
}
/** Luminance in units of 10⁻⁵, as the paper's Table 1 prints it. */
export const formatLuminance = (l) => fixed(l * 1e5, 2);
/** RMS in percent: one decimal is plenty above 10 %, two below. */
export const formatRms = (rms) => fixed(rms, rms >= 10 ? 1 : 2);

export function formatDuration(seconds) {
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
export function formatParameter(x) {
  const exponent = Math.log10(Math.abs(x));
  if (x !== 0 && Number.isInteger(exponent) && Math.abs(exponent) >= 3) {
    const power = `10${[...String(exponent)].map((c) => SUPERSCRIPTS[c]).join('')}`;
    return x < 0 ? `−${power}` : power;
  }
  return String(Number(x.toPrecision(6)));
}

/**
 * A number over a wide range to `digits` significant digits: as itself from 0.01 to 99,999
 * (414, 12,300, 0.042), else mantissa·10ⁿ (3.16·10⁷, 4.2·10⁻³), a power of ten alone (10⁸).
 */
export function formatScientific(x, digits = 3) {
  if (x === null || x === undefined || !Number.isFinite(x)) return '—';
  if (x === 0) return '0';
  const rounded = Number(x.toPrecision(digits));
  const e = Math.floor(Math.log10(Math.abs(rounded)) + 1e-12);
  if (e >= -2 && e < 5) return rounded.toLocaleString(undefined, { maximumFractionDigits: 12 });
  const m = Number((rounded / 10 ** e).toPrecision(digits));
  const power = `10${[...String(e)].map((c) => SUPERSCRIPTS[c]).join('')}`;
  return m === 1 ? power : `${String(m).replace('-', '−')}·${power}`;
}

/**
 * A value ± its error over a wide range (formatScientific's), with a real minus: as themselves
 * when the value prints plainly (`0.0118 ± 2·10⁻⁵`, `3.3 ± 1.64`), else both on the value's power
 * of ten (`(4.06 ± 0.476)·10⁵`, `(−2.03 ± 0.2)·10⁻⁴`); without an error, the value alone.
 */
export function formatScientificWithError(x, se) {
  const minus = (text) => text.replace(/^-/, '−');
  if (se === null || se === undefined || !Number.isFinite(x) || x === 0) {
    return se === null || se === undefined ? minus(formatScientific(x)) : `${minus(formatScientific(x))} ± ${formatScientific(se)}`;
  }
  const e = Math.floor(Math.log10(Math.abs(Number(x.toPrecision(3)))) + 1e-12);
  if (e >= -2 && e < 5) return `${minus(formatScientific(x))} ± ${formatScientific(se)}`;
  const mantissa = (v) => minus(String(Number((v / 10 ** e).toPrecision(3))));
  const power = `10${[...String(e)].map((c) => SUPERSCRIPTS[c]).join('')}`;
  return `(${mantissa(x)} ± ${mantissa(se)})·${power}`;
}

/** A number with a real minus sign: `−0.126`. */
export const signed = (x, digits) => `${x < 0 ? '−' : ''}${fixed(Math.abs(x), digits)}`;

/** β of every heuristic stacked on a table, in words: `switch −0.126 ± 0.015, power_planes23 0.510 ± 1.212`. */
export function formatBetas(heuristics) {
  return heuristics.map((b) => `${b.strategy} ${signed(b.beta, 3)}${b.beta_stderr === null || b.beta_stderr === undefined ? '' : ` ± ${fixed(b.beta_stderr, 3)}`}`).join(', ');
}

export function withError(value, error, format) {
  return error === null || error === undefined ? format(value) : `${format(value)} ± ${format(error)}`;
}

export function badge(state) {
  return h('span', { class: `badge badge-${state}` }, state);
}

/** A progress bar element; `updateProgress` fills it in. */
export function progressBar() {
  return h('div', { class: 'progress', role: 'progressbar', 'aria-label': 'Iterations done', 'aria-valuemin': 0 },
    h('div', { class: 'progress-fill' }), h('span', { class: 'progress-text' }));
}

export function updateProgress(bar, job) {
  const { iterations_done: done, iterations_total: total } = job.progress;
  bar.setAttribute('aria-valuenow', done);
  bar.setAttribute('aria-valuemax', total);
  bar.dataset.state = job.state;
  bar.querySelector('.progress-fill').style.width = `${total > 0 ? Math.min(100, (100 * done) / total) : 0}%`;
  bar.querySelector('.progress-text').textContent = `${formatCount(done)} / ${formatCount(total)}`;
}

export function describeBest(best) {
  return best ? `${best.strategy} · ${formatRms(best.rms_percent)} %` : '—';
}

/** Whether resource `a` is at least as recent as `b` (poll answers can overtake stream events). */
export function isNewer(a, b) {
  if (a.updated_at !== b.updated_at) return a.updated_at > b.updated_at;
  return a.progress.iterations_done >= b.progress.iterations_done;
}
