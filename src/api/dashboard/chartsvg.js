// Chart SVG: the chart of a PlotSlot (plots.js) as a vector figure — its shown series (lines,
// points, filled and open markers, error bars, bands, guide lines, the edge marks of values beyond
// the y range) redrawn from the uPlot
// instance's data and current scales and the slot's extras (chartkit.js), ticked by the page's
// rules (axes.js), with its title, axis labels and legend (the series, then the slot's notes) laid
// out by measuring their text, so that nothing is cut or overlaps whatever the labels. The PNG
// (chartfiles.js) is this SVG rasterised at twice its size: both files show the same figure.

import { linearLabels, linearTicks, logLabel, logTicks } from './axes.js';
import { EDGE_FONT, MARKER_RADIUS, edgeLabelOffset, edgeLayout } from './chartkit.js';

const FONT = 'system-ui, Helvetica, Arial, sans-serif';
const LEGEND_ROW = 20;
const SWATCH = 22;

const escapeXml = (text) => String(text).replace(/[<>&"']/g, (c) => ({ '<': '&lt;', '>': '&gt;', '&': '&amp;', '"': '&quot;', "'": '&apos;' }[c]));
const num = (x) => Number(x.toFixed(2));

const measurer = document.createElement('canvas').getContext('2d');
/** The width of `text` in px as the browser sets it (with a little slack for other renderers). */
export function textWidth(text, size = 12, weight = 'normal') {
  measurer.font = `${weight} ${size}px ${FONT}`;
  return measurer.measureText(String(text)).width * 1.04;
}

/** `text` broken into lines no wider than `width` at `size` px (a word longer than that keeps its own line). */
export function wrap(text, width, size, weight) {
  const lines = [];
  let line = '';
  for (const word of String(text).split(' ')) {
    const next = line ? `${line} ${word}` : word;
    if (line && textWidth(next, size, weight) > width) {
      lines.push(line);
      line = word;
    } else line = next;
  }
  if (line) lines.push(line);
  return lines;
}

/** A series' stroke colour as uPlot resolved it. */
function strokeOf(u, i) {
  const stroke = u.series[i].stroke;
  return (typeof stroke === 'function' ? stroke(u, i) : stroke) || '#444';
}

/** The shown y series of `u`: index, label, colour, dash, width, and whether it shows points. */
export function shownSeries(u) {
  return u.series.map((s, i) => ({ s, i })).filter(({ s, i }) => i > 0 && s.show).map(({ s, i }) => {
    let points = s.points?.show;
    if (typeof points === 'function') {
      try { points = points(u, i); } catch { points = false; }
    }
    return { i, label: s.label, color: strokeOf(u, i), dash: s.dash ?? [], width: s.width ?? 1, points: Boolean(points) };
  });
}

/** Maps a value of scale `key` of `u` to [0, 1] along it (log scales logarithmically); null if it cannot be drawn. */
function fraction(u, key, v) {
  const { min, max, distr } = u.scales[key];
  if (v === null || v === undefined || !Number.isFinite(v)) return null;
  if (distr === 3) return v > 0 && min > 0 ? Math.log10(v / min) / Math.log10(max / min) : null;
  return (v - min) / (max - min);
}

/** The ticks and their labels of scale `key` over `pixels`: the slot's own (xTicks, xLabels) or the page's rules. */
function ticksOf(slot, key, pixels, space) {
  const { min, max, distr } = slot.plot.scales[key];
  if (key === 'x' && slot.xLabels) {
    const ticks = slot.xLabels.map((_, i) => i).filter((i) => i >= min && i <= max);
    return { ticks, labels: ticks.map((i) => slot.xLabels[i]) };
  }
  if (key === 'x' && slot.xTicks) {
    const ticks = slot.xTicks.filter((v) => v >= min && v <= max);
    return { ticks, labels: ticks.map((v) => (distr === 3 ? logLabel(v) : String(Number(v.toPrecision(6))))) };
  }
  if (distr === 3) {
    const ticks = logTicks(min, max);
    return { ticks, labels: ticks.map(logLabel) };
  }
  const { ticks, step } = linearTicks(min, max, pixels, space);
  return { ticks, labels: linearLabels(ticks, step) };
}

/** A legend laid out in rows across `width`: each entry a swatch and its text; notes on lines of their own. */
function legendLayout(series, notes, width) {
  const items = [];
  let x = 0;
  let row = 0;
  for (const s of series) {
    const w = SWATCH + 6 + textWidth(s.label) + 18;
    if (x > 0 && x + w > width) {
      x = 0;
      row += 1;
    }
    items.push({ ...s, x, row });
    x += w;
  }
  const first = series.length ? row + 1 : 0;
  return { items, notes: notes.map((note, n) => ({ ...note, row: first + n })), rows: first + notes.length };
}

/**
 * The SVG document of the chart in `slot`: `width` px wide with a plot `plotHeight` px high (CSS
 * px), its title `title` (default the slot's; null for none) and, with `legend`, its legend.
 */
export function chartSvg(slot, { width = 820, plotHeight = 320, title = slot.title ?? 'optimis chart', legend = true } = {}) {
  const u = slot.plot;
  const titleLines = title ? wrap(title, width - 24, 15, '600') : [];
  const yTicksProbe = ticksOf(slot, 'y', plotHeight, 36);
  const top = 12 + titleLines.length * 19 + 12;
  const left = 26 + Math.max(24, ...yTicksProbe.labels.map((l) => textWidth(l))) + 8;
  const xProbe = ticksOf(slot, 'x', width - left - 24, 64);
  const right = Math.max(20, textWidth(xProbe.labels.at(-1) ?? '') / 2 + 6);
  const plotW = width - left - right;
  const plotH = plotHeight;
  const { ticks: xTicks, labels: xLabels } = ticksOf(slot, 'x', plotW, 64);
  const { ticks: yTicks, labels: yLabels } = yTicksProbe;
  const X = (v) => { const f = fraction(u, 'x', v); return f === null ? null : left + f * plotW; };
  const Y = (v) => { const f = fraction(u, 'y', v); return f === null ? null : top + (1 - f) * plotH; };
  const series = shownSeries(u);
  const lay = legend ? legendLayout(series, slot.notes ?? [], width - left - 12) : { items: [], notes: [], rows: 0 };
  const legendTop = top + plotH + 64;
  const height = lay.rows ? legendTop + lay.rows * LEGEND_ROW + 4 : top + plotH + 50;
  const out = [];
  out.push(`<svg xmlns="http://www.w3.org/2000/svg" width="${width}" height="${num(height)}" viewBox="0 0 ${width} ${num(height)}" font-family="${FONT}" font-size="12">`);
  out.push(`<title>${escapeXml(title ?? slot.title ?? '')}</title>`);
  out.push(`<rect width="${width}" height="${num(height)}" fill="#fff"/>`);
  titleLines.forEach((line, k) => out.push(`<text x="12" y="${24 + k * 19}" font-size="15" font-weight="600" fill="#1d2430">${escapeXml(line)}</text>`));
  const clip = `plot-area-${Math.random().toString(36).slice(2, 8)}`;
  out.push(`<defs><clipPath id="${clip}"><rect x="${num(left)}" y="${top}" width="${num(plotW)}" height="${plotH}"/></clipPath></defs>`);
  // Axes: grid lines, the frame, tick labels and the axis labels (shrunk to fit their side if long).
  out.push('<g class="axes" stroke="#e3e6eb" stroke-width="1">');
  for (const v of xTicks) out.push(`<line x1="${num(X(v))}" x2="${num(X(v))}" y1="${top}" y2="${top + plotH}"/>`);
  for (const v of yTicks) out.push(`<line x1="${num(left)}" x2="${num(left + plotW)}" y1="${num(Y(v))}" y2="${num(Y(v))}"/>`);
  out.push('</g>');
  out.push(`<rect x="${num(left)}" y="${top}" width="${num(plotW)}" height="${plotH}" fill="none" stroke="#555"/>`);
  out.push('<g class="tick-labels" fill="#333">');
  xTicks.forEach((v, k) => out.push(`<text x="${num(X(v))}" y="${top + plotH + 17}" text-anchor="middle">${escapeXml(xLabels[k])}</text>`));
  yTicks.forEach((v, k) => out.push(`<text x="${num(left - 6)}" y="${num(Y(v) + 4)}" text-anchor="end">${escapeXml(yLabels[k])}</text>`));
  out.push('</g>');
  const axisLabel = (text, room) => `font-size="${num(Math.min(12.5, (12.5 * room) / Math.max(1, textWidth(text, 12.5, '600'))))}" font-weight="600"`;
  const xText = u.axes[0].label ?? '';
  const yText = u.axes[1].label ?? '';
  out.push(`<text class="axis-label" x="${num(left + plotW / 2)}" y="${top + plotH + 42}" text-anchor="middle" ${axisLabel(xText, plotW)}>${escapeXml(xText)}</text>`);
  out.push(`<text class="axis-label" transform="translate(16 ${num(top + plotH / 2)}) rotate(-90)" text-anchor="middle" ${axisLabel(yText, plotH)}>${escapeXml(yText)}</text>`);
  out.push(`<g clip-path="url(#${clip})">`, ...dataMarks(slot, series, X, Y, top + plotH), ...guideMarks(slot, X, Y, { left, top, plotW, plotH }), '</g>');
  out.push(...edgeSvg(slot, X, top, plotH, left + plotW));
  if (legend) out.push(...legendMarks(lay, left, legendTop));
  out.push('</svg>');
  return `${out.join('\n')}\n`;
}

/** The bands, lines, markers and error bars of the shown `series`. */
function dataMarks(slot, series, X, Y, bottom) {
  const u = slot.plot;
  const out = [];
  for (const { i, color } of series) {
    const band = slot.bands?.[i - 1];
    if (!band) continue;
    for (const run of bandRuns(band)) {
      const upper = run.map((k) => [X(u.data[0][k]), Y(band.hi[k])]);
      const lower = [...run].reverse().map((k) => [X(u.data[0][k]), Y(band.lo[k])]);
      const pts = [...upper, ...lower].filter(([x, y]) => x !== null && y !== null);
      out.push(`<polygon class="band" fill="${color}" fill-opacity="0.14" points="${pts.map(([x, y]) => `${num(x)},${num(y)}`).join(' ')}"/>`);
    }
  }
  for (const { i, color, dash, width, points } of series) {
    const d = [];
    let pen = 'M';
    const marks = [];
    u.data[0].forEach((xv, k) => {
      const x = X(xv);
      const y = Y(u.data[i][k]);
      if (x === null || y === null) {
        pen = 'M';
        return;
      }
      d.push(`${pen}${num(x)} ${num(y)}`);
      pen = 'L';
      const open = slot.markers?.[i - 1]?.open[k];
      if (open) marks.push(`<circle class="marker-open" cx="${num(x)}" cy="${num(y)}" r="${MARKER_RADIUS}" fill="#fff" stroke="${color}" stroke-width="1.5"/>`);
      else if (open === false) marks.push(`<circle class="marker" cx="${num(x)}" cy="${num(y)}" r="${MARKER_RADIUS}" fill="${color}"/>`);
      else if (points) marks.push(`<circle cx="${num(x)}" cy="${num(y)}" r="2.5" fill="${color}"/>`);
    });
    const dashAttr = dash.length ? ` stroke-dasharray="${dash.join(' ')}"` : '';
    out.push(`<path class="series" data-label="${escapeXml(u.series[i].label)}" d="${d.join(' ')}" fill="none" stroke="${color}" stroke-width="${width}" stroke-linejoin="round"${dashAttr}/>`);
    out.push(...marks);
    (slot.bars?.[i - 1]?.err ?? []).forEach((e, k) => {
      const y = u.data[i][k];
      if (y === null || e === null || !(e > 0)) return;
      const x = X(u.data[0][k]);
      const hi = Y(y + e);
      const lo = Y(y - e) ?? bottom;
      if (x === null || hi === null) return;
      out.push(`<path class="error-bar" d="M${num(x)} ${num(lo)} V${num(hi)} M${num(x - 3)} ${num(hi)} H${num(x + 3)} M${num(x - 3)} ${num(lo)} H${num(x + 3)}" stroke="${color}" fill="none"/>`);
    });
  }
  return out;
}

/** The slot's dashed guide lines with their labels. */
function guideMarks(slot, X, Y, { left, top, plotW, plotH }) {
  const out = [];
  for (const [axis, list] of [['x', slot.guides?.x ?? []], ['y', slot.guides?.y ?? []]]) {
    for (const { value, label } of list) {
      const p = axis === 'x' ? X(value) : Y(value);
      if (p === null) continue;
      const line = axis === 'x'
        ? `<line x1="${num(p)}" x2="${num(p)}" y1="${top}" y2="${top + plotH}"/><text x="${num(p + 4)}" y="${top + 14}" stroke="none">${escapeXml(label)}</text>`
        : `<line x1="${num(left)}" x2="${num(left + plotW)}" y1="${num(p)}" y2="${num(p)}"/><text x="${num(left + 6)}" y="${num(p - 5)}" stroke="none">${escapeXml(label)}</text>`;
      out.push(`<g class="guide" data-axis="${axis}" data-value="${value}" stroke="#333" stroke-width="1.5" stroke-dasharray="6 4" fill="#333">${line}</g>`);
    }
  }
  return out;
}

/** The slot's edge marks (chartkit.js's edgeMarks): ▲/▼ at the frame's edge with the value beside it. */
function edgeSvg(slot, X, top, plotH, right) {
  const u = slot.plot;
  const shown = (slot.edges ?? []).filter((e) => u.series[e.s + 1]?.show);
  const layout = edgeLayout(shown, u.scales.y.min, u.scales.y.max, X, (text) => textWidth(text, EDGE_FONT), 4, right);
  if (layout.length === 0) return [];
  const out = [`<g class="off-scale" font-size="${EDGE_FONT}">`];
  for (const m of layout) {
    const down = m.side === 'bottom';
    const edge = down ? top + plotH - 1 : top + 1;
    const base = down ? edge - 8 : edge + 8;
    const offset = edgeLabelOffset(m.row);
    out.push(`<path class="off-scale-mark" d="M${num(m.px)} ${num(edge)} L${num(m.px - 5)} ${num(base)} L${num(m.px + 5)} ${num(base)} Z" fill="${m.color}"/>`,
      `<text x="${num(m.lx)}" y="${num((down ? edge - offset : edge + offset) + 4)}" fill="#1d2430">${escapeXml(m.text)}</text>`);
  }
  out.push('</g>');
  return out;
}

/** A legend note's symbol at (x, y): a filled or open marker, an edge mark's triangle, or none. */
export function noteSymbol(marker, x, y) {
  if (marker === 'none') return '';
  if (marker === 'edge') return `<path d="M${num(x)} ${num(y - 5)} L${num(x - 5)} ${num(y + 3)} L${num(x + 5)} ${num(y + 3)} Z" fill="#444"/>`;
  return `<circle cx="${num(x)}" cy="${y}" r="${MARKER_RADIUS}" fill="${marker === 'open' ? '#fff' : '#444'}" stroke="#444" stroke-width="1.5"/>`;
}

/** The legend: a swatch (the series' line, dashed like it) and its label per entry, then the notes. */
function legendMarks(lay, left, legendTop) {
  const out = ['<g class="legend" fill="#1d2430">'];
  for (const { x, row, color, dash, label } of lay.items) {
    const y = legendTop + row * LEGEND_ROW;
    const dashAttr = dash.length ? ` stroke-dasharray="${dash.join(' ')}"` : '';
    out.push(`<line x1="${num(left + x)}" x2="${num(left + x + SWATCH)}" y1="${y}" y2="${y}" stroke="${color}" stroke-width="2.5"${dashAttr}/>`);
    out.push(`<text x="${num(left + x + SWATCH + 6)}" y="${y + 4}">${escapeXml(label)}</text>`);
  }
  for (const note of lay.notes) {
    const y = legendTop + note.row * LEGEND_ROW;
    out.push(noteSymbol(note.marker, left + 11, y));
    out.push(`<text class="note" x="${num(left + SWATCH + 6)}" y="${y + 4}">${escapeXml(note.text)}</text>`);
  }
  out.push('</g>');
  return out;
}

/** The index runs where a band has both edges. */
function bandRuns({ lo, hi }) {
  const out = [];
  let run = [];
  lo.forEach((l, k) => {
    if (Number.isFinite(l) && Number.isFinite(hi[k])) run.push(k);
    else if (run.length) {
      out.push(run);
      run = [];
    }
  });
  if (run.length) out.push(run);
  return out;
}
