// Fig. 2 of the paper: a weights table's w₁ against r₃, one line per r₂ band — which table it is,
// its data, and its chart with caption.
//
// Which table: the recommended row's, when the recommendation has one (optimal_cv, or a table with
// heuristics stacked on it, whose table part T is drawn: a path's weights add Σ β·heuristic). When
// a per-path strategy is recommended the result has no table; the chart then shows the table
// optimum at optimal_cv's λ (GET /v1/jobs/{id}/result?lambda=λ, fitted on all iterations) for
// reference, labelled as not recommended. Cells the gradient penalty set (status `smoothed`) have
// no data standard error: open markers, no bars.

import { axis, legendValue } from './axes.js';
import { errorBars, extent, guides, markers } from './chartkit.js';
import { fixed, formatBetas, formatParameter, showMessage, signed } from './format.js';
import { UNFITTED, WEIGHT_RANGE, binsOf, formatInterval, spotGuide, weightRange } from './plots.js';

/**
 * The λ at which to fetch the table optimum for `result`, or null when it is not wanted: wanted
 * when a per-path strategy is recommended (no table) and optimal_cv chose a λ.
 */
export function tableOptimumLambda(result) {
  if (result.weights.length > 0 || (result.recommended?.lambda ?? null) !== null) return null;
  const cv = result.noise_table.find((r) => r.strategy === 'optimal_cv');
  return cv && !cv.error && cv.lambda !== null && cv.lambda !== undefined ? cv.lambda : null;
}

/**
 * What Fig. 2 shows for `result`: the recommended table, else `optimum` (the table optimum's
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
 * Fig. 2's data from a table's `weights`: w₁ against the r₃ cell midpoint, one series per r₂ bin,
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

/** The chart's title, its heading's label and the series' prefix for `source`. */
function labelsOf(source) {
  if (source.kind === 'table-optimum') {
    const what = `table optimum (optimal_cv, λ = ${formatParameter(source.lambda)}), not recommended`;
    return { title: `w₁ of the ${what}, against r₃`, heading: what, series: 'w₁ (table optimum, not recommended)' };
  }
  const part = source.heuristics.length > 0;
  return {
    title: `recommended ${part ? `${source.strategy}: its table part T₁` : 'w₁'} against r₃ (Fig. 2)`,
    heading: `recommended: ${source.strategy}${part ? ' (its table part)' : ''}`,
    series: part ? 'T₁ (table part)' : 'w₁',
  };
}

/**
 * Draws Fig. 2 of `source` (figureSource) in `slot`, its caption in `note` and what it shows in
 * `kind` (beside the card's heading); `jobTitle` starts the chart files' title.
 */
