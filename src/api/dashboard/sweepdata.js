// Sweep data: what the sweep page's charts show, read from a sweep resource (GET /v1/sweeps/{id}):
// which value of every axis a point takes, the RMS of every strategy against one swept field (the
// other axes fixed), and the effective w₁ against r₃ of every point's recommended row, from the
// documents the page fetched for the points' jobs (GET /v1/jobs/{job}/effective). No DOM and no
// uPlot here.

import { effectiveSeries, strategiesIn } from './plots.js';

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

/**
 * The effective w₁ against r₃ of the points with a document in `docs` (point index → its
 * /effective document), all in one r₂ bin — the first in which some point's paths carry light —
 * so that the small panels compare like with like (in the paper's scenes r₂ < 0.5, where the
 * spot's step in w₁ at r₃ = a is; beyond it only the open tail bin of r₃ carries light). x is the
 * union of the documents' bin positions (plots.js's r3Positions: the open tail bin one step past
 * the grid), `end` the right end of the axis, `tail` the tail bin's edge and position; per point
 * its label, strategy and kind, w₁ and its total standard error (null where the bin has no
 * light-carrying path) and `drawn`, how many bins have weights. `lit` lists the other r₂ bins
 * where some point has light (not drawn), `dark` those where none has.
 */
export function effectiveW1(sweep, docs) {
  const data = new Map([...docs].map(([index, doc]) => [index, effectiveSeries(doc)]));
  const bins = [...new Map([...data.values()].flatMap((d) => d.series.map((b) => [b.r2[0], b.r2]))).values()].sort((a, b) => a[0] - b[0]);
  const hasLight = (r2) => [...data.values()].some((d) => d.series.some((b) => b.r2[0] === r2[0] && b.drawn > 0));
  const r2 = bins.find(hasLight) ?? null;
  const x = [...new Set([...data.values()].flatMap((d) => d.x))].sort((a, b) => a - b);
  const series = sweep.points.filter((p) => data.has(p.index)).map((p) => {
    const d = data.get(p.index);
    const doc = docs.get(p.index);
    const bin = r2 ? d.series.find((b) => b.r2[0] === r2[0]) : null;
    const at = new Map(d.x.map((v, i) => [v, i]));
    const pick = (list) => x.map((v) => (bin && at.has(v) ? list[at.get(v)] : null));
    return {
      point: p.index, label: describePoint(p, sweep.fields), strategy: doc.strategy, kind: doc.kind, paths: doc.paths_per_side,
      y: bin ? pick(bin.w1) : x.map(() => null), err: bin ? pick(bin.err1) : x.map(() => null), drawn: bin ? bin.drawn : 0,
    };
  });
  const ends = [...data.values()].map((d) => d.end);
  const tail = [...data.values()].map((d) => d.r3.at(-1)).find((b) => b?.[1] === null) ?? null;
  return {
    x, r2, series, end: ends.length ? Math.max(...ends) : 1, tail: tail ? { lo: tail[0], x: x.at(-1) } : null,
    lit: bins.filter((b) => b !== r2 && hasLight(b)), dark: bins.filter((b) => !hasLight(b)),
  };
}
