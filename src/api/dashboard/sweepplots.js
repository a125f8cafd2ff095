// The sweep page's charts: per swept field, the RMS of every strategy against the field's value
// (with a selector per other axis of a grid), and the recommended w₁ against r₃ of every point
// that recommends a weights table (open markers for cells without a data SE), both with error bars
// (± 1 standard error; chartkit.js) and SVG/PNG downloads (chartfiles.js). The numbers come from
// sweepdata.js.

/* global uPlot */

import { errorBars, extent, logRange, markers } from './chartkit.js';
import { chartDownloads } from './chartfiles.js';
import { fixed, formatParameter, formatRms, h, showMessage } from './format.js';
import { PlotSlot, strategyColor, weightRange } from './plots.js';
import { describeValue, hasSelectors, rmsAgainst, w1AgainstR3 } from './sweepdata.js';

const POINT_COLORS = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf'];
const POINT_DASHES = [[], [6, 4], [2, 3], [12, 3, 2, 3]];

/** The x scale and axis of a field: its values (a log scale when they span a decade or more), or its values' indices named by `labels`. */
function xAxisOf(data, field) {
  if (!data.numeric) {
    const n = data.labels.length;
    return {
      scale: { time: false, range: () => [-0.5, n - 0.5] },
      axis: { label: field, splits: () => data.labels.map((_, i) => i), values: (u, splits) => splits.map((i) => data.labels[i] ?? '') },
    };
  }
  const [min, max] = [Math.min(...data.x), Math.max(...data.x)];
  const log = min > 0 && max / min >= 10;
  // Ticks at the swept values while there are few; else uPlot's (on whole decades when logarithmic).
  const values = [...new Set(data.x)];
  const few = values.length <= 8;
  const range = log
    ? (u, lo, hi) => (few ? [lo / 1.3, hi * 1.3] : uPlot.rangeLog(lo, hi, 10, true))
    : (u, lo, hi) => {
      const pad = lo === hi ? Math.abs(lo) * 0.5 || 1 : 0.06 * (hi - lo);
      return [lo - pad, hi + pad];
    };
  const axis = {
    label: log ? `${field} (log scale)` : field,
    values: (u, splits) => splits.map((v) => (v === null ? '' : formatParameter(v))),
  };
  if (few) {
    axis.splits = () => values;
    axis.filter = (u, splits) => splits; // a log axis would otherwise label only 1, 2 and 5 × 10ⁿ
  }
  return { scale: { time: false, distr: log ? 3 : 1, range }, axis };
}

function drawRms(slot, note, data, field, sweep) {
  const figures = data.points.filter((i) => sweep.points[i].figures).length;
  if (figures === 0 || data.series.length === 0) {
    slot.clear('No figures yet: they appear with the first checkpoint of a run.');
    showMessage(note, '');
    return;
  }
  const { scale, axis } = xAxisOf(data, field);
  slot.xLabels = data.numeric ? null : data.labels;
  const xValue = (u, v) => (v === null ? '—' : data.numeric ? formatParameter(v) : data.labels[v]);
  const series = [{ label: field, value: xValue }];
  slot.bars = data.series.map((s) => ({ err: s.err, color: strategyColor(s.strategy) }));
  data.series.forEach((s, k) => {
    const outside = { all: ' (outside fixed weights)', some: ' (outside fixed weights at some points)', '': '' }[s.outside];
    series.push({
      label: `${s.strategy}${outside}`, stroke: slot.bars[k].color, width: 1.5, dash: s.outside ? [6, 4] : [],
      points: { show: true, size: 5 },
      // slot.bars, not s: a redraw with the same series keeps these functions but not the data.
      value: (u, v, si, i) => {
        const e = slot.bars[k]?.err[i];
        return v === null ? '—' : `${formatRms(v)}${e ? ` ± ${formatRms(e)}` : ''} %`;
      },
    });
  });
  slot.draw({
    series,
    scales: { x: scale, y: { distr: 3, range: (u) => logRange(extent(u, slot, true)) } },
    axes: [axis, { label: 'RMS error (%, log scale)', size: 60 }],
    plugins: [errorBars(slot)],
  }, [data.x, ...data.series.map((s) => s.y)]);
  const predicted = data.points.some((i) => sweep.points[i].figures?.source === 'predicted');
  const parts = ['Bars: ± 1 standard error (the in-sample optimal has none).',
    "Dashed: strategies outside the solver's fixed weights, shown for comparison."];
  if (hasSelectors(sweep.spec)) parts.push('The other axes are at the values selected above.');
  if (predicted) parts.push('Some points are predicted from one run with noise components.');
  if (figures < data.points.length) parts.push(`${data.points.length - figures} of ${data.points.length} points have no figures yet.`);
  showMessage(note, parts.join(' '));
}

