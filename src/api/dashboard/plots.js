// Plots: the uPlot charts of a job's history — the luminance against iterations (± 1 SE bands, the
// quadrature reference) and the RMS against iterations — and what every chart shares (the chart
// slot, the strategies' order and colours, the weights' range, cells and effective-weight bins as
// chart data; Fig. 2 is fig2.js's, the sweep's weight panels sweepw1.js's).
// uPlot is the vendored library, loaded before this module as a classic script (a global); the
// plugins are chartkit.js's, the axes' ticks and sizes and the legend's values axes.js's.

/* global uPlot */

import { axis, legendValue } from './axes.js';
import { bands, extent, guides, linearRange } from './chartkit.js';
import { fixed, formatCount, formatLuminance, formatParameter, formatRms, h, showMessage } from './format.js';
import { luminanceStderr } from './paper.js';

// Every strategy of a noise table, in the server's order (docs/model.md §8): the paper's cases, the
// fits of a table, the heuristics, the heuristics over planes 2–3 (w₀ = 0), the stacked optimum and
// each stackable heuristic corrected by a table (with w₀ free every heuristic is stackable).
export const STRATEGIES = [
  'plane1', 'plane2', 'plane3', 'switch', 'optimal', 'optimal_holdout', 'optimal_cv', 'balance', 'power', 'correlation_aware',
  'balance_planes23', 'power_planes23', 'correlation_aware_planes23', 'optimal_stacked', 'switch_corrected', 'balance_corrected',
  'power_corrected', 'correlation_aware_corrected', 'balance_planes23_corrected', 'power_planes23_corrected',
  'correlation_aware_planes23_corrected',
];
// Eleven distinct hues, one per family: a heuristic's variants keep its hue and are told apart by
// their dash — over planes 2–3 dashed, corrected by a table dotted, both dash-dotted — so that the
// 21 lines of a chart stay distinguishable (issue 42, item 7: shades of grey were not).
const FAMILY_COLORS = {
  plane1: '#8c564b', plane2: '#1f77b4', plane3: '#2ca02c', switch: '#9467bd', optimal: '#d62728',
  optimal_holdout: '#ff7f0e', optimal_cv: '#e377c2', optimal_stacked: '#1a237e', balance: '#17becf', power: '#7f7f7f',
  correlation_aware: '#bcbd22',
};
const familyOf = (strategy) => strategy.replace(/_corrected$/, '').replace(/_planes23$/, '');
const STRATEGY_COLORS = Object.fromEntries(STRATEGIES.map((s) => [s, FAMILY_COLORS[familyOf(s)]]));
/** The dash of a strategy's line: [] solid, dashed over planes 2–3, dotted corrected, dash-dotted both. */
export function strategyDash(strategy) {
  const planes = /_planes23(_corrected)?$/.test(strategy);
  const corrected = strategy.endsWith('_corrected');
  return planes && corrected ? [8, 3, 2, 3] : planes ? [8, 4] : corrected ? [2, 3] : [];
}
export const strategyColor = (strategy) => STRATEGY_COLORS[strategy] ?? '#444';

/**
 * The strategies named in `lists` (each a list of rows with a `strategy`), in the order of
 * STRATEGIES, then any this page does not know, in the order they come.
 */
export function strategiesIn(lists) {
  const seen = [...new Set(lists.flatMap((rows) => rows.map((r) => r.strategy)))];
  return [...STRATEGIES.filter((s) => seen.includes(s)), ...seen.filter((s) => !STRATEGIES.includes(s))];
}

// The weights plot clips the y axis to this range: with few samples a cell's fitted weights can be
// in the hundreds, which would flatten every other cell to a line.
export const WEIGHT_RANGE = [-1, 2];

// The frame of the job page's Fig. 2 panels and the sweep's weight panels: every sensible weight
// with room around [0, 1]. A value beyond it (an in-sample cell fitted to noise, 94.6 ± 84) is not
// cut off silently: chartkit.js's edgeMarks marks it at the frame's edge with its value.
export const WEIGHT_FRAME = [-0.5, 1.5];

