// Fig. 2 of the paper — w₁ against r₃, one line per r₂ band — on the job page, as two panels
// of one card, and the weights-table figure the compare page overlays.
//
// (a) "Recommended weights (effective)": the recommended row's effective weights per (r₂, r₃) bin
//     (GET /v1/jobs/{id}/effective): the contribution-weighted average of each technique's weight
//     over the bin's full paths, ± 1 SE, w₁ solid with filled markers, w₂ dashed with hollow ones.
//     Why effective weights: a per-path heuristic has no table, and a stack's table part is not its
//     weights (a path adds Σ β·heuristic); what the weight function does on average on the paths
//     that carry the light is the one figure every kind of recommendation has, so this panel draws
//     what is recommended — heuristic, table or stack alike.
// (b) "The paper's procedure (λ = 0, in-sample)": the table fitted in-sample at λ = 0 on all
//     iterations (GET /v1/jobs/{id}/result?lambda=0), the figure the paper drew, on a fixed y range:
//     its noise cells (94.6 ± 84) are marked ▲/▼ at the frame's edge with their value rather than
//     stretching the axis or being cut off, and cells copied from a neighbour (status empty or
//     uninformative) are gaps, not data. Labelled as what it is: not honest, not recommended.
// A kept solve's fitted recommendation has no effective weights (the route fits under the job's
// own options); its heuristic has the same ones under any options, so it is drawn.
//
// The compare page still overlays each job's weights table (figureSource, figure2, weightValue;
// csvtables.js's tableColumns): those helpers stay here, beside the job page's.

import { axis, legendValue } from './axes.js';
import { edgeMarks, errorBars, guides, markers } from './chartkit.js';
import { fixed, formatBetas, formatCount, formatLuminance, formatParameter, showMessage } from './format.js';
import {
  UNFITTED, WEIGHT_FRAME, binsOf, effectiveSeries, formatInterval, r2Words, r3AxisEnd, r3Positions, spotGuide, splitAtRange,
  weightRange,
} from './plots.js';

/**
 * The λ at which the compare page fetches the table optimum for `result`, or null when it is not
 * wanted: wanted when a per-path strategy is recommended (no table) and optimal_cv chose a λ.
 */
export function tableOptimumLambda(result) {
  if (result.weights.length > 0 || (result.recommended?.lambda ?? null) !== null) return null;
  const cv = result.noise_table.find((r) => r.strategy === 'optimal_cv');
  return cv && !cv.error && cv.lambda !== null && cv.lambda !== undefined ? cv.lambda : null;
}

/**
 * Which weights table of `result` the compare overlay draws (and the job page's "Weights (CSV)"
 * saves, with no `optimum`): the recommended table, else `optimum` (the table optimum's
 * result at `tableOptimumLambda(result)`, or { error }), else nothing and why.
 *   { kind: 'recommended', weights, strategy, lambda, heuristics }
 *   { kind: 'table-optimum', weights, lambda, recommended }
 *   { kind: 'none', message }
 * `ownOptions`: whether the result is the job's own solve (only its table optimum can be fetched).
 */
export function figureSource(result, optimum, ownOptions) {
  const rec = result.recommended;
  if (result.weights.length > 0) {
    const strategy = result.weights_fit?.strategy ?? rec?.strategy;
    // β belong to the recommended row's table; a table fitted otherwise (?lambda=: `optimal`) has none.
    const heuristics = strategy === rec?.strategy ? rec.heuristics ?? [] : [];
    return { kind: 'recommended', weights: result.weights, strategy, lambda: result.weights_fit?.lambda ?? rec?.lambda ?? null, heuristics };
  }
  if (!rec || (rec.lambda ?? null) !== null) {
    return { kind: 'none', message: `No weights in this result${result.solve_error ? `: ${result.solve_error}` : '.'}` };
  }
  const perPath = `The recommended strategy, ${rec.strategy}, is per-path: its weights are a function of the whole path, not a table.`;
  if (!ownOptions) {
    return { kind: 'none', message: `${perPath} The table optimum for comparison is available for the job's own solver options only (choose default).` };
  }
  const lambda = tableOptimumLambda(result);
  if (lambda === null) return { kind: 'none', message: `${perPath} optimal_cv has no λ, so there is no table optimum to show.` };
  if (!optimum || optimum.error || optimum.result.weights.length === 0) {
    return { kind: 'none', message: `${perPath} The table optimum at λ = ${formatParameter(lambda)} could not be loaded${optimum?.error ? `: ${optimum.error}` : ''}.` };
  }
  return { kind: 'table-optimum', weights: optimum.result.weights, lambda, recommended: rec.strategy };
}

