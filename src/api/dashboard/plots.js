// Plots: the uPlot charts of a job's result — the recommended w₁ against r₃ (the paper's Fig. 2,
// ± 1 SE bars, the r₃ = a marker), the luminance against iterations (± 1 SE bands, the quadrature
// reference) and the RMS against iterations — and what every chart shares (the chart slot, the
// strategies' colours, the weights' range). uPlot is the vendored library, loaded before this
// module as a classic script (a global); the plugins are chartkit.js's.

/* global uPlot */

import { bands, errorBars, extent, guides, linearRange } from './chartkit.js';
import { fixed, formatCount, formatLuminance, formatParameter, formatRms, h, showMessage } from './format.js';
import { luminanceStderr } from './paper.js';

export const STRATEGIES = [
  'plane1', 'plane2', 'plane3', 'switch', 'optimal', 'optimal_holdout', 'optimal_cv', 'balance', 'power', 'correlation_aware',
];
export const STRATEGY_COLORS = {
  plane1: '#8c564b', plane2: '#1f77b4', plane3: '#2ca02c', switch: '#9467bd', optimal: '#d62728',
  optimal_holdout: '#ff7f0e', optimal_cv: '#e377c2', balance: '#17becf', power: '#7f7f7f', correlation_aware: '#bcbd22',
};
// The weights plot clips the y axis to this range: with few samples a cell's fitted weights can be
// in the hundreds, which would flatten every other cell to a line.
export const WEIGHT_RANGE = [-1, 2];

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

// Cells whose weights the server copied from a neighbour because the data say nothing about them.
export const UNFITTED = new Set(['empty', 'uninformative']);

/** Fits the data, but never beyond WEIGHT_RANGE, and always shows 0 and 1. */
export function weightRange(u, min, max) {
  const lo = Math.max(WEIGHT_RANGE[0], Math.min(min ?? 0, 0));
  const hi = Math.min(WEIGHT_RANGE[1], Math.max(max ?? 1, 1));
  const pad = 0.05 * (hi - lo);
  return [lo - pad, hi + pad];
}

/** An interval of a cell coordinate in words: `[0, 0.5)`, `[0.5, ∞)`. */
export const formatInterval = ([lo, hi]) => `[${formatParameter(lo)}, ${hi === null ? '∞' : formatParameter(hi)})`;

/** The lower edges of a coordinate's bins among `weights`, in order. */
export const binsOf = (weights, key) => [...new Map(weights.map((w) => [w[key][0], w[key]])).values()].sort((a, b) => a[0] - b[0]);

/**
 * The paper's Fig. 2 from a result's `weights`: w₁ against the r₃ cell midpoint, one series per r₂
 * bin, in the first φ bin (the paper finds the weights independent of φ); the open tail cell of r₃
 * is left out, and cells whose weights were copied from a neighbour are gaps. `err` is the
 * jackknife standard error of w₁.
 */
export function figure2(weights) {
  const phi = binsOf(weights, 'phi')[0];
  const cells = weights.filter((w) => w.phi[0] === phi[0] && w.r3[1] !== null);
  const mid = (w) => (w.r3[0] + w.r3[1]) / 2;
  const x = [...new Set(cells.map(mid))].sort((a, b) => a - b);
  const series = binsOf(cells, 'r2').map((r2) => {
    const at = new Map(cells.filter((w) => w.r2[0] === r2[0] && !UNFITTED.has(w.status)).map((w) => [mid(w), w]));
    return { r2, y: x.map((v) => at.get(v)?.w1 ?? null), err: x.map((v) => at.get(v)?.w1_stderr ?? null) };
  });
  return { x, series, phi, phiBins: binsOf(weights, 'phi').length };
}

const R2_COLORS = ['#1f5fa8', '#c4561d', '#2ca02c', '#9467bd'];

/** The value shown in a legend: w₁ ± its SE. */
const withBar = (slot, k) => (u, v, si, i) => {
  const e = slot.bars?.[k]?.err[i];
  return v === null ? '—' : `${fixed(v, 3)}${e === null || e === undefined ? '' : ` ± ${fixed(e, 3)}`}`;
};

/** The spot's radius a as a vertical guide (the switch strategy's r₃ ≤ a), when the light is a spot. */
export function spotGuide(illumination, label = 'r₃ = a') {
  return illumination.kind === 'spot' ? [{ value: illumination.a, label: `${label} = ${formatParameter(illumination.a)}` }] : [];
}