// The chart drawn in each container, for the browser test (plotOf).
const drawn = new WeakMap();

/** The uPlot instance drawn in `container`, if any (the browser test reads its axes through it). */
export const plotOf = (container) => drawn.get(container)?.plot ?? null;

/**
 * One uPlot chart in a container, rebuilt only when its series change; follows the page width.
 * `title` names it in its downloads; `bars`, `bands` and `guides` are its extras (chartkit.js).
 */
export class PlotSlot {
  constructor(container, title = '') {
    this.container = container;
    this.title = title;
    this.plot = null;
    this.signature = '';
    this.height = 300;
    this.onResize = () => this.plot?.setSize(this.size());
    window.addEventListener('resize', this.onResize);
    drawn.set(container, this);
  }

  size() {
    return { width: Math.max(200, this.container.clientWidth || 600), height: this.height };
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
    // What the chart kit's plugins reported drawing (data-markers, …) is no longer on the page.
    for (const key of Object.keys(this.container.dataset)) if (key !== 'ref') delete this.container.dataset[key];
    this.container.replaceChildren(...(message ? [h('p', { class: 'empty' }, message)] : []));
  }

  destroy() {
    window.removeEventListener('resize', this.onResize);
    this.plot?.destroy();
  }
}

// Cells whose weights the server copied from a neighbour because the data say nothing about them.
export const UNFITTED = new Set(['empty', 'uninformative']);

/**
 * Fits the data, but never beyond WEIGHT_RANGE, and always shows `shown` (0 and 1 for weights;
 * 0 alone for a table part, whose cells sum to 1 − Σβ and may all be small).
 */
export function weightRange(u, min, max, shown = [0, 1], limits = WEIGHT_RANGE) {
  const lo = Math.max(limits[0], Math.min(min ?? shown[0], ...shown));
  const hi = Math.min(limits[1], Math.max(max ?? shown.at(-1), ...shown));
  const pad = 0.05 * (hi - lo) || 0.05;
  return [lo - pad, hi + pad];
}

/**
 * Where each r₃ bin (`bins`: [lo, hi] in order) sits on a chart's x axis: its midpoint; the open
 * tail bin [lo, ∞) at lo + the previous bin's width — it has no midpoint, and there it reads as
 * "one step beyond the grid" rather than as a point inside the last finite bin.
 */
export const r3Positions = (bins) => bins.map((b, k) => {
  if (b[1] !== null) return (b[0] + b[1]) / 2;
  return b[0] + (k > 0 ? b[0] - bins[k - 1][0] : Math.max(b[0], 1e-3));
});

/** The right end of an x axis over `bins` (r3Positions): the last finite edge, or half a step past the tail bin. */
export function r3AxisEnd(bins, x) {
  const last = bins.at(-1);
  if (!last) return 1;
  return last[1] !== null ? last[1] : x.at(-1) + (x.at(-1) - last[0]) / 2;
}

/**
 * An effective-weights document (GET /v1/jobs/{id}/effective) as chart data: the r₃ bins and their
 * x positions (r3Positions), and per r₂ bin w₀, w₁, w₂ with their total standard errors, null where
 * no sampled path of the bin carries light (its `w` is null: no weight matters there), `drawn` how
 * many of its bins have weights.
 */
export function effectiveSeries(doc) {
  const r3 = binsOf(doc.bins, 'r3');
  const x = r3Positions(r3);
  const series = binsOf(doc.bins, 'r2').map((r2) => {
    const at = new Map(doc.bins.filter((b) => b.r2[0] === r2[0]).map((b) => [b.r3[0], b]));
    const bins = r3.map((b) => at.get(b[0]) ?? null);
    const w = (m) => bins.map((b) => (b?.w ? b.w[m] : null));
    const err = (m) => bins.map((b) => (b?.w && b.stderr ? b.stderr[m] : null));
    return { r2, bins, w0: w(0), w1: w(1), w2: w(2), err1: err(1), err2: err(2), drawn: bins.filter((b) => b?.w).length };
  });
  return { r3, x, end: r3AxisEnd(r3, x), series };
}

