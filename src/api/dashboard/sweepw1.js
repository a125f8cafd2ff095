// The sweep page's recommended weights against r₃ as small multiples: one small chart per point,
// laid out as the sweep's grid (a row per value of the first axis, a column per value of the last),
// all on the same x and y ranges. Each draws the effective w₁ of its point's recommended row — the
// contribution-weighted average of w₁ over each (r₂, r₃) bin's full paths, from GET
// /v1/jobs/{job}/effective — with ± 1 SE bars, over the other points' curves in faint grey for
// comparison. Effective weights exist for every kind of recommendation (a per-path heuristic, a
// table, a stack drawn whole), so no panel is left empty for want of a table; a panel whose request
// failed says why. One SVG/PNG download holds the whole grid (chartfiles.js's gridSvg).
//
// The requests go one at a time (the server computes each on its heavy pool, which every page
// shares), with fewer paths than the job page's (10,000 per side: a small chart shows no finer
// detail), and each is made again only when its point's run has a new checkpoint.
//
// Why small multiples rather than nine overlaid curves or a selector: overlaid, nine curves with
// their bars cannot be told apart; a selector shows one point at a time and a static picture (the
// README's screenshot, a PNG in a paper) only the one selected. The grid reads in a glance, along a
// row or a column how w₁ moves with one swept field, and every panel in a picture.

import { api } from './api.js';
import { axis, legendValue } from './axes.js';
import { edgeMarks, errorBars, markers } from './chartkit.js';
import { chartDownloads, gridSvg } from './chartfiles.js';
import { fixed, formatCount, formatParameter, h, showMessage } from './format.js';
import { PlotSlot, WEIGHT_FRAME, r2Words, splitAtRange, weightRange } from './plots.js';
import { describePoint, effectiveW1 } from './sweepdata.js';

const HIGHLIGHT = '#1f5fa8';
const FAINT = '#c3c9d3';
/** Paths per side of each panel's effective weights. */
const PATHS = 10000;

/** The sweep's columns: the values of its last axis in a grid of several axes, else up to three. */
function columnsOf(sweep) {
  const { spec } = sweep;
  const n = sweep.points.length;
  const last = spec.axes.at(-1).values.length;
  if (spec.mode !== 'zip' && spec.axes.length > 1 && last <= 5) return last;
  return Math.min(3, n);
}

/** The y range shared by every panel: all points' w₁ ± SE, 0 and 1 always in view, within the weights' frame. */
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
  return weightRange(null, Number.isFinite(lo) ? lo : 0, Number.isFinite(hi) ? hi : 1, [0, 1], WEIGHT_FRAME);
}

/**
 * The effective-weights request of a point (its run's job, its recommended row), or null when it
 * has none to make; `key` changes with the run's checkpoint. A predicted point's row is asked of
 * the run it is predicted from.
 */
function requestOf(point) {
  const f = point.figures;
  if (!f || point.job_id === null || point.job_id === undefined || !f.recommended) return null;
  const path = `/v1/jobs/${point.job_id}/effective?paths=${PATHS}&strategy=${encodeURIComponent(f.recommended.strategy)}`;
  return { index: point.index, path, key: `${path}@${f.iterations}:${f.partial}` };
}

/** The effective weights' small multiples in the sweep page's card: `plot` the grid's container, `note` its caption. */
export class W1Grid {
  constructor(sweepId, plot, note) {
    Object.assign(this, { sweepId, plot, note, panels: [], layout: '', alive: true, sweep: null });
    this.wanted = []; // the points' requests (requestOf), as of the last answer of the sweep
    this.answers = new Map(); // request key → { effective } or { error }
    this.shown = new Map(); // point index → the answer drawn last (kept while its next one loads)
    this.busy = false;
    this.range = { x: [0, 1], y: [0, 1] }; // read by every panel's scales, updated before each draw
    this.grid = h('div', { class: 'w1-grid', 'data-ref': 'w1-grid' });
    this.plot.replaceChildren(this.grid);
    this.downloads = chartDownloads(() => this.svg(), `optimis-sweep-${sweepId}-w1`);
    this.plot.after(this.downloads);
  }

  update(sweep) {
    this.sweep = sweep;
    this.wanted = sweep.points.map(requestOf).filter(Boolean);
    this.render();
    this.pump();
  }