/** Which table `figure` (figureSource, not 'none') is, for the weights CSV: its `table` and `strategy` columns. */
export function tableColumns(figure) {
  if (figure.kind === 'table-optimum') return { table: 'table_optimum_not_recommended', strategy: 'optimal_cv' };
  return { table: figure.heuristics.length ? 'recommended_table_part' : 'recommended', strategy: figure.strategy };
}

/** Whether a cell's w₁ has no data standard error of its own (smoothed, fixed, …): an open marker. */
const openCell = (w) => w.status === 'smoothed' || w.w1_stderr === null || w.w1_stderr === undefined;

/**
 * The compare overlay's data from a table's `weights`: w₁ against the r₃ cell midpoint, one series per r₂ bin,
 * in the first φ bin (the paper finds the weights independent of φ); the open tail cell of r₃ is
 * left out, and cells whose weights were copied from a neighbour are gaps. Per series: `err` the
 * jackknife standard error of w₁ (null without one) and `open` whether the cell has none.
 */
export function figure2(weights) {
  const phi = binsOf(weights, 'phi')[0];
  const cells = weights.filter((w) => w.phi[0] === phi[0] && w.r3[1] !== null);
  const mid = (w) => (w.r3[0] + w.r3[1]) / 2;
  const x = [...new Set(cells.map(mid))].sort((a, b) => a - b);
  const series = binsOf(cells, 'r2').map((r2) => {
    const at = new Map(cells.filter((w) => w.r2[0] === r2[0] && !UNFITTED.has(w.status)).map((w) => [mid(w), w]));
    const cell = x.map((v) => at.get(v) ?? null);
    return {
      r2,
      y: cell.map((w) => w?.w1 ?? null),
      err: cell.map((w) => (w && !openCell(w) ? w.w1_stderr : null)),
      open: cell.map((w) => (w ? openCell(w) : false)),
    };
  });
  // The largest finite r₃ edge: the x axis runs from 0 to it.
  const edge = cells.length ? Math.max(...cells.map((w) => w.r3[1])) : null;
  return { x, series, phi, phiBins: binsOf(weights, 'phi').length, edge };
}

const R2_COLORS = ['#1f5fa8', '#c4561d', '#2ca02c', '#9467bd'];

/** A value beyond the frame in words, with its SE when it has one: `94.6 ± 84.2`, `−3.12`. */
const edgeText = (v, e) => {
  const n = (x) => String(Number(x.toPrecision(3))).replace('-', '−');
  return `${n(v)}${e === null || e === undefined ? '' : ` ± ${n(e)}`}`;
};

/**
 * The legend value of series k + 1 of `slot` under the cursor: v ± its SE (slot.bars), the value
 * and "off the scale" for one marked at the frame's edge (its data are null there).
 */
const frameValue = (slot, k) => (u, v, s, i) => {
  if (i === null || i === undefined) return '';
  if (v === null || v === undefined) {
    const edge = slot.edges?.find((m) => m.s === k && m.i === i);
    return edge ? `${edge.text} (off the scale)` : '—';
  }
  const e = slot.bars?.[k]?.err[i];
  if (slot.markers?.[k]?.noSe?.[i]) return `${fixed(v, 3)} (no SE)`;
  return `${fixed(v, 3)}${e === null || e === undefined ? '' : ` ± ${fixed(e, 3)}`}`;
};

/** What each kind of recommendation is, in words. */
const KINDS = {
  heuristic: 'a per-path heuristic',
  table: 'a weights table',
  stack: 'a table with heuristics stacked on it',
};

/**
 * The /effective query the effective panel needs for `result` (`own`: the job's own solver options
 * are shown, not a kept solve's): { path } (no strategy: the job's recommended row, which `result`
 * recommends), or { message } saying why there is none to draw.
 */
