// Axes and legends of every chart: ticks on round steps, tick labels that say them exactly, axis
// sizes that fit their tick labels and label, and legend values that leave a static picture
// readable. The chart files (chartsvg.js) tick their axes with the same rules.
//
// Why not uPlot's defaults: its linear steps include 2.5 × 10ⁿ, whose ticks 0.0025, 0.005, 0.0075
// it prints with at most three decimals (0.003, 0.005, 0.008: uneven-looking); its log axes put a
// grid line at every 1…9 × 10ⁿ; its axes are a fixed 50 px whatever their labels; and its legend
// shows "—" for every value while no cursor is on the chart, which is what a screenshot shows.

/* global uPlot */

import { fixed } from './format.js';

const SUPERSCRIPTS = { '-': '⁻', 0: '⁰', 1: '¹', 2: '²', 3: '³', 4: '⁴', 5: '⁵', 6: '⁶', 7: '⁷', 8: '⁸', 9: '⁹' };

/** Linear tick steps: 1, 2 and 5 × 10ⁿ. */
export const STEPS = [];
for (let e = -15; e <= 15; e += 1) for (const m of [1, 2, 5]) STEPS.push(Number(`${m}e${e}`));

/** The decimals a tick step needs: 0.005 → 3, 0.02 → 2, 50 → 0. */
export const decimalsOf = (step) => Math.max(0, -Math.floor(Math.log10(step) + 1e-9));

/** Linear ticks in [min, max]: the smallest round step at least `space` px apart over `pixels`. */
export function linearTicks(min, max, pixels, space) {
  if (!(max > min)) return { ticks: Number.isFinite(min) ? [min] : [], step: 1 };
  const step = STEPS.find((s) => (s / (max - min)) * pixels >= space) ?? STEPS.at(-1);
  const ticks = [];
  for (let k = Math.ceil(min / step - 1e-9); k * step <= max + step * 1e-9; k += 1) ticks.push(Number((k * step).toPrecision(12)));
  return { ticks, step };
}

/**
 * Log ticks in [min, max]: the decades; with 2 and 5 × 10ⁿ when they span three decades or less;
 * with every 1…9 × 10ⁿ when less than half of one (else there would be one tick or none).
 */
export function logTicks(min, max) {
  if (!(min > 0 && max > min)) return [];
  const span = Math.log10(max / min);
  const mults = span > 3 ? [1] : span >= 0.5 ? [1, 2, 5] : [1, 2, 3, 4, 5, 6, 7, 8, 9];
  const every = span > 8 ? Math.ceil(span / 8) : 1; // at most about eight decades labelled
  const out = [];
  for (let e = Math.floor(Math.log10(min)); e <= Math.ceil(Math.log10(max)); e += 1) {
    if (mults.length === 1 && e % every !== 0) continue;
    for (const m of mults) {
      const v = Number(`${m}e${e}`);
      if (v >= min * (1 - 1e-9) && v <= max * (1 + 1e-9)) out.push(v);
    }
  }
  return out;
}

/** A power of ten as 10ⁿ. */
export const power = (e) => `10${[...String(e)].map((c) => SUPERSCRIPTS[c]).join('')}`;

/** A log tick: 10ⁿ beyond 10⁴ either way, else the number itself (0.02, 50, 1,000). */
export function logLabel(v) {
  const e = Math.log10(v);
  if (Number.isInteger(Math.round(e * 1e9) / 1e9) && Math.abs(Math.round(e)) >= 4) return power(Math.round(e));
  return Number(v.toPrecision(6)).toLocaleString(undefined, { maximumFractionDigits: 12 });
}

/** Linear ticks' labels: every one with the decimals of the step, so that they read evenly. */
export const linearLabels = (ticks, step) => ticks.map((v) => fixed(Math.abs(v) < step * 1e-9 ? 0 : v, decimalsOf(step)));

/**
 * An axis's size in CSS px: its ticks, the gap and its widest tick label (the line height on a
 * horizontal axis); uPlot adds the label's `labelSize`. Converges in uPlot's few sizing cycles.
 */
export function fitSize(u, values, i, cycle) {
  const axis = u.axes[i];
  if (cycle > 2 && axis._size) return axis._size;
  const tick = (axis.ticks?.show === false ? 0 : axis.ticks?.size ?? 10) + (axis.gap ?? 5);
  const fontPx = axis.font?.[2] ?? 12; // [font, device px, CSS px]
  if (axis.side % 2 === 0) return Math.ceil(tick + fontPx * 1.5 + 2);
  if (!values?.length) return 50;
  u.ctx.font = axis.font[0];
  const widest = Math.max(0, ...values.map((v) => u.ctx.measureText(String(v ?? '')).width)) / uPlot.pxRatio;
  return Math.ceil(tick + widest + 6);
}

/**
 * uPlot axis options for a linear (`log` false) or log scale: round ticks, their labels, a fitted
 * size; `extra` (label, space…) is merged in.
 */
export function axis(extra = {}, log = false) {
  if (log) {
    return {
      size: fitSize,
      splits: (u, i, min, max) => logTicks(min, max),
      filter: (u, splits) => splits, // uPlot's log filter would hide 2 and 5 × 10ⁿ
      values: (u, splits) => splits.map((v) => (v === null ? '' : logLabel(v))),
      ...extra,
    };
  }
  return {
    size: fitSize,
    incrs: STEPS,
    values: (u, splits, i, space, step) => linearLabels(splits, step || (splits[1] - splits[0]) || 1),
    ...extra,
  };
}

/**
 * A legend value: `format(v, i)` under the cursor, "—" where the series has no value there, and
 * nothing while no cursor is on the chart, so that a static legend reads as a key (app.css then
 * hides the colon and the x entry).
 */
export const legendValue = (format) => (u, v, s, i) => {
  if (i === null || i === undefined) return '';
  return v === null || v === undefined ? '—' : format(v, i);
};
