// CSV: tables built in the page from the API's JSON, as RFC 4180 text (CRLF line ends, fields with
// a comma, quote or line break quoted, quotes doubled), and the "Download CSV" buttons that save
// them. Column names carry their units: luminance in model units (not × 10⁵), rms_percent in percent.

import { saveBlob } from './api.js';
import { h } from './format.js';

/** One field: numbers as JavaScript writes them (full precision), null/undefined empty. */
function field(value) {
  if (value === null || value === undefined || (typeof value === 'number' && !Number.isFinite(value))) return '';
  const text = String(value);
  return /[",\r\n]/.test(text) ? `"${text.replace(/"/g, '""')}"` : text;
}

/** The CSV text of `rows` (objects) under the header `columns` (their keys, in order). */
export function toCsv(columns, rows) {
  const lines = [columns, ...rows.map((row) => columns.map((c) => row[c]))];
  return `${lines.map((line) => line.map(field).join(',')).join('\r\n')}\r\n`;
}

/**
 * A "CSV" button that saves the table `make()` returns ({ columns, rows }) as `filename`; made
 * when clicked, so that it is always the table shown.
 */
export function csvButton(label, filename, make) {
  const button = h('button', { type: 'button', class: 'download', 'data-download': 'csv' }, label);
  button.addEventListener('click', () => {
    const { columns, rows } = make();
    saveBlob(new Blob([toCsv(columns, rows)], { type: 'text/csv;charset=utf-8' }), typeof filename === 'function' ? filename() : filename);
  });
  return button;
}