/** An r₂ bin in words: `r₂ ∈ [0, 0.5)`, `r₂ ≥ 0.5` for the open one. */
export const r2Words = (r2) => (r2[1] === null ? `r₂ ≥ ${formatParameter(r2[0])}` : `r₂ ∈ ${formatInterval(r2)}`);

/**
 * Splits the values `y` of a series at the y range [lo, hi]: `inside` keeps the values within it
 * (null beyond: the line breaks there rather than running off the frame), `outside` lists the
 * others with their index, for chartkit.js's edgeMarks.
 */
export function splitAtRange(y, [lo, hi]) {
  const beyond = (v) => v !== null && v !== undefined && (v < lo || v > hi);
  return {
    inside: y.map((v) => (beyond(v) ? null : v)),
    outside: y.flatMap((v, i) => (beyond(v) ? [{ i, value: v }] : [])),
  };
}

/** An interval of a cell coordinate in words: `[0, 0.5)`, `[0.5, ∞)`. */
export const formatInterval = ([lo, hi]) => `[${formatParameter(lo)}, ${hi === null ? '∞' : formatParameter(hi)})`;

/** The lower edges of a coordinate's bins among `weights`, in order. */
export const binsOf = (weights, key) => [...new Map(weights.map((w) => [w[key][0], w[key]])).values()].sort((a, b) => a[0] - b[0]);

/** The spot's radius a as a vertical guide (the switch strategy's r₃ ≤ a), when the light is a spot. */
export function spotGuide(illumination, label = 'r₃ = a') {
  return illumination.kind === 'spot' ? [{ value: illumination.a, label: `${label} = ${formatParameter(illumination.a)}` }] : [];
}

// Shown at first on the luminance chart (the others are a click on the legend away): the paper's
// fixed cases, the cross-validated table and the recommended row; the in-sample optimum is
// optimistic, the other heuristics and fits crowd it.
const LUMINANCE_SHOWN = new Set(['plane1', 'plane2', 'plane3', 'switch', 'optimal_cv']);

/** The strategies the luminance chart shows at first, given the recommended one. */
export const luminanceShown = (recommended) => new Set([...LUMINANCE_SHOWN, ...(recommended ? [recommended] : [])]);

/**
 * The luminance of every strategy against iterations (× 10⁵, as the table), each with a band of
 * ± 1 SE, SE(L) = L · (RMS/100) / √M, and the quadrature reference (R → 0) as a horizontal line.
 */
export function drawLuminance(slot, note, points, reference, recommended) {
  if (points.length === 0) {
    slot.clear('No checkpoints yet.');
    showMessage(note, '');
    return;
  }
  const x = points.map((p) => p.iterations);
  const series = [{ label: 'iterations', value: legendValue(formatCount) }];
  const data = [x];
  slot.bands = [];
  const shown = luminanceShown(recommended);
  for (const strategy of strategiesIn(points.map((p) => p.strategies))) {
    const rows = points.map((p) => p.strategies.find((s) => s.strategy === strategy) ?? null);
    const y = rows.map((r) => (r && Number.isFinite(r.luminance) ? r.luminance * 1e5 : null));
    const se = rows.map((r, i) => (y[i] === null ? null : luminanceStderr(r.luminance, r.rms_percent, points[i].iterations)));
    data.push(y);
    slot.bands.push({
      lo: y.map((v, i) => (v === null || se[i] === null ? null : v - se[i] * 1e5)),
      hi: y.map((v, i) => (v === null || se[i] === null ? null : v + se[i] * 1e5)),
      color: strategyColor(strategy),
    });
    const k = slot.bands.length - 1;
    series.push({
      label: strategy === 'optimal' ? 'optimal (in-sample)' : strategy, stroke: strategyColor(strategy), dash: strategyDash(strategy), width: 2, spanGaps: true,
      show: shown.has(strategy), points: { show: points.length < 40, size: 4 },
      value: legendValue((v, i) => {
        const band = slot.bands[k];
        return `${fixed(v, 2)}${band?.hi[i] === null || band?.hi[i] === undefined ? '' : ` ± ${fixed(band.hi[i] - v, 2)}`}`;
      }),
    });
  }
  slot.guides = { x: [], y: reference === null ? [] : [{ value: reference * 1e5, label: `reference R → 0 (quadrature) ${formatLuminance(reference)}` }] };
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: (u) => linearRange(extent(u, slot, false)) } },
    axes: [axis({ label: 'iterations M' }), axis({ label: 'L·10⁵ (± 1 SE band)' })],
    plugins: [bands(slot), guides(slot)],
  }, data);
  showMessage(note, `Bands: ± 1 standard error, L · (RMS/100) / √M at each checkpoint. Dashed: the quadrature reference in the limit R → 0${reference === null ? ' (none for this scene)' : ''}; at the job's R a strategy may expect another L (the noise table's z is taken against that). Shown at first: the paper's cases 1–4, optimal_cv and the recommended row; click a legend entry to show or hide a strategy; the in-sample optimum is optimistic.${points.length === 1 ? ' One checkpoint so far: lines appear from the second on.' : ''}`);
}

