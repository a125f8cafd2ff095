// Chart files: the SVG and PNG downloads of a chart drawn in a PlotSlot (plots.js).
//
// SVG: a small serialiser of what the chart plots — it redraws the shown series (lines, points,
// filled and open markers, error bars, bands, guide lines) from the uPlot instance's data and
// current scales and the slot's extras (chartkit.js) as vector paths, with its own axis ticks and a
// legend (the series, then the slot's notes): a real vector figure, not a picture of the canvas.
// PNG: uPlot's canvas as drawn (axes included) on a white page with the chart's title above and the
// same legend below, saved with canvas.toBlob.

import { saveBlob } from './api.js';
import { MARKER_RADIUS } from './chartkit.js';
import { h } from './format.js';

const W = 820;
const PLOT_H = 400;
const M = { left: 78, right: 24, top: 44, bottom: 56 };
const LEGEND_ROW = 20;
const LEGEND_COLS = 3;

const escapeXml = (text) => String(text).replace(/[<>&"']/g, (c) => ({ '<': '&lt;', '>': '&gt;', '&': '&amp;', '"': '&quot;', "'": '&apos;' }[c]));
const num = (x) => Number(x.toFixed(2));

/** A series' stroke colour as uPlot resolved it. */
function strokeOf(u, i) {
  const stroke = u.series[i].stroke;
  return (typeof stroke === 'function' ? stroke(u, i) : stroke) || '#444';
}

/** The shown y series of `u`: index, label, colour, dash, width, and whether it shows points. */
function shownSeries(u) {
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

/** Round tick values in [min, max]: about `count` on a linear scale, the decades (and 2, 5 ×) on a log one. */
function ticks(min, max, distr, count = 6) {
  if (distr === 3) {
    const out = [];
    const few = Math.log10(max / min) < 2;
    for (let e = Math.floor(Math.log10(min)); e <= Math.ceil(Math.log10(max)); e += 1) {
      for (const m of few ? [1, 2, 5] : [1]) {
        const v = m * 10 ** e;
        if (v >= min * (1 - 1e-9) && v <= max * (1 + 1e-9)) out.push(Number(v.toPrecision(12)));
      }
    }
    return out;
  }
  const raw = (max - min) / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * power).find((s) => s >= raw) ?? raw;
  const out = [];
  for (let v = Math.ceil(min / step) * step; v <= max + step * 1e-9; v += step) out.push(Number(v.toPrecision(12)));
  return out;
}

const tickLabel = (v) => String(Number(v.toPrecision(4)));

/** The SVG document of the chart in `slot` (its title from `slot.title`). */
export function chartSvg(slot) {
  const u = slot.plot;
  const plotW = W - M.left - M.right;
  const plotH = PLOT_H - M.top - M.bottom;
  const X = (v) => { const f = fraction(u, 'x', v); return f === null ? null : M.left + f * plotW; };
  const Y = (v) => { const f = fraction(u, 'y', v); return f === null ? null : M.top + (1 - f) * plotH; };
  const series = shownSeries(u);
  const notes = slot.notes ?? [];
  const legendRows = Math.ceil(series.length / LEGEND_COLS) + notes.length;
  const height = PLOT_H + 12 + legendRows * LEGEND_ROW;
  const out = [];
  const title = slot.title ?? 'optimis chart';
  out.push(`<svg xmlns="http://www.w3.org/2000/svg" width="${W}" height="${height}" viewBox="0 0 ${W} ${height}" font-family="system-ui, Helvetica, Arial, sans-serif" font-size="12">`);
  out.push(`<title>${escapeXml(title)}</title>`);
  out.push(`<rect width="${W}" height="${height}" fill="#fff"/>`);
  out.push(`<text x="${M.left}" y="22" font-size="15" font-weight="600">${escapeXml(title)}</text>`);
  out.push(`<defs><clipPath id="plot-area"><rect x="${M.left}" y="${M.top}" width="${plotW}" height="${plotH}"/></clipPath></defs>`);
  // Axes: grid lines, ticks and labels.
  const xs = u.scales.x;
  const ys = u.scales.y;
  const xTicks = slot.xLabels ? slot.xLabels.map((_, i) => i).filter((i) => i >= xs.min && i <= xs.max) : ticks(xs.min, xs.max, xs.distr);
  const yTicks = ticks(ys.min, ys.max, ys.distr);
  out.push('<g class="axes" stroke="#e3e6eb" stroke-width="1">');
  for (const v of xTicks) out.push(`<line x1="${num(X(v))}" x2="${num(X(v))}" y1="${M.top}" y2="${M.top + plotH}"/>`);
  for (const v of yTicks) out.push(`<line x1="${M.left}" x2="${M.left + plotW}" y1="${num(Y(v))}" y2="${num(Y(v))}"/>`);
  out.push('</g>');
  out.push(`<rect x="${M.left}" y="${M.top}" width="${plotW}" height="${plotH}" fill="none" stroke="#555"/>`);
  out.push('<g class="tick-labels" fill="#333">');
  for (const v of xTicks) {
    const label = slot.xLabels ? slot.xLabels[v] : tickLabel(v);
    out.push(`<text x="${num(X(v))}" y="${M.top + plotH + 16}" text-anchor="middle">${escapeXml(label)}</text>`);
  }
  for (const v of yTicks) out.push(`<text x="${M.left - 6}" y="${num(Y(v) + 4)}" text-anchor="end">${escapeXml(tickLabel(v))}</text>`);
  out.push('</g>');
  out.push(`<text x="${M.left + plotW / 2}" y="${M.top + plotH + 40}" text-anchor="middle">${escapeXml(u.axes[0].label ?? '')}</text>`);
  out.push(`<text transform="translate(16 ${M.top + plotH / 2}) rotate(-90)" text-anchor="middle">${escapeXml(u.axes[1].label ?? '')}</text>`);
  // The data, clipped to the plot area.
  out.push('<g clip-path="url(#plot-area)">');
  for (const { i, color } of series) {
    const band = slot.bands?.[i - 1];
    if (!band) continue;
    for (const run of bandRuns(band)) {
      const upper = run.map((k) => [X(u.data[0][k]), Y(band.hi[k])]);
      const lower = run.reverse().map((k) => [X(u.data[0][k]), Y(band.lo[k])]);
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
    out.push(`<path class="series" data-label="${escapeXml(u.series[i].label)}" d="${d.join(' ')}" fill="none" stroke="${color}" stroke-width="${width}"${dashAttr}/>`);
    out.push(...marks);
    const bars = slot.bars?.[i - 1];
    if (!bars) continue;
    bars.err.forEach((e, k) => {
      const y = u.data[i][k];
      if (y === null || e === null || !(e > 0)) return;
      const x = X(u.data[0][k]);
      const hi = Y(y + e);
      const lo = Y(y - e) ?? M.top + plotH;
      if (x === null || hi === null) return;
      out.push(`<path class="error-bar" d="M${num(x)} ${num(lo)} V${num(hi)} M${num(x - 3)} ${num(hi)} H${num(x + 3)} M${num(x - 3)} ${num(lo)} H${num(x + 3)}" stroke="${color}" fill="none"/>`);
    });
  }
  for (const [axis, list] of [['x', slot.guides?.x ?? []], ['y', slot.guides?.y ?? []]]) {
    for (const { value, label } of list) {
      const p = axis === 'x' ? X(value) : Y(value);
      if (p === null) continue;
      const line = axis === 'x'
        ? `<line x1="${num(p)}" x2="${num(p)}" y1="${M.top}" y2="${M.top + plotH}"/><text x="${num(p + 4)}" y="${M.top + 14}" stroke="none">${escapeXml(label)}</text>`
        : `<line x1="${M.left}" x2="${M.left + plotW}" y1="${num(p)}" y2="${num(p)}"/><text x="${M.left + 6}" y="${num(p - 5)}" stroke="none">${escapeXml(label)}</text>`;
      out.push(`<g class="guide" data-axis="${axis}" data-value="${value}" stroke="#333" stroke-width="1.5" stroke-dasharray="6 4" fill="#333">${line}</g>`);
    }
  }
  out.push('</g>');
  // The legend.
  const colW = (W - M.left) / LEGEND_COLS;
  out.push('<g class="legend">');
  series.forEach(({ i, color, dash }, n) => {
    const x = M.left + (n % LEGEND_COLS) * colW;
    const y = PLOT_H + 12 + Math.floor(n / LEGEND_COLS) * LEGEND_ROW;
    const dashAttr = dash.length ? ` stroke-dasharray="${dash.join(' ')}"` : '';
    out.push(`<line x1="${num(x)}" x2="${num(x + 22)}" y1="${y}" y2="${y}" stroke="${color}" stroke-width="2"${dashAttr}/>`);
    out.push(`<text x="${num(x + 28)}" y="${y + 4}">${escapeXml(u.series[i].label)}</text>`);
  });
  const notesTop = PLOT_H + 12 + Math.ceil(series.length / LEGEND_COLS) * LEGEND_ROW;
  notes.forEach((note, n) => {
    const y = notesTop + n * LEGEND_ROW;
    out.push(`<circle cx="${M.left + 11}" cy="${y}" r="${MARKER_RADIUS}" fill="${note.marker === 'open' ? '#fff' : '#444'}" stroke="#444" stroke-width="1.5"/>`);
    out.push(`<text class="note" x="${M.left + 28}" y="${y + 4}">${escapeXml(note.text)}</text>`);
  });
  out.push('</g></svg>');
  return `${out.join('\n')}\n`;
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

/** The chart in `slot` as a PNG: uPlot's canvas on a white page, its title above and a legend below. */
export function chartPng(slot) {
  const u = slot.plot;
  const source = u.ctx.canvas;
  const ratio = source.width / Math.max(1, source.clientWidth || source.width);
  const series = shownSeries(u);
  const notes = slot.notes ?? [];
  const rows = Math.ceil(series.length / LEGEND_COLS) + notes.length;
  const head = 30 * ratio;
  const canvas = document.createElement('canvas');
  canvas.width = source.width;
  canvas.height = head + source.height + (rows * LEGEND_ROW + 12) * ratio;
  const ctx = canvas.getContext('2d');
  ctx.fillStyle = '#fff';
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.fillStyle = '#1d2430';
  ctx.font = `600 ${15 * ratio}px system-ui, sans-serif`;
  ctx.fillText(slot.title ?? '', 10 * ratio, 20 * ratio);
  ctx.drawImage(source, 0, head);
  ctx.font = `${12 * ratio}px system-ui, sans-serif`;
  ctx.textAlign = 'left';
  ctx.textBaseline = 'alphabetic';
  const colW = canvas.width / LEGEND_COLS;
  series.forEach(({ i, color, dash }, n) => {
    const x = 10 * ratio + (n % LEGEND_COLS) * colW;
    const y = head + source.height + (12 + Math.floor(n / LEGEND_COLS) * LEGEND_ROW) * ratio;
    ctx.strokeStyle = color;
    ctx.lineWidth = 2 * ratio;
    ctx.setLineDash(dash.map((d) => d * ratio));
    ctx.beginPath();
    ctx.moveTo(x, y);
    ctx.lineTo(x + 22 * ratio, y);
    ctx.stroke();
    ctx.fillText(u.series[i].label, x + 28 * ratio, y + 4 * ratio);
  });
  const notesTop = head + source.height + (12 + Math.ceil(series.length / LEGEND_COLS) * LEGEND_ROW) * ratio;
  ctx.setLineDash([]);
  ctx.lineWidth = 1.5 * ratio;
  notes.forEach((note, n) => {
    const y = notesTop + n * LEGEND_ROW * ratio;
    ctx.beginPath();
    ctx.arc(21 * ratio, y, MARKER_RADIUS * ratio, 0, 2 * Math.PI);
    ctx.fillStyle = note.marker === 'open' ? '#fff' : '#444';
    ctx.fill();
    ctx.strokeStyle = '#444';
    ctx.stroke();
    ctx.fillStyle = '#1d2430';
    ctx.fillText(note.text, 38 * ratio, y + 4 * ratio);
  });
  return new Promise((resolve, reject) => canvas.toBlob((blob) => (blob ? resolve(blob) : reject(new Error('no PNG'))), 'image/png'));
}

/**
 * The "SVG" and "PNG" buttons of the chart in `slot`, saved as `name`.svg / .png (`name` may be a
 * function, for names that depend on what is shown). Nothing happens while the slot has no chart.
 */
export function chartDownloads(slot, name) {
  const base = () => (typeof name === 'function' ? name() : name);
  const svg = h('button', { type: 'button', class: 'download', 'data-download': 'svg' }, 'SVG');
  const png = h('button', { type: 'button', class: 'download', 'data-download': 'png' }, 'PNG');
  svg.addEventListener('click', () => {
    if (slot.plot) saveBlob(new Blob([chartSvg(slot)], { type: 'image/svg+xml' }), `${base()}.svg`);
  });
  png.addEventListener('click', async () => {
    if (slot.plot) saveBlob(await chartPng(slot), `${base()}.png`);
  });
  return h('div', { class: 'downloads', role: 'group', 'aria-label': 'Download the chart' }, h('span', { class: 'hint' }, 'Download:'), svg, png);
}
