// Sweep data: what the sweep page's charts show, read from a sweep resource (GET /v1/sweeps/{id}):
// which value of every axis a point takes, the RMS of every strategy against one swept field (the
// other axes fixed), and the recommended w₁ against r₃ of every point that recommends a table. No
// DOM and no uPlot here.

import { UNFITTED, strategiesIn } from './plots.js';

/**
 * Which value (an index into the axis's values) of every axis point `index` takes, as the server
 * expands them: a grid varies the last axis fastest, a zip takes the i-th value of every axis.
 */
export function picks(spec, index) {
  if (spec.mode === 'zip') return spec.axes.map(() => index);
  const out = new Array(spec.axes.length);
  let rest = index;
  for (let a = spec.axes.length - 1; a >= 0; a -= 1) {
    const n = spec.axes[a].values.length;
    out[a] = rest % n;
    rest = Math.floor(rest / n);
  }
  return out;
}

/** A swept value in words: a number or a string as it is, anything else as its JSON, cut at `max` characters. */
export function describeValue(value, max = 40) {
  const text = typeof value === 'string' ? value : JSON.stringify(value);
  return text.length > max ? `${text.slice(0, max - 1)}…` : text;
}

/** A point's swept values in words, each value kept short: `merge_radius=0.003, scene.l3=1`. */
export function describePoint(point, fields) {
  return fields.map((f) => `${f}=${describeValue(point.values[f], 24)}`).join(', ');
}

/** Whether an axis's values are all finite numbers (then they are the x coordinate). */
export const isNumericAxis = (axis) => axis.values.every((v) => typeof v === 'number' && Number.isFinite(v));

/**
 * Whether a field's chart fixes the other axes with selectors: in a grid of several axes (every
 * combination exists). In a zip all axes move together, so every point is on every chart.
 */
export const hasSelectors = (spec) => spec.mode !== 'zip' && spec.axes.length > 1;

/** The strategies of every point's noise table, in the order of the job page's table. */
const strategiesOf = (points) => strategiesIn(points.map((p) => p.figures?.noise_table ?? []));

/**
 * RMS % of every strategy against axis `a`, the other axes at the value indices `fixed` (grid of
 * several axes only). x is the field's value when the axis is numeric, else the value's index
 * (`labels` names them). Per strategy: y (null where missing or not positive: the y axis is
 * logarithmic, and for a predicted figure the run does not support), its standard error `err` (null for
 * the in-sample optimal and other rows without one), `outside`: 'all', 'some' or '' of the points where
 * the row does not keep the fixed weights, and `hidden`: how many unsupported predicted figures were left out.
 */
export function rmsAgainst(sweep, a, fixed) {
  const { spec } = sweep;
  const axis = spec.axes[a];
  const numeric = isNumericAxis(axis);
  const select = hasSelectors(spec);
  const chosen = sweep.points
    .map((point) => ({ point, at: picks(spec, point.index) }))
    .filter(({ at }) => !select || at.every((v, b) => b === a || v === fixed[b]))
    .map(({ point, at }) => ({ point, x: numeric ? axis.values[at[a]] : at[a] }))
    .sort((m, n) => m.x - n.x);
  const series = strategiesOf(sweep.points).map((strategy) => {
    const rows = chosen.map(({ point }) => point.figures?.noise_table.find((r) => r.strategy === strategy) ?? null);
    // A predicted figure its run does not support (RMS SE above the support limit) is not drawn.
    const unsupported = chosen.map(({ point }) => (point.figures?.unsupported ?? []).includes(strategy));
    const y = rows.map((r, i) => (r && r.rms_percent > 0 && !unsupported[i] ? r.rms_percent : null));
    const err = rows.map((r, i) => (y[i] === null ? null : r.rms_percent_stderr ?? null));
    const outside = rows.filter((r, i) => y[i] !== null).map((r) => r.respects_fixed === false);
    const all = outside.length > 0 && outside.every(Boolean);
    const hidden = rows.filter((r, i) => r && r.rms_percent > 0 && unsupported[i]).length;
    return { strategy, y, err, outside: all ? 'all' : outside.some(Boolean) ? 'some' : '', hidden };
  });
  return {
    x: chosen.map((c) => c.x),
    numeric,
    labels: numeric ? null : axis.values.map((v) => describeValue(v, 24)),
    points: chosen.map((c) => c.point.index),
    series,
  };
}

/** The lower edge of a coordinate's first bin among `rows` (`r2` or `phi`). */
const firstBin = (rows, key) => Math.min(...rows.map((w) => w[key][0]));

/**
 * The recommended w₁ of every point that recommends a weights table, against r₃, in the first r₂
 * bin and the first φ bin: x is the union of the cells' midpoints (the open tail cell [lo, ∞) is
 * left out); per point, w₁ (null in cells whose weights the server copied from a neighbour, as on
 * the job page), its jackknife standard error and whether the cell has none (`open`: smoothed).
 * A table with heuristics stacked on it is its table part (`part`; its label says so). `bins` tells
 * whether there were several r₂ or φ bins, and which were taken; `perPath` lists the points that
 * recommend a per-path strategy (no table) and `missing` counts those without figures yet.
 */
export function w1AgainstR3(sweep) {
  const cellsOf = (point) => {
    const weights = point.figures?.weights ?? [];
    if (weights.length === 0) return [];
    const r2 = firstBin(weights, 'r2');
    const phi = firstBin(weights, 'phi');
    return weights.filter((w) => w.r2[0] === r2 && w.phi[0] === phi && w.r3[1] !== null);
  };
  const cells = sweep.points.map(cellsOf);
  const mid = (w) => (w.r3[0] + w.r3[1]) / 2;
  const x = [...new Set(cells.flat().map(mid))].sort((m, n) => m - n);
  const open = (w) => w.status === 'smoothed' || w.w1_stderr === null || w.w1_stderr === undefined;
  const series = sweep.points.flatMap((point, i) => {
    if (cells[i].length === 0) return [];
    const at = new Map(cells[i].filter((w) => !UNFITTED.has(w.status)).map((w) => [mid(w), w]));
    const part = point.figures.recommended?.heuristics?.length > 0;
    return [{
      point: point.index,
      part,
      label: `${describePoint(point, sweep.fields)}${part ? ` (${point.figures.recommended.strategy}: table part)` : ''}`,
      y: x.map((v) => at.get(v)?.w1 ?? null),
      err: x.map((v) => (at.has(v) && !open(at.get(v)) ? at.get(v).w1_stderr : null)),
      open: x.map((v) => (at.has(v) ? open(at.get(v)) : false)),
    }];
  });
  const perPath = sweep.points.filter((p, i) => cells[i].length === 0 && p.figures?.recommended && p.figures.recommended.lambda === null)
    .map((p) => ({ point: p.index, label: describePoint(p, sweep.fields), strategy: p.figures.recommended.strategy }));
  const first = sweep.points.find((p) => p.figures?.weights?.length)?.figures.weights ?? [];
  const count = (key) => new Set(first.map((w) => w[key][0])).size;
  const bins = {
    r2: count('r2') > 1 ? first.find((w) => w.r2[0] === firstBin(first, 'r2')).r2 : null,
    phi: count('phi') > 1 ? first.find((w) => w.phi[0] === firstBin(first, 'phi')).phi : null,
  };
  return { x, series, bins, perPath, missing: sweep.points.filter((p) => !p.figures).length };
}