export function drawWeights(slot, note, weights, spec, fit) {
  if (weights.length === 0) {
    slot.clear('No fitted weights in this result.');
    showMessage(note, '');
    return;
  }
  const { x, series: bins, phi, phiBins } = figure2(weights);
  slot.bars = bins.map((b, k) => ({ err: b.err, color: R2_COLORS[k % R2_COLORS.length] }));
  slot.guides = { x: spotGuide(spec.scene.illumination), y: [] };
  const series = [{ label: 'r₃', value: (u, v) => (v === null ? '—' : formatParameter(v)) }];
  bins.forEach((b, k) => series.push({
    label: `w₁, r₂ ∈ ${formatInterval(b.r2)}`, stroke: slot.bars[k].color, width: 2, dash: k ? [8, 4] : [],
    points: { show: true, size: 5 }, value: withBar(slot, k),
  }));
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: (u, min, max) => weightRange(u, ...(extent(u, slot, false) ?? [min, max])) } },
    axes: [{ label: `r₃ (cell midpoint)${phiBins > 1 ? `, φ ∈ ${formatInterval(phi.map((v) => Number(v.toFixed(3))))}` : ''}` }, { label: 'w₁' }],
    cursor: { drag: { x: true, y: false } },
    plugins: [errorBars(slot), guides(slot)],
  }, [x, ...bins.map((b) => b.y)]);
  const clipped = bins.flatMap((b) => b.y).filter((v) => v !== null && (v < WEIGHT_RANGE[0] || v > WEIGHT_RANGE[1])).length;
  const w0 = spec.solver.fixed?.w0;
  const parts = [fit
    ? (fit.strategy === 'optimal'
      ? `Weights fitted in-sample on all iterations at λ = ${formatParameter(fit.lambda)} (the cross-validated fit failed).`
      : `Recommended weights: ${fit.strategy}, λ = ${formatParameter(fit.lambda)} chosen by cross-validation, fitted on all iterations.`)
    : '',
  'Bars: ± 1 jackknife standard error of w₁.',
  w0 === 0 ? 'w₂ = 1 − w₁ (w₀ = 0 is fixed), so it is not drawn.' : 'w₂ = 1 − w₀ − w₁; w₀ and w₂ are in the weights CSV.',
  `The open tail cell r₃ ≥ ${formatParameter(x.length ? binsOf(weights, 'r3').at(-1)[0] : 0)} is left out; gaps are cells without informative samples.`];
  if (phiBins > 1) parts.push(`First of ${phiBins} φ bins.`);
  if (slot.guides.x.length) parts.push('Dashed line: the spot radius a, where the switch strategy changes plane.');
  if (clipped) parts.push(`${clipped} value${clipped > 1 ? 's lie' : ' lies'} outside [${WEIGHT_RANGE.join(', ')}] and ${clipped > 1 ? 'are' : 'is'} cut off.`);
  showMessage(note, parts.filter(Boolean).join(' '));
}

// Shown at first on the luminance chart (the others are a click on the legend away): the paper's
// fixed cases and the recommended fit; the in-sample optimum is optimistic, the heuristics crowd it.
const LUMINANCE_SHOWN = new Set(['plane1', 'plane2', 'plane3', 'switch', 'optimal_cv']);

/**
 * The luminance of every strategy against iterations (× 10⁵, as the table), each with a band of
 * ± 1 SE, SE(L) = L · (RMS/100) / √M, and the quadrature reference as a horizontal line.
 */
export function drawLuminance(slot, note, points, reference) {
  if (points.length === 0) {
    slot.clear('No checkpoints yet.');
    showMessage(note, '');
    return;
  }
  const x = points.map((p) => p.iterations);
  const series = [{ label: 'iterations', value: (u, v) => (v === null ? '—' : formatCount(v)) }];
  const data = [x];
  slot.bands = [];
  for (const strategy of STRATEGIES) {
    const rows = points.map((p) => p.strategies.find((s) => s.strategy === strategy) ?? null);
    const y = rows.map((r) => (r && Number.isFinite(r.luminance) ? r.luminance * 1e5 : null));
    const se = rows.map((r, i) => (y[i] === null ? null : luminanceStderr(r.luminance, r.rms_percent, points[i].iterations)));
    data.push(y);
    slot.bands.push({
      lo: y.map((v, i) => (v === null || se[i] === null ? null : v - se[i] * 1e5)),
      hi: y.map((v, i) => (v === null || se[i] === null ? null : v + se[i] * 1e5)),
      color: STRATEGY_COLORS[strategy],
    });
    const k = slot.bands.length - 1;
    series.push({
      label: strategy === 'optimal' ? 'optimal (in-sample)' : strategy, stroke: STRATEGY_COLORS[strategy], width: 2,
      show: LUMINANCE_SHOWN.has(strategy), points: { show: points.length < 40, size: 4 },
      value: (u, v, si, i) => {
        const band = slot.bands[k];
        return v === null ? '—' : `${fixed(v, 2)}${band?.hi[i] === null ? '' : ` ± ${fixed(band.hi[i] - v, 2)}`}`;
      },
    });
  }
  slot.guides = { x: [], y: reference === null ? [] : [{ value: reference * 1e5, label: `reference (quadrature) ${formatLuminance(reference)}` }] };
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: (u) => linearRange(extent(u, slot, false)) } },
    axes: [{ label: 'iterations M' }, { label: 'L·10⁵ (± 1 SE band)', size: 60 }],
    plugins: [bands(slot), guides(slot)],
  }, data);
  showMessage(note, `Bands: ± 1 standard error, L · (RMS/100) / √M at each checkpoint. Dashed: the quadrature reference${reference === null ? ' (none for this scene)' : ''}. Click a legend entry to show or hide a strategy; the in-sample optimum is optimistic.${points.length === 1 ? ' One checkpoint so far: lines appear from the second on.' : ''}`);
}

export function drawHistory(slot, note, points) {
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