  /** Fetches the wanted answers not yet in, one at a time, redrawing after each. */
  async pump() {
    if (this.busy) return;
    this.busy = true;
    try {
      for (;;) {
        const next = this.wanted.find((w) => !this.answers.has(w.key));
        if (!next || !this.alive) break;
        const answer = await api(next.path).then((effective) => ({ effective }), (error) => ({ error: error.message }));
        if (!this.alive) break;
        this.answers.set(next.key, answer);
        // Answers for checkpoints the points have moved past are not needed again.
        const keys = new Set(this.wanted.map((w) => w.key));
        for (const key of this.answers.keys()) if (!keys.has(key)) this.answers.delete(key);
        this.render();
      }
    } finally {
      this.busy = false;
    }
  }

  /** What each point's panel shows: { doc } to draw, or { text } (and whether it is an error). */
  statesOf(sweep) {
    const states = new Map();
    for (const point of sweep.points) {
      const want = this.wanted.find((w) => w.index === point.index);
      const answer = want ? this.answers.get(want.key) : undefined;
      if (answer) this.shown.set(point.index, answer);
      if (!want) this.shown.delete(point.index);
      const shown = this.shown.get(point.index);
      const f = point.figures;
      let state;
      if (!f) state = { text: 'No figures yet.' };
      else if (point.job_id === null || point.job_id === undefined) state = { text: 'Its run was deleted: no paths to average its weights over.' };
      else if (!f.recommended) state = { text: `No row could be recommended${f.error ? `: ${f.error}` : '.'}` };
      else if (!shown) state = { text: 'Computing the effective weights…' };
      else if (shown.error) state = { text: `Cannot compute the effective weights: ${shown.error}`, error: true };
      else state = { doc: shown.effective };
      states.set(point.index, state);
    }
    return states;
  }

  render() {
    const sweep = this.sweep;
    if (!sweep) return;
    const states = this.statesOf(sweep);
    const docs = new Map([...states].filter(([, s]) => s.doc).map(([index, s]) => [index, s.doc]));
    const data = effectiveW1(sweep, docs);
    this.data = data;
    // A point whose document has no light-carrying path in the drawn r₂ bin says so instead of a chart.
    for (const s of data.series) {
      if (s.drawn === 0) states.set(s.point, { text: `No sampled path carries light${data.r2 ? ` in ${r2Words(data.r2)}` : ''}: no weights to draw.` });
    }
    const charted = data.series.filter((s) => s.drawn > 0);
    this.downloads.hidden = charted.length === 0;
    const key = this.keyOf(sweep, states);
    if (this.layout !== key) this.build(sweep, states, key);
    this.range = { x: [0, data.end], y: sharedRange({ series: charted }) };
    for (const panel of this.panels) this.drawPanel(panel, charted);
    const edges = this.panels.reduce((n, p) => n + (p.slot?.edges?.length ?? 0), 0);
    this.notes = [
      ...data.dark.map((b) => ({ marker: 'none', text: `${r2Words(b)}: no light path reaches it at any point` })),
      ...(edges ? [{ marker: 'edge', text: 'beyond the axis: marked at its edge with the value' }] : []),
    ];
    showMessage(this.note, this.caption(sweep, data, charted, states, edges));
  }

  /** The card's caption: what the panels draw, and what is left out. */
  caption(sweep, data, charted, states, edges) {
    if (!data.r2) {
      const waiting = [...states.values()].some((s) => s.text === 'Computing the effective weights…');
      return waiting ? 'Computing the points\' effective weights…' : '';
    }
    const paths = charted[0]?.paths ?? PATHS;
    const parts = [`One chart per point, on the same axes: the effective w₁ of its recommended row — a per-path heuristic, a table or a stack drawn whole alike — per r₃ bin in ${r2Words(data.r2)}: the contribution-weighted average of w₁ over the bin's full paths (${formatCount(paths)} paths per side, from GET /v1/jobs/{job}/effective), in blue with bars of ± 1 standard error; the other points' in grey, for comparison.`];
    for (const b of data.dark) parts.push(`${r2Words(b)}: no light path reaches it at any point, so no weight matters there.`);
    if (data.lit.length) parts.push(`Not drawn here: ${data.lit.map(r2Words).join(', ')} (on each job's page).`);
    if (data.tail) parts.push(`The open tail bin r₃ ≥ ${formatParameter(data.tail.lo)} is drawn at r₃ = ${formatParameter(Number(data.tail.x.toPrecision(6)))} (its edge plus the previous bin's width).`);
    if (edges) parts.push(`${edges} value${edges > 1 ? 's lie' : ' lies'} beyond the axis: marked ▲/▼ at the frame's edge with the value.`);
    if (sweep.points.some((p) => p.figures?.source === 'predicted')) {
      parts.push('A predicted point draws its recommended row as its run weights it, at the run\'s own budget: the prediction\'s re-fitted table for the point\'s budget is not drawn.');
    }
    const failed = [...states.values()].filter((s) => s.error).length;
    if (failed) parts.push(`${failed} of ${sweep.points.length} points' effective weights could not be computed (their panels say why).`);
    const missing = sweep.points.filter((p) => !p.figures).length;
    if (missing) parts.push(`${missing} of ${sweep.points.length} points have no figures yet.`);
    return parts.join(' ');
  }