export function drawHistory(slot, note, points) {
  if (points.length === 0) {
    slot.clear('No checkpoints yet.');
    showMessage(note, '');
    return;
  }
  const x = points.map((p) => p.iterations);
  const series = [{ label: 'iterations', value: legendValue(formatCount) }];
  const data = [x];
  for (const strategy of strategiesIn(points.map((p) => p.strategies))) {
    // Log scale: a missing or non-positive RMS becomes a gap.
    data.push(points.map((p) => {
      const rms = p.strategies.find((s) => s.strategy === strategy)?.rms_percent;
      return rms > 0 ? rms : null;
    }));
    series.push({
      label: strategy, stroke: strategyColor(strategy), dash: strategyDash(strategy), width: 2, spanGaps: true, points: { show: points.length < 40, size: 4 },
      value: legendValue((v) => `${formatRms(v)} %`),
    });
  }
  // One object for the slot's life: a redraw with the same series keeps the first options (and
  // their range function), which updates this object.
  slot.historyClip ??= { early: false };
  const clipped = slot.historyClip;
  slot.draw({
    series,
    scales: { x: { time: false }, y: { distr: 3, range: (u) => settledRange(u, clipped) } },
    axes: [axis({ label: 'iterations M' }), axis({ label: 'RMS error (%, log scale)' }, true)],
  }, data);
  const notes = [];
  if (points.length === 1) notes.push('One checkpoint so far: lines appear from the second on.');
  if (clipped.early) notes.push('The axis follows the checkpoints after the first tenth of the iterations: earlier, noisier figures above it are cut off (hover the line for them).');
  showMessage(note, notes.join(' '));
}

/**
 * The log axis of the RMS history: spanned by the visible values from the first tenth of the
 * iterations on, padded — one early checkpoint of a fitted row (a few hundred iterations, 1,300 %)
 * would otherwise squeeze every later line into the bottom of the chart. Sets `clipped.early`
 * when an earlier value lies above the axis.
 */
function settledRange(u, clipped) {
  const x = u.data[0];
  const settledFrom = 0.1 * (x[x.length - 1] ?? 0);
  let lo = Infinity;
  let hi = -Infinity;
  let earlyHi = -Infinity;
  u.data.slice(1).forEach((ys, s) => {
    if (u.series[s + 1] && !u.series[s + 1].show) return;
    ys.forEach((y, i) => {
      if (!(y > 0)) return;
      lo = Math.min(lo, y);
      if (x[i] >= settledFrom || x.length <= 2) hi = Math.max(hi, y);
      else earlyHi = Math.max(earlyHi, y);
    });
  });
  if (!Number.isFinite(hi)) hi = earlyHi;
  if (!Number.isFinite(lo) || !Number.isFinite(hi)) return [1, 100];
  clipped.early = earlyHi > hi * 1.25;
  return [lo / 1.25, hi * 1.25];
}
