// Chart files: the SVG and PNG downloads of a chart (a PlotSlot, plots.js) or of a grid of small
// charts (the sweep page's small multiples).
//
// The SVG is chartsvg.js's vector figure. The PNG is that same SVG rasterised by the browser at
// PNG_SCALE times its size (820 px → 1,640 px for a full chart, whatever the screen's pixel ratio):
// the text and lines are drawn at that resolution, not a screen bitmap scaled up, so the PNG is
// fit for print. (The vendored uPlot 1.6.32 has no per-chart pixel ratio to redraw its canvas at.)

import { saveBlob } from './api.js';
import { chartSvg, noteSymbol, textWidth, wrap } from './chartsvg.js';
import { h } from './format.js';

/** How many PNG pixels per SVG px. */
export const PNG_SCALE = 2;

const escapeXml = (text) => String(text).replace(/[<>&"']/g, (c) => ({ '<': '&lt;', '>': '&gt;', '&': '&amp;', '"': '&quot;', "'": '&apos;' }[c]));

/** The PNG of an SVG document (a Blob), rendered at `scale` × its width and height. */
export async function svgToPng(svg, scale = PNG_SCALE) {
  const [, width, height] = /<svg[^>]* width="([\d.]+)" height="([\d.]+)"/.exec(svg).map(Number);
  const [w, hgt] = [Math.round(width * scale), Math.round(height * scale)];
  // The image's own size is the scaled one (the viewBox keeps the drawing), so the browser renders
  // the vectors at full resolution. A data: URL: the page's Content-Security-Policy allows it for images.
  const scaled = svg.replace(/(<svg[^>]*?) width="[\d.]+" height="[\d.]+"/, `$1 width="${w}" height="${hgt}"`);
  const image = new Image();
  image.src = `data:image/svg+xml;charset=utf-8,${encodeURIComponent(scaled)}`;
  await image.decode();
  const canvas = Object.assign(document.createElement('canvas'), { width: w, height: hgt });
  const ctx = canvas.getContext('2d');
  ctx.fillStyle = '#fff';
  ctx.fillRect(0, 0, w, hgt);
  ctx.drawImage(image, 0, 0, w, hgt);
  return new Promise((resolve, reject) => canvas.toBlob((blob) => (blob ? resolve(blob) : reject(new Error('no PNG'))), 'image/png'));
}

/**
 * Small multiples as one SVG: `panels` ({ slot, title }) in `columns` columns of `panelWidth` px
 * (by default at least 820 px in all, as wide as a single chart's figure), each its chart without
 * a legend under its own title, then one legend for all (`legend`: entries { label, color, dash,
 * width } and the notes { marker, text }), under the figure's `title`.
 */
export function gridSvg(panels, { title, columns, panelWidth = Math.max(300, Math.ceil(820 / columns)), plotHeight = 170, legend = [], notes = [] }) {
  const docs = panels.map((p) => chartSvg(p.slot, { width: panelWidth, plotHeight, title: null, legend: false }));
  // Each panel's title above its chart, all in one font size and one block height so that the
  // charts line up; shrunk so that its longest word (a strategy's name) fits the panel.
  const words = panels.flatMap((p) => p.title.split(' '));
  const size = Math.min(12.5, (12.5 * (panelWidth - 24)) / Math.max(1, ...words.map((w) => textWidth(w, 12.5, '600'))));
  const titles = panels.map((p) => wrap(p.title, panelWidth - 24, size, '600'));
  // Below the last line's descenders: each chart's own white page must not cover them.
  const titleHeight = Math.max(...titles.map((t) => t.length)) * size * 1.3 + 5;
  const chartHeight = Math.max(...docs.map((doc) => Number(/<svg[^>]* height="([\d.]+)"/.exec(doc)[1])));
  const rowHeight = titleHeight + chartHeight;
  const rows = Math.ceil(panels.length / columns);
  const width = columns * panelWidth;
  const head = 40;
  const keyTop = head + rows * rowHeight + 18;
  const keyRows = legend.length + notes.length;
  const height = Math.round(keyTop + keyRows * 20 + 8);
  const out = [`<svg xmlns="http://www.w3.org/2000/svg" width="${width}" height="${height}" viewBox="0 0 ${width} ${height}" font-family="system-ui, Helvetica, Arial, sans-serif" font-size="12">`,
    `<title>${escapeXml(title)}</title>`, `<rect width="${width}" height="${height}" fill="#fff"/>`,
    `<text x="12" y="26" font-size="${Math.min(16, (16 * (width - 24)) / Math.max(1, textWidth(title, 16, '600')))}" font-weight="600" fill="#1d2430">${escapeXml(title)}</text>`];
  docs.forEach((doc, k) => {
    const x = (k % columns) * panelWidth;
    const y = head + Math.floor(k / columns) * rowHeight;
    titles[k].forEach((line, n) => out.push(`<text class="panel-title" x="${x + 12}" y="${(y + size * 1.3 * (n + 1)).toFixed(1)}" font-size="${size.toFixed(2)}" font-weight="600" fill="#1d2430">${escapeXml(line)}</text>`));
    // A nested <svg> keeps each panel's coordinates; its clip path ids are made unique by chartSvg.
    out.push(doc.replace('<svg xmlns="http://www.w3.org/2000/svg"', `<svg class="panel" x="${x}" y="${(y + titleHeight).toFixed(1)}"`).replace(/<title>.*?<\/title>\n/, ''));
  });
  out.push('<g class="legend" fill="#1d2430">');
  legend.forEach(({ label, color, dash = [], width: w = 2.5 }, n) => {
    const y = keyTop + n * 20;
    out.push(`<line x1="24" x2="46" y1="${y}" y2="${y}" stroke="${color}" stroke-width="${w}"${dash.length ? ` stroke-dasharray="${dash.join(' ')}"` : ''}/>`,
      `<text x="52" y="${y + 4}">${escapeXml(label)}</text>`);
  });
  notes.forEach(({ marker, text }, n) => {
    const y = keyTop + (legend.length + n) * 20;
    out.push(noteSymbol(marker, 35, y), `<text class="note" x="52" y="${y + 4}">${escapeXml(text)}</text>`);
  });
  out.push('</g></svg>');
  return `${out.join('\n')}\n`;
}

/**
 * The "SVG" and "PNG" buttons of a figure, saved as `name`.svg / .png (`name` may be a function,
 * for names that depend on what is shown): `source` is a PlotSlot (its chart) or a function that
 * returns the SVG document, null while there is nothing to save.
 */
export function chartDownloads(source, name) {
  const base = () => (typeof name === 'function' ? name() : name);
  const svgOf = typeof source === 'function' ? source : () => (source.plot ? chartSvg(source) : null);
  const svg = h('button', { type: 'button', class: 'download', 'data-download': 'svg' }, 'SVG');
  const png = h('button', { type: 'button', class: 'download', 'data-download': 'png' }, 'PNG');
  svg.addEventListener('click', () => {
    const doc = svgOf();
    if (doc) saveBlob(new Blob([doc], { type: 'image/svg+xml' }), `${base()}.svg`);
  });
  png.addEventListener('click', async () => {
    const doc = svgOf();
    if (doc) saveBlob(await svgToPng(doc), `${base()}.png`);
  });
  return h('div', { class: 'downloads', role: 'group', 'aria-label': 'Download the chart' }, h('span', { class: 'hint' }, 'Download:'), svg, png);
}