  /** What the panels depend on: the columns, and per point whether it has a chart or which text. */
  keyOf(sweep, states) {
    return JSON.stringify([columnsOf(sweep), sweep.points.map((p) => {
      const s = states.get(p.index);
      return s.doc ? `chart:${s.doc.strategy}:${s.doc.kind}` : s.text;
    })]);
  }

  /** One panel per point, in the sweep's order (its grid row by row). */
  build(sweep, states, key) {
    this.clear();
    this.layout = key;
    const columns = columnsOf(sweep);
    this.grid.style.setProperty('--columns', columns);
    this.grid.dataset.columns = columns;
    this.panels = sweep.points.map((point) => {
      const state = states.get(point.index);
      // The point's values, then the row its panel draws and what kind of weights it is.
      const title = `${describePoint(point, sweep.fields)}${state.doc ? ` · ${state.doc.strategy} (${state.doc.kind})` : ''}`;
      const plot = h('div', { class: 'plot plot-small' });
      const figure = h('figure', { class: 'w1-panel', 'data-point': point.index }, h('figcaption', {}, title), plot);
      this.grid.append(figure);
      if (!state.doc) {
        plot.replaceChildren(h('p', { class: state.error ? 'empty error' : 'empty' }, state.text));
        return { point: point.index, title, figure, slot: null };
      }
      const slot = new PlotSlot(plot, `Sweep ${this.sweepId}, ${title}: effective w₁ against r₃`);
      slot.height = 220;
      return { point: point.index, title, figure, slot };
    });
  }

  /** Draws a panel: the other points in grey under its own, with bars, markers and edge marks on its own only. */
  drawPanel(panel, charted) {
    const { slot } = panel;
    if (!slot) return;
    const own = charted.find((s) => s.point === panel.point);
    if (!own) return;
    const others = charted.filter((s) => s !== own);
    const last = others.length; // the panel's own series is drawn last, over the others
    const y = this.range.y;
    const mine = splitAtRange(own.y, y);
    slot.bars = [...others.map(() => null), { err: own.err, color: HIGHLIGHT }];
    slot.markers = [...others.map(() => null), { open: own.y.map(() => false), color: HIGHLIGHT }];
    slot.edges = mine.outside.map(({ i, value }) => ({
      s: last, i, x: this.data.x[i], value, text: String(Number(value.toPrecision(3))).replace('-', '−'), color: HIGHLIGHT,
    }));
    slot.notes = [];
    const series = [{ label: 'r₃', value: legendValue(formatParameter) },
      ...others.map((s) => ({ label: s.label, stroke: FAINT, width: 1, points: { show: false }, value: legendValue((v) => fixed(v, 3)) })),
      { label: `w₁, ${panel.title}`, stroke: HIGHLIGHT, width: 2, points: { show: false }, value: legendValue((v) => fixed(v, 3)) }];
    slot.draw({
      series,
      legend: { show: false },
      scales: { x: { time: false, range: () => this.range.x }, y: { range: () => this.range.y } },
      axes: [axis({ label: 'r₃ (bin midpoint)' }), axis({ label: 'effective w₁' })],
      plugins: [errorBars(slot), markers(slot), edgeMarks(slot)],
    }, [this.data.x, ...others.map((s) => splitAtRange(s.y, y).inside), mine.inside]);
  }

  /** The grid as one SVG document (null while there is none). */
  svg() {
    const shown = this.panels.filter((p) => p.slot?.plot);
    if (shown.length === 0) return null;
    const bin = this.data?.r2 ? `, ${r2Words(this.data.r2)}` : '';
    return gridSvg(shown, {
      title: `Sweep ${this.sweepId}: effective w₁ of each point's recommended row against r₃${bin}`,
      columns: Math.min(shown.length, Number(this.grid.dataset.columns) || 3),
      legend: [{ label: 'effective w₁ of the panel\'s point, ± 1 SE', color: HIGHLIGHT }, { label: 'the other points', color: FAINT, width: 1.5 }],
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
    this.alive = false;
    this.clear();
  }
}