/** One card: the RMS of every strategy against swept field `a`, with a selector per other axis of a grid. */
export class RmsChart {
  constructor(sweep, a) {
    const { spec } = sweep;
    this.a = a;
    this.field = sweep.fields[a];
    this.fixed = spec.axes.map(() => 0);
    const selectors = hasSelectors(spec) ? spec.axes.map((axis, b) => (b === a ? null : this.selector(axis, b))) : [];
    const plot = h('div', { class: 'plot', 'data-ref': 'rms-plot' });
    this.note = h('p', { class: 'hint' });
    const id = `rms-heading-${a}`;
    this.card = h('section', { class: 'card', 'data-field': this.field, 'aria-labelledby': id },
      h('h2', { id }, 'RMS error against ', h('code', {}, this.field)),
      selectors.some(Boolean) ? h('div', { class: 'chart-controls' }, selectors) : null,
      plot, this.note);
    this.slot = new PlotSlot(plot, `Sweep ${sweep.id}: RMS error against ${this.field}`);
    this.card.append(chartDownloads(this.slot, `optimis-sweep-${sweep.id}-rms-${this.field.replace(/[^A-Za-z0-9_.-]/g, '_')}`));
  }

  selector(axis, b) {
    const select = h('select', { 'data-axis': axis.field },
      axis.values.map((v, i) => h('option', { value: i }, describeValue(v))));
    select.addEventListener('change', () => {
      this.fixed[b] = Number(select.value);
      this.update(this.sweep);
    });
    return h('label', { class: 'inline-label' }, h('code', {}, axis.field), select);
  }

  update(sweep) {
    this.sweep = sweep;
    drawRms(this.slot, this.note, rmsAgainst(sweep, this.a, this.fixed), this.field, sweep);
  }

  destroy() {
    this.slot.destroy();
  }
}

/** The recommended w₁ of every point against r₃ (cell midpoints), one line per point. */
export function drawW1(slot, note, sweep) {
  const data = w1AgainstR3(sweep);
  const perPath = data.perPath.length
    ? `${data.perPath.length} of ${sweep.points.length} points recommend a per-path strategy, which has no weights table (${data.perPath.map((p) => `${p.label}: ${p.strategy}`).join('; ')}); a measured point's job page draws its table optimum instead.`
    : '';
  if (data.x.length === 0) {
    slot.clear(data.perPath.length ? 'No point recommends a weights table.' : 'No weights yet: they appear with the first checkpoint of a run.');
    showMessage(note, perPath);
    return;
  }
  slot.bars = data.series.map((s, k) => ({ err: s.err, color: POINT_COLORS[k % POINT_COLORS.length] }));
  slot.markers = data.series.map((s, k) => ({ open: s.open, color: POINT_COLORS[k % POINT_COLORS.length] }));
  const open = data.series.reduce((n, s) => n + s.open.filter((o, i) => o && s.y[i] !== null).length, 0);
  slot.notes = open ? [{ marker: 'open', text: 'open: no data SE (smoothed: set by its neighbours through λ), no bar' }] : [];
  const series = [{ label: 'r₃', value: (u, v) => (v === null ? '—' : formatParameter(v)) }];
  data.series.forEach((s, k) => series.push({
    label: s.label, stroke: slot.bars[k].color, width: 1.5,
    dash: POINT_DASHES[Math.floor(k / POINT_COLORS.length) % POINT_DASHES.length], points: { show: false },
    value: (u, v, si, i) => {
      const e = slot.bars[k]?.err[i];
      if (v === null) return '—';
      if (slot.markers[k]?.open[i]) return `${fixed(v, 3)} (no SE)`;
      return `${fixed(v, 3)}${e === null || e === undefined ? '' : ` ± ${fixed(e, 3)}`}`;
    },
  }));
  const bins = [];
  if (data.bins.r2) bins.push(`r₂ ∈ [${data.bins.r2.map((v) => (v === null ? '∞' : formatParameter(v))).join(', ')})`);
  if (data.bins.phi) bins.push(`φ ∈ [${data.bins.phi.map((v) => fixed(v, 2)).join(', ')})`);
  slot.draw({
    series,
    scales: { x: { time: false }, y: { range: (u, min, max) => weightRange(u, ...(extent(u, slot, false) ?? [min, max])) } },
    axes: [{ label: `r₃ (cell midpoint)${bins.length ? `, first bin: ${bins.join(', ')}` : ''}` }, { label: 'w₁' }],
    plugins: [errorBars(slot), markers(slot)],
  }, [data.x, ...data.series.map((s) => s.y)]);
  const parts = [`The recommended weights table of each point that has one (a stacked recommendation: its table part); bars: ± 1 jackknife standard error${open ? '; open markers: cells without a data standard error (smoothed), no bars' : ''}. The open tail cell of r₃ is left out; gaps are cells without informative samples.`];
  if (perPath) parts.push(perPath);
  if (data.missing) parts.push(`${data.missing} of ${sweep.points.length} points have no figures yet.`);
  showMessage(note, parts.join(' '));
}
