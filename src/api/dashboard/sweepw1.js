// The sweep page's recommended w₁ against r₃ as small multiples: one small chart per point, laid
// out as the sweep's grid (a row per value of the first axis, a column per value of the last), all
// on the same x and y ranges. Each draws its point's w₁ with ± 1 jackknife SE bars and open markers
// for cells without a data SE, over the other points' curves in faint grey for comparison; a point
// that recommends a per-path strategy (no table) keeps its place with a line saying so. One SVG/PNG
// download holds the whole grid (chartfiles.js's gridSvg).
//
// Why small multiples rather than nine overlaid curves or a selector: overlaid, nine curves with
// their bars cannot be told apart; a selector shows one point at a time and a static picture (the
// README's screenshot, a PNG in a paper) only the one selected. The grid reads in a glance, along a
// row or a column how w₁ moves with one swept field, and every panel in a picture.

import { axis, legendValue } from './axes.js';
import { errorBars, markers } from './chartkit.js';
import { chartDownloads, gridSvg } from './chartfiles.js';
import { weightValue } from './fig2.js';
import { fixed, formatParameter, h, showMessage } from './format.js';
import { PlotSlot, weightRange } from './plots.js';
import { describePoint, w1AgainstR3 } from './sweepdata.js';

const HIGHLIGHT = '#1f5fa8';
const FAINT = '#c3c9d3';
const OPEN_NOTE = { marker: 'open', text: 'open marker: no data SE (smoothed: set by its neighbours through λ), no bar' };

/** The sweep's columns: the values of its last axis in a grid of several axes, else up to three. */
function columnsOf(sweep) {
  const { spec } = sweep;
  const n = sweep.points.length;
  const last = spec.axes.at(-1).values.length;
  if (spec.mode !== 'zip' && spec.axes.length > 1 && last <= 5) return last;
  return Math.min(3, n);
}

/** The y range shared by every panel: all points' w₁ ± SE, within the weights' range (plots.js). */
function sharedRange(data) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const s of data.series) {
    s.y.forEach((v, i) => {
      if (v === null) return;
      const e = s.err[i] ?? 0;
      lo = Math.min(lo, v - e);
      hi = Math.max(hi, v + e);
    });
  }
  // 0 and 1 always in view, as on the job page; 0 alone when every table is a table part (its cells
  // sum to 1 − Σβ and may all be small).
  const shown = data.series.every((s) => s.part) ? [0] : [0, 1];
  return weightRange(null, Number.isFinite(lo) ? lo : 0, Number.isFinite(hi) ? hi : shown.at(-1), shown);
}

/** The small multiples of w₁(r₃) in the sweep page's card: `plot` the grid's container, `note` its caption. */
export class W1Grid {
  constructor(sweepId, plot, note) {
    Object.assign(this, { sweepId, plot, note, panels: [], layout: '' });
    this.range = { x: [0, 1], y: [0, 1] }; // read by every panel's scales, updated before each draw
    this.grid = h('div', { class: 'w1-grid', 'data-ref': 'w1-grid' });
    this.plot.replaceChildren(this.grid);
    this.downloads = chartDownloads(() => this.svg(), `optimis-sweep-${sweepId}-w1`);
    this.plot.after(this.downloads);
  }

  update(sweep) {
    const data = w1AgainstR3(sweep);
    this.data = data;
    const perPath = data.perPath.length
      ? `${data.perPath.length} of ${sweep.points.length} points recommend a per-path strategy, which has no weights table (${data.perPath.map((p) => `${p.label}: ${p.strategy}`).join('; ')}); a measured point's job page draws its table optimum instead.`
      : '';
    this.downloads.hidden = data.x.length === 0;
    if (data.x.length === 0) {
      this.clear();
      this.grid.replaceChildren(h('p', { class: 'empty' }, data.perPath.length ? 'No point recommends a weights table.' : 'No weights yet: they appear with the first checkpoint of a run.'));
      showMessage(this.note, perPath);
      return;
    }
    if (this.layout !== this.keyOf(sweep, data)) this.build(sweep, data);
    const edge = Math.max(...sweep.points.flatMap((p) => (p.figures?.weights ?? []).map((w) => w.r3[1]).filter((v) => v !== null)));
    this.range = { x: [0, Number.isFinite(edge) ? edge : data.x.at(-1)], y: sharedRange(data) };
    for (const panel of this.panels) this.drawPanel(panel, data);
    const open = data.series.reduce((n, s) => n + s.open.filter((o, i) => o && s.y[i] !== null).length, 0);
    this.notes = open ? [OPEN_NOTE] : [];
    const bins = [];
    if (data.bins.r2) bins.push(`r₂ ∈ [${data.bins.r2.map((v) => (v === null ? '∞' : formatParameter(v))).join(', ')})`);
    if (data.bins.phi) bins.push(`φ ∈ [${data.bins.phi.map((v) => fixed(v, 2)).join(', ')})`);
    const parts = [`One chart per point, on the same axes: its recommended weights table (a stacked recommendation: its table part), in blue with ± 1 jackknife standard error bars${open ? ', open markers for cells without a data standard error (smoothed), no bars' : ''}; the other points' in grey, for comparison.${bins.length ? ` First bin: ${bins.join(', ')}.` : ''} The open tail cell of r₃ is left out; gaps are cells without informative samples.`];
    if (perPath) parts.push(perPath);
    if (data.missing) parts.push(`${data.missing} of ${sweep.points.length} points have no figures yet.`);
    showMessage(this.note, parts.join(' '));
  }