export function effectiveQuery(id, result, own) {
  const rec = result.recommended;
  if (!rec) return { message: `No row could be recommended, so there are no recommended weights to draw${result.solve_error ? `: ${result.solve_error}` : '.'}` };
  if (own) return { path: `/v1/jobs/${id}/effective` };
  // A per-path heuristic (no λ, no β) is the same function under any solver options.
  if ((rec.lambda ?? null) === null && !(rec.heuristics?.length)) {
    return { path: `/v1/jobs/${id}/effective?strategy=${encodeURIComponent(rec.strategy)}` };
  }
  return {
    message: `The kept solve recommends ${rec.strategy}, fitted under its own options; effective weights are computed under the job's own solver options only (choose default). Its table is in "Weights (CSV)".`,
  };
}

/**
 * Draws panel (a): `source` is { effective, recommended, kept } (the /effective document, the
 * result's recommendation, whether a kept solve is shown), or { message } / { error } to show
 * instead. `kind` (beside the card's heading) names the recommendation; `jobTitle` starts the
 * chart files' title.
 */
export function drawEffective(slot, { note, kind }, source, spec, jobTitle) {
  const doc = source.effective;
  const data = doc ? effectiveSeries(doc) : null;
  const lit = data ? data.series.filter((b) => b.drawn > 0) : [];
  if (!doc || lit.length === 0) {
    slot.edges = [];
    const empty = doc ? `No sampled path carries light in any bin (${formatCount(doc.paths_per_side)} paths per side): there are no weights to draw.`
      : 'Computing the effective weights…';
    slot.clear(source.message ?? (source.error ? `Cannot compute the effective weights: ${source.error}` : empty));
    showMessage(note, '');
    kind.textContent = source.recommended ? `recommended: ${source.recommended.strategy}` : '';
    delete kind.dataset.kind;
    return;
  }
  const { x, end } = data;
  slot.title = `${jobTitle}: effective weights of the recommended ${doc.strategy} (${doc.kind}) against r₃ (Fig. 2)`;
  kind.textContent = `recommended: ${doc.strategy} (${KINDS[doc.kind] ?? doc.kind})`;
  kind.dataset.kind = doc.kind;
  // Two series per r₂ bin with light: w₁ (solid, filled markers) and w₂ (dashed, hollow).
  const lines = lit.flatMap((b) => {
    const color = R2_COLORS[data.series.indexOf(b) % R2_COLORS.length];
    return [
      { b, m: 1, y: b.w1, err: b.err1, color, dash: [], hollow: false },
      { b, m: 2, y: b.w2, err: b.err2, color, dash: [7, 4], hollow: true },
    ];
  });
  const values = lines.flatMap((l) => l.y.map((v, i) => [v, l.err[i] ?? 0]).filter(([v]) => v !== null));
  slot.yRange = weightRange(null, Math.min(...values.map(([v, e]) => v - e)), Math.max(...values.map(([v, e]) => v + e)), [0, 1], WEIGHT_FRAME);
  slot.xRange = [0, end];
  const split = lines.map((l) => splitAtRange(l.y, slot.yRange));
  slot.edges = split.flatMap((sp, s) => sp.outside.map(({ i, value }) => ({
    s, i, x: x[i], value, text: `w${lines[s].m === 1 ? '₁' : '₂'} ${edgeText(value, lines[s].err[i])}`, color: lines[s].color,
  })));
  slot.bars = lines.map((l) => ({ err: l.err, color: l.color }));
  slot.markers = lines.map((l) => ({ open: l.y.map(() => l.hollow), color: l.color }));
  slot.guides = { x: spotGuide(spec.scene.illumination), y: [] };
  const dark = data.series.filter((b) => b.drawn === 0);
  slot.notes = [
    { marker: 'filled', text: 'filled, solid: w₁ ± 1 SE' },
    { marker: 'open', text: 'hollow, dashed: w₂ ± 1 SE' },
    ...dark.map((b) => ({ marker: 'none', text: `${r2Words(b.r2)}: no light path reaches it` })),
    ...(slot.edges.length ? [{ marker: 'edge', text: 'beyond the axis: marked at its edge with the value' }] : []),
  ];
  const series = [{ label: 'r₃', value: legendValue(formatParameter) }];
  lines.forEach((l, k) => series.push({
    label: `w${l.m === 1 ? '₁' : '₂'}, ${r2Words(l.b.r2)}`, stroke: l.color, width: 2, dash: l.dash,
    points: { show: false }, value: frameValue(slot, k),
  }));
  slot.draw({
    series,
    scales: { x: { time: false, range: () => slot.xRange }, y: { range: () => slot.yRange } },
    axes: [axis({ label: 'r₃ (bin midpoint)' }), axis({ label: 'effective weight' })],
    cursor: { drag: { x: true, y: false } },
    plugins: [errorBars(slot), markers(slot), guides(slot), edgeMarks(slot)],
  }, [x, ...split.map((sp) => sp.inside)]);
  showMessage(note, effectiveCaption(source, data, { dark, edges: slot.edges.length, guided: slot.guides.x.length > 0 }));
}

