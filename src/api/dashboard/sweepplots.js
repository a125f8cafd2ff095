// The sweep page's RMS charts: per swept field, the RMS of every strategy against the field's value
// (with a selector per other axis of a grid), with error bars (± 1 standard error; chartkit.js) and
// SVG/PNG downloads (chartfiles.js). The numbers come from sweepdata.js; the recommended w₁ of
// every point is sweepw1.js's.

/* global uPlot */

import { axis, fitSize, legendValue, logLabel } from './axes.js';
import { errorBars, extent, logRange } from './chartkit.js';
import { chartDownloads } from './chartfiles.js';
import { formatParameter, formatRms, h, showMessage } from './format.js';
import { PlotSlot, strategyColor } from './plots.js';
import { describeValue, hasSelectors, rmsAgainst } from './sweepdata.js';

/** The x scale and axis of a field: its values (a log scale when they span a decade or more), or its values' indices named by `labels`. */
function xAxisOf(data, field) {
  if (!data.numeric) {
    const n = data.labels.length;
    return {
      scale: { time: false, range: () => [-0.5, n - 0.5] },
      axis: { label: field, size: fitSize, splits: () => data.labels.map((_, i) => i), values: (u, splits) => splits.map((i) => data.labels[i] ?? '') },
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
  const label = log ? `${field} (log scale)` : field;
  // Few values: a tick at each, labelled as the spec gives it (the chart files tick the same: xTicks).
  const ticks = few ? {
    splits: () => values,
    filter: (u, splits) => splits, // a log axis would otherwise label only 1, 2 and 5 × 10ⁿ
    values: (u, splits) => splits.map((v) => (v === null ? '' : log ? logLabel(v) : formatParameter(v))),
  } : {};
  return { scale: { time: false, distr: log ? 3 : 1, range }, axis: axis({ label, ...ticks }, log), xTicks: few ? values : null };
}

function drawRms(slot, note, data, field, sweep) {
  const figures = data.points.filter((i) => sweep.points[i].figures).length;
  if (figures === 0 || data.series.length === 0) {
    slot.clear('No figures yet: they appear with the first checkpoint of a run.');
    showMessage(note, '');
    return;
  }
  const { scale, axis: xAxis, xTicks } = xAxisOf(data, field);
  slot.xLabels = data.numeric ? null : data.labels;
  slot.xTicks = xTicks ?? null;
  const series = [{ label: field, value: legendValue((v) => (data.numeric ? formatParameter(v) : data.labels[v])) }];
  slot.bars = data.series.map((s) => ({ err: s.err, color: strategyColor(s.strategy) }));
  data.series.forEach((s, k) => {
    const outside = { all: ' (outside fixed weights)', some: ' (outside fixed weights at some points)', '': '' }[s.outside];
    series.push({
      label: `${s.strategy}${outside}`, stroke: slot.bars[k].color, width: 1.5, dash: s.outside ? [6, 4] : [],
      points: { show: true, size: 5 },
      // slot.bars, not s: a redraw with the same series keeps these functions but not the data.
      value: legendValue((v, i) => {
        const e = slot.bars[k]?.err[i];
        return `${formatRms(v)}${e ? ` ± ${formatRms(e)}` : ''} %`;
      }),
    });
  });
  slot.draw({
    series,
    scales: { x: scale, y: { distr: 3, range: (u) => logRange(extent(u, slot, true)) } },
    axes: [xAxis, axis({ label: 'RMS error (%, log scale)' }, true)],
    plugins: [errorBars(slot)],
  }, [data.x, ...data.series.map((s) => s.y)]);
  const predicted = data.points.some((i) => sweep.points[i].figures?.source === 'predicted');
  const parts = ['Bars: ± 1 standard error (the in-sample optimal has none).',
    "Dashed: strategies outside the solver's fixed weights, shown for comparison."];
  if (hasSelectors(sweep.spec)) parts.push('The other axes are at the values selected above.');
  if (predicted) parts.push('Some points are predicted from one run with noise components.');
  const hidden = data.series.reduce((n, s) => n + s.hidden, 0);
  if (hidden > 0) {
    parts.push(`${hidden} predicted ${hidden === 1 ? 'figure is' : 'figures are'} not drawn: the run does not support them (their RMS standard error is above the prediction's support limit).`);
  }
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