  /** What the panels depend on: the points, which of them have a table, the columns. */
  keyOf(sweep, data) {
    return JSON.stringify([columnsOf(sweep), sweep.points.map((p) => [p.index, data.series.some((s) => s.point === p.index)])]);
  }

  /** One panel per point, in the sweep's order (its grid row by row). */
  build(sweep, data) {
    this.clear();
    this.layout = this.keyOf(sweep, data);
    const columns = columnsOf(sweep);
    this.grid.style.setProperty('--columns', columns);
    this.grid.dataset.columns = columns;
    this.panels = sweep.points.map((point) => {
      // The point's values, and for a stacked recommendation that its table part is drawn.
      const title = data.series.find((s) => s.point === point.index)?.label ?? describePoint(point, sweep.fields);
      const plot = h('div', { class: 'plot plot-small' });
      const figure = h('figure', { class: 'w1-panel', 'data-point': point.index }, h('figcaption', {}, title), plot);
      this.grid.append(figure);
      const k = data.series.findIndex((s) => s.point === point.index);
      if (k < 0) {
        const per = data.perPath.find((p) => p.point === point.index);
        plot.replaceChildren(h('p', { class: 'empty' }, per ? `Recommends ${per.strategy}, a per-path strategy: no weights table.` : 'No figures yet.'));
        return { point: point.index, title, figure, slot: null };
      }
      const slot = new PlotSlot(plot, `Sweep ${this.sweepId}, ${title}: recommended w₁ against r₃`);
      slot.height = 220;
      return { point: point.index, title, figure, slot };
    });
  }

  /** Draws a panel: the other points in grey under its own, with bars and markers on its own only. */
  drawPanel(panel, data) {
    const { slot } = panel;
    if (!slot) return;
    const own = data.series.find((s) => s.point === panel.point);
    const others = data.series.filter((s) => s !== own);
    const last = others.length; // the panel's own series is drawn last, over the others
    slot.bars = [...others.map(() => null), { err: own.err, color: HIGHLIGHT }];
    slot.markers = [...others.map(() => null), { open: own.open, color: HIGHLIGHT }];
    slot.notes = [];
    const series = [{ label: 'r₃', value: legendValue(formatParameter) },
      ...others.map((s) => ({ label: s.label, stroke: FAINT, width: 1, points: { show: false }, value: legendValue((v) => fixed(v, 3)) })),
      { label: `w₁, ${panel.title}`, stroke: HIGHLIGHT, width: 2, points: { show: false }, value: weightValue(slot, last) }];
    slot.draw({
      series,
      legend: { show: false },
      scales: { x: { time: false, range: () => this.range.x }, y: { range: () => this.range.y } },
      axes: [axis({ label: 'r₃ (cell midpoint)' }), axis({ label: 'w₁' })],
      plugins: [errorBars(slot), markers(slot)],
    }, [data.x, ...others.map((s) => s.y), own.y]);
  }

  /** The grid as one SVG document (null while there is none). */
  svg() {
    const shown = this.panels.filter((p) => p.slot?.plot);
    if (shown.length === 0) return null;
    return gridSvg(shown, {
      title: `Sweep ${this.sweepId}: recommended w₁ against r₃, every point that recommends a table`,
      columns: Math.min(shown.length, Number(this.grid.dataset.columns) || 3),
      legend: [{ label: 'w₁ of the panel\'s point, ± 1 jackknife SE', color: HIGHLIGHT }, { label: 'the other points', color: FAINT, width: 1.5 }],
      notes: this.notes,
    });
  }

  clear() {
    for (const panel of this.panels) panel.slot?.destroy();
    this.panels = [];
    this.layout = '';
    this.grid.replaceChildren();
  }

  destroy() {
    this.clear();
  }
}