/** What panel (a) shows and how to read it. */
function effectiveCaption({ effective: doc, recommended: rec, kept }, data, { dark, edges, guided }) {
  const parts = [];
  const what = KINDS[doc.kind] ?? doc.kind;
  if (doc.kind === 'heuristic') {
    parts.push(`Recommended: ${doc.strategy}, ${what} (no weights table: its weights are a function of the whole path).`);
  } else {
    const lambda = rec && rec.strategy === doc.strategy && rec.lambda !== null && rec.lambda !== undefined ? `, λ = ${formatParameter(rec.lambda)}` : '';
    parts.push(`Recommended: ${doc.strategy}, ${what}${lambda}, fitted on all iterations.`);
    if (doc.kind === 'stack' && rec?.heuristics?.length) {
      parts.push(`Drawn whole — its table part and Σ β·heuristic together, β: ${formatBetas(rec.heuristics)}.`);
    }
  }
  if (kept) parts.push('(The kept solve\'s recommendation: a per-path heuristic, the same function under any solver options.)');
  parts.push(`These are its effective weights: per (r₂, r₃) bin the contribution-weighted average of each technique's weight over the bin's full paths (paths_per_side = ${formatCount(doc.paths_per_side)} paths per side, drawn by the server for this figure), with bars of ± 1 standard error (${doc.kind === 'heuristic' ? 'sampling' : 'sampling and the fit\'s jackknife over the folds, combined'}).`);
  parts.push('Solid line, filled markers: w₁; dashed, hollow: w₂.');
  const w0 = data.series.flatMap((b) => b.w0).filter((v) => v !== null);
  if (w0.every((v) => Math.abs(v) < 1e-12)) parts.push('w₀ = 0 in every bin.');
  else parts.push(`w₀ = 1 − w₁ − w₂ (|w₀| up to ${fixed(Math.max(...w0.map(Math.abs)), 3)}) is in the effective weights CSV.`);
  for (const b of dark) parts.push(`${r2Words(b.r2)}: no light path reaches it (no sampled path carries light there), so no weight matters there; not drawn.`);
  const gaps = data.series.filter((b) => b.drawn > 0).reduce((n, b) => n + b.bins.length - b.drawn, 0);
  if (gaps) parts.push(`${gaps} bin${gaps > 1 ? 's' : ''} without a light-carrying path ${gaps > 1 ? 'are gaps' : 'is a gap'}.`);
  const tail = data.r3.at(-1);
  if (tail?.[1] === null) parts.push(`The open tail bin r₃ ≥ ${formatParameter(tail[0])} is drawn at r₃ = ${formatParameter(Number(data.x.at(-1).toPrecision(6)))} (its edge plus the previous bin's width).`);
  if (edges) parts.push(`${edges} value${edges > 1 ? 's lie' : ' lies'} beyond the axis: marked ▲/▼ at the frame's edge with the value.`);
  if (guided) parts.push('Dashed vertical line: the spot radius a.');
  const reached = doc.camera_paths_reaching_plane3 < doc.paths_per_side ? ` (${formatCount(doc.camera_paths_reaching_plane3)} camera paths reached plane 3)` : '';
  parts.push(`The paths' estimate of the pixel's L·10⁵: ${formatLuminance(doc.luminance)}${reached}.`);
  return parts.join(' ');
}