export function drawWeights(slot, { note, kind }, source, spec, jobTitle) {
  if (source.kind === 'none') {
    slot.clear(source.message);
    showMessage(note, '');
    kind.textContent = '';
    return;
  }
  const labels = labelsOf(source);
  slot.title = `${jobTitle}: ${labels.title}`;
  kind.textContent = labels.heading;
  kind.dataset.kind = source.kind;
  const { x, series: bins, phi, phiBins, edge } = figure2(source.weights);
  const colors = bins.map((b, k) => R2_COLORS[k % R2_COLORS.length]);
  slot.bars = bins.map((b, k) => ({ err: b.err, color: colors[k] }));
  slot.markers = bins.map((b, k) => ({ open: b.open, color: colors[k] }));
  slot.guides = { x: spotGuide(spec.scene.illumination), y: [] };
  const open = bins.flatMap((b) => b.open.filter((o, i) => o && b.y[i] !== null)).length;
  const part = source.kind === 'recommended' && source.heuristics.length > 0;
  const drawn = bins.flatMap((b) => b.y.filter((v) => v !== null)).length;
  slot.notes = [
    open < drawn && open ? { marker: 'filled', text: 'filled: fitted to its own samples, ± 1 jackknife SE' } : null,
    open ? { marker: 'open', text: 'open: no data SE (smoothed: set by its neighbours through λ), no bar' } : null,
  ].filter(Boolean);
  const series = [{ label: 'r₃', value: legendValue(formatParameter) }];
  bins.forEach((b, k) => series.push({
    label: `${labels.series}, r₂ ∈ ${formatInterval(b.r2)}`, stroke: colors[k], width: 2, dash: k ? [8, 4] : [],
    points: { show: false }, value: weightValue(slot, k),
  }));
  slot.draw({
    series,
    scales: { x: { time: false, range: (u, min, max) => [0, edge ?? max] },
      y: { range: (u, min, max) => weightRange(u, ...(extent(u, slot, false) ?? [min, max]), part ? [0] : [0, 1]) } },
    axes: [axis({ label: `r₃ (cell midpoint)${phiBins > 1 ? `, φ ∈ ${formatInterval(phi.map((v) => Number(v.toFixed(3))))}` : ''}` }),
      axis({ label: part ? 'T₁ (table part of w₁)' : 'w₁' })],
    cursor: { drag: { x: true, y: false } },
    plugins: [errorBars(slot), markers(slot), guides(slot)],
  }, [x, ...bins.map((b) => b.y)]);
  showMessage(note, caption(source, { x, bins, open, drawn, phiBins, guided: slot.guides.x.length > 0 }));
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

/** What the chart shows and how to read it. */
function caption(source, { x, bins, open, drawn, phiBins, guided }) {
  const parts = [];
  const part = source.kind === 'recommended' && source.heuristics.length > 0;
  const betaSum = part ? source.heuristics.reduce((s, b) => s + b.beta, 0) : 0;
  if (source.kind === 'table-optimum') {
    parts.push(`Not the recommended weights: the recommendation is ${source.recommended}, a per-path strategy (no table; the reason is under the noise table).`,
      `Drawn for reference: the table optimum at optimal_cv's λ = ${formatParameter(source.lambda)}, fitted on all iterations (its cross-fitted figures are optimal_cv's row).`);
  } else if (source.strategy === 'optimal') {
    parts.push(`Weights fitted in-sample on all iterations at λ = ${formatParameter(source.lambda)}.`);
  } else {
    // A corrected row takes the stacked optimum's λ; the others chose their own.
    const how = source.strategy.endsWith('_corrected') ? "optimal_stacked's, chosen by cross-validation" : 'chosen by cross-validation';
    parts.push(`Recommended: ${source.strategy}, λ = ${formatParameter(source.lambda)} (${how}), fitted on all iterations.`);
    if (part) {
      parts.push(`Drawn: its table part T₁; a path's w₁ is T₁ + Σ β·(that heuristic's w₁ of the path), β: ${formatBetas(source.heuristics)}. The table's weights sum to 1 − Σβ = ${signed(1 - betaSum, 3)} in every cell.`);
    }
  }
  if (open < drawn) parts.push('Filled markers: cells fitted to their own samples, with bars of ± 1 jackknife standard error of w₁.');
  if (open) {
    parts.push(`Open markers (${open === drawn ? `all ${open}` : open}): cells without a data standard error — smoothed cells, whose weights the gradient penalty (their neighbours) set more than their own merges — drawn without bars.`);
  }
  // From the table itself, not the job's spec: a kept solve may have freed w₀.
  const [w0, w1, w2, total] = part ? ['T₀', 'T₁', 'T₂', '(1 − Σβ)'] : ['w₀', 'w₁', 'w₂', '1'];
  if (source.weights.every((w) => w.w0 === 0)) parts.push(`${w2} = ${total} − ${w1} (w₀ = 0 in every cell), so it is not drawn.`);
  else parts.push(`${w2} = ${total} − ${w0} − ${w1}; both are in the weights CSV.`);
  parts.push(`The open tail cell r₃ ≥ ${formatParameter(x.length ? binsOf(source.weights, 'r3').at(-1)[0] : 0)} is left out; gaps are cells without informative samples.`);
  if (phiBins > 1) parts.push(`First of ${phiBins} φ bins.`);
  if (guided) parts.push('Dashed line: the spot radius a, where the switch strategy changes plane.');
  const clipped = bins.flatMap((b) => b.y).filter((v) => v !== null && (v < WEIGHT_RANGE[0] || v > WEIGHT_RANGE[1])).length;
  if (clipped) parts.push(`${clipped} value${clipped > 1 ? 's lie' : ' lies'} outside [${WEIGHT_RANGE.join(', ')}] and ${clipped > 1 ? 'are' : 'is'} cut off.`);
  return parts.join(' ');
}
