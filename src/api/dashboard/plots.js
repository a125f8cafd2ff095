// Plots: the uPlot charts of a job's result (the fitted weights per cell, the RMS history per
// strategy), and what every chart shares (the chart slot, the strategies' colours, the weights'
// range). uPlot is the vendored library, loaded before this module as a classic script (a global).

/* global uPlot */

import { fixed, formatCount, formatParameter, formatRms, h, showMessage } from './format.js';

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

/** One uPlot chart in a container, rebuilt only when its series change; follows the page width. */
export class PlotSlot {
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
export const UNFITTED = new Set(['empty', 'uninformative']);

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
    const w1 = mean('w1');
    const lo = w1.map((w, i) => (w === null ? null : w - 2 * (spread(i) ?? NaN)));
    const hi = w1.map((w, i) => (w === null ? null : w + 2 * (spread(i) ?? NaN)));
    // The jackknife SE of w₁ (root mean square over the φ bins), for the ± 2σ lines.
    function spread(i) {
      const ses = weights
        .filter((w) => w.r2[0] === band[0] && w.r3[0] === r3Cells[i][0] && !UNFITTED.has(w.status) && w.w1_stderr !== null)
        .map((w) => w.w1_stderr);
      return ses.length ? Math.sqrt(ses.reduce((a, b) => a + b * b, 0) / ses.length) : null;
    }
    const finite = (v) => (v === null || Number.isNaN(v) ? null : v);
    return { band, w1, w2: mean('w2'), w1lo: lo.map(finite), w1hi: hi.map(finite) };
  });
  return { x, tail: r3Cells.at(-1), tailX: x.at(-1), bands };
}

const BAND_DASHES = [[], [8, 4], [2, 3], [12, 3, 2, 3]];
const W1_COLORS = ['#1f5fa8', '#5b9bd5', '#9cc3e6', '#0b3d6b'];
const W2_COLORS = ['#c4561d', '#f08c4a', '#f5b88d', '#7a3510'];

export function drawWeights(slot, note, weights, phiBins, fit) {
  if (weights.length === 0) {
    slot.clear('No fitted weights in this result.');
    showMessage(note, '');
    return;
  }
  const { x, tail, tailX, bands } = weightSeries(weights);
  const phi = phiBins > 1 ? ` · mean of ${phiBins} φ bins` : '';
  const series = [{ label: `r₃${phi}`, value: (u, v) => (v === null ? '—' : formatParameter(v)) }];
  const data = [x];
  bands.forEach(({ band, w1, w2, w1lo, w1hi }, i) => {
    const dash = BAND_DASHES[i % BAND_DASHES.length];
    const r2 = `r₂ ${formatInterval(band)}`;
    series.push(weightLine(`w₁, ${r2}`, W1_COLORS[i % W1_COLORS.length], dash));
    series.push(weightLine(`w₂, ${r2}`, W2_COLORS[i % W2_COLORS.length], dash));
    data.push(w1, w2);
    if (w1lo.some((v) => v !== null)) {
      series.push(errorLine(`w₁ − 2 SE, ${r2}`, W1_COLORS[i % W1_COLORS.length]));
      series.push(errorLine(`w₁ + 2 SE, ${r2}`, W1_COLORS[i % W1_COLORS.length]));
      data.push(w1lo, w1hi);
    }
  });
  const tailLabel = tail[1] === null ? `; tail r₃ ≥ ${formatParameter(tail[0])} drawn at ${formatParameter(tailX)}` : '';
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: weightRange } },
    axes: [{ label: `r₃ (cell centre${tailLabel})` }, { label: 'weight' }],
    cursor: { drag: { x: true, y: false } },
  }, data);
  const clipped = data.slice(1).flat().filter((v) => v !== null && (v < WEIGHT_RANGE[0] || v > WEIGHT_RANGE[1])).length;
  const which = fit
    ? (fit.strategy === 'optimal'
      ? `Weights fitted in-sample on all iterations at λ = ${formatParameter(fit.lambda)}. `
      : `Recommended weights: ${fit.strategy}, λ = ${formatParameter(fit.lambda)} chosen by cross-validation, fitted on all iterations; thin lines: w₁ ± 2 jackknife standard errors. `)
    : '';
  const gaps = `${which}Gaps are cells without informative samples.`;
  const cut = clipped ? ` ${clipped} value${clipped > 1 ? 's lie' : ' lies'} outside [${WEIGHT_RANGE.join(', ')}] and ${clipped > 1 ? 'are' : 'is'} cut off (usually cells with few samples).` : '';
  showMessage(note, gaps + cut);
}

function errorLine(label, stroke) {
  return { label, stroke, width: 1, dash: [3, 3], points: { show: false }, value: (u, v) => (v === null ? '—' : fixed(v, 3)) };
}

function weightLine(label, stroke, dash) {
  return { label, stroke, dash, width: 2, points: { show: true, size: 4 }, value: (u, v) => (v === null ? '—' : fixed(v, 3)) };
}

/** Fits the data, but never beyond WEIGHT_RANGE, and always shows 0 and 1. */
export function weightRange(u, min, max) {
  const lo = Math.max(WEIGHT_RANGE[0], Math.min(min ?? 0, 0));
  const hi = Math.min(WEIGHT_RANGE[1], Math.max(max ?? 1, 1));
  const pad = 0.05 * (hi - lo);
  return [lo - pad, hi + pad];
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