/**
 * Panel (b)'s data from a λ = 0 table's `weights`: w₁ against the r₃ cell position (r3Positions:
 * the tail cell one step past the grid), one series per r₂ bin, in the first φ bin. Per series:
 * `y` w₁ of the cells fitted to data (null for a copied cell: empty or uninformative), `err` its
 * jackknife SE (null without one), `noSe` whether the cell has none (fixed, smoothed), `copied`
 * how many cells are copies.
 */
export function lambdaZeroSeries(weights) {
  const phi = binsOf(weights, 'phi')[0];
  const cells = weights.filter((w) => w.phi[0] === phi[0]);
  const r3 = binsOf(cells, 'r3');
  const x = r3Positions(r3);
  const series = binsOf(cells, 'r2').map((r2) => {
    const at = new Map(cells.filter((w) => w.r2[0] === r2[0]).map((w) => [w.r3[0], w]));
    const cell = r3.map((b) => at.get(b[0]) ?? null);
    const data = cell.map((w) => (w && !UNFITTED.has(w.status) ? w : null));
    return {
      r2,
      y: data.map((w) => w?.w1 ?? null),
      err: data.map((w) => (w && !openCell(w) ? w.w1_stderr : null)),
      noSe: data.map((w) => (w ? openCell(w) : false)),
      copied: cell.filter((w) => w && UNFITTED.has(w.status)).length,
      drawn: data.filter(Boolean).length,
    };
  });
  return { x, r3, end: r3AxisEnd(r3, x), series, phi, phiBins: binsOf(weights, 'phi').length };
}

/**
 * Draws panel (b): `source` is { result } (the result at λ = 0), { error } (its request failed) or
 * { message }; `kept` whether the page shows a kept solve (this panel is the job's own options').
 */
export function drawLambdaZero(slot, note, source, spec, jobTitle, kept) {
  const weights = source.result?.weights ?? [];
  const data = weights.length ? lambdaZeroSeries(weights) : null;
  const shown = data ? data.series.filter((b) => b.drawn > 0) : [];
  if (shown.length === 0) {
    slot.edges = [];
    const why = source.error ?? source.result?.solve_error ?? (data ? 'every cell is a copy of a neighbour' : 'no weights');
    slot.clear(source.message ?? `The λ = 0 fit failed: ${why}`);
    showMessage(note, '');
    return;
  }
  slot.title = `${jobTitle}: w₁ fitted in-sample at λ = 0 (the paper's procedure), not recommended`;
  slot.yRange = [...WEIGHT_FRAME];
  slot.xRange = [0, data.end];
  const colors = shown.map((b) => R2_COLORS[data.series.indexOf(b) % R2_COLORS.length]);
  const split = shown.map((b) => splitAtRange(b.y, slot.yRange));
  slot.edges = split.flatMap((sp, s) => sp.outside.map(({ i, value }) => ({
    s, i, x: data.x[i], value, text: edgeText(value, shown[s].err[i]), color: colors[s],
  })));
  // Bars and markers only where the value is drawn: an off-scale cell is its edge mark alone.
  slot.bars = shown.map((b, s) => ({ err: b.err.map((e, i) => (split[s].inside[i] === null ? null : e)), color: colors[s] }));
  slot.markers = shown.map((b, s) => ({ open: b.noSe, noSe: b.noSe, color: colors[s] }));
  slot.guides = { x: spotGuide(spec.scene.illumination), y: [] };
  const drawn = split.reduce((n, sp) => n + sp.inside.filter((v) => v !== null).length, 0);
  const open = shown.reduce((n, b, s) => n + b.noSe.filter((o, i) => o && split[s].inside[i] !== null).length, 0);
  const hidden = data.series.filter((b) => b.drawn === 0);
  slot.notes = [
    open < drawn ? { marker: 'filled', text: 'filled: fitted to its own samples, ± 1 jackknife SE' } : null,
    open ? { marker: 'open', text: 'open: no data SE, no bar' } : null,
    slot.edges.length ? { marker: 'edge', text: `▲/▼: beyond [${WEIGHT_FRAME.map((v) => String(v).replace('-', '−')).join(', ')}], with the value` } : null,
    ...hidden.map((b) => ({ marker: 'none', text: `${r2Words(b.r2)}: every cell copied from a neighbour (no data)` })),
    { marker: 'none', text: 'in-sample fit: not an honest estimate, not recommended' },
  ].filter(Boolean);
  const series = [{ label: 'r₃', value: legendValue(formatParameter) }];
  shown.forEach((b, k) => series.push({
    label: `w₁ (λ = 0), ${r2Words(b.r2)}`, stroke: colors[k], width: 2, dash: k ? [8, 4] : [], points: { show: false },
    value: frameValue(slot, k),
  }));
  slot.draw({
    series,
    scales: { x: { time: false, range: () => slot.xRange }, y: { range: () => slot.yRange } },
    axes: [axis({ label: `r₃ (cell midpoint)${data.phiBins > 1 ? `, φ ∈ ${formatInterval(data.phi.map((v) => Number(v.toFixed(3))))}` : ''}` }),
      axis({ label: 'w₁ (λ = 0, in-sample)' })],
    cursor: { drag: { x: true, y: false } },
    plugins: [errorBars(slot), markers(slot), guides(slot), edgeMarks(slot)],
  }, [data.x, ...split.map((sp) => sp.inside)]);
  showMessage(note, lambdaZeroCaption(weights, data, { hidden, open, drawn, edges: slot.edges.length, guided: slot.guides.x.length > 0, kept }));
}

/** What panel (b) shows and how to read it. */
function lambdaZeroCaption(weights, data, { hidden, open, drawn, edges, guided, kept }) {
  const parts = ['The paper\'s procedure: the weights table fitted at λ = 0 (no smoothing) on all iterations and drawn from the same iterations — in-sample fit: not an honest estimate, not recommended (the recommended weights are the other panel).'];
  if (kept) parts.push('Under the job\'s own solver options, not the kept solve\'s.');
  if (open < drawn) parts.push('Filled markers: cells fitted to their own samples, with bars of ± 1 jackknife standard error of w₁.');
  if (open) parts.push(`Open markers (${open}): cells without a data standard error (fixed), no bar.`);
  if (edges) parts.push(`${edges} cell${edges > 1 ? 's lie' : ' lies'} beyond the axis [${WEIGHT_FRAME.map((v) => String(v).replace('-', '−')).join(', ')}] — noise of cells with few samples: marked ▲/▼ at the frame's edge with the value ± its SE.`);
  const copied = data.series.filter((b) => b.drawn > 0).reduce((n, b) => n + b.copied, 0);
  if (copied) parts.push(`${copied} cell${copied > 1 ? 's are copies' : ' is a copy'} of a neighbour (status empty or uninformative), not data: ${copied > 1 ? 'gaps' : 'a gap'}.`);
  for (const b of hidden) parts.push(`${r2Words(b.r2)}: every cell is a copy of a neighbour (no data), so it has no line.`);
  const tail = data.r3.at(-1);
  if (tail?.[1] === null) parts.push(`The open tail cell r₃ ≥ ${formatParameter(tail[0])} is drawn at r₃ = ${formatParameter(Number(data.x.at(-1).toPrecision(6)))}.`);
  if (weights.every((w) => w.w0 === 0)) parts.push('w₂ = 1 − w₁ (w₀ = 0 in every cell), so it is not drawn.');
  else parts.push('w₂ = 1 − w₀ − w₁, not drawn.');
  if (data.phiBins > 1) parts.push(`First of ${data.phiBins} φ bins.`);
  if (guided) parts.push('Dashed vertical line: the spot radius a.');
  return parts.join(' ');
}

/**
 * The value of series k + 1 of `slot` in the legend under the cursor: w₁ ± its SE (from slot.bars,
 * not the series' data: a redraw with the same series keeps these functions), or that the cell has
 * no SE. Shared by the compare overlay and the sweep's small multiples.
 */
export const weightValue = (slot, k) => legendValue((v, i) => {
  const e = slot.bars?.[k]?.err[i];
  if (slot.markers?.[k]?.open[i]) return `${fixed(v, 3)} (no SE)`;
  return `${fixed(v, 3)}${e === null || e === undefined ? '' : ` ± ${fixed(e, 3)}`}`;
});
