// Files of the browser test: a download's name and bytes, CSV text as rows, a PNG's size, the
// column lists of the CSV contract, docs/csv.md, read from the document itself so that the
// dashboard's CSVs are checked against what the contract says, not against a copy of it, and the
// README's screenshots.

import { readFile } from 'node:fs/promises';
import path from 'node:path';

import { check } from './harness.mjs';

const DOC_SCREENSHOT_LIMIT = 400_000;

export const PNG_SIGNATURE = Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]);

/** The width and height in pixels of a PNG file's bytes (its IHDR chunk). */
export const pngSize = (bytes) => ({ width: bytes.readUInt32BE(16), height: bytes.readUInt32BE(20) });

/** Clicks `button` and returns the download: its suggested name and its bytes. */
export async function downloadFrom(page, button) {
  const [download] = await Promise.all([page.waitForEvent('download'), button.click()]);
  return { name: download.suggestedFilename(), bytes: await readFile(await download.path()) };
}

/** A CSV text as rows of fields (RFC 4180: CRLF lines, quoted fields with doubled quotes). */
export function parseCsv(text) {
  const rows = [];
  let row = [];
  let field = '';
  let quoted = false;
  for (let i = 0; i < text.length; i += 1) {
    const c = text[i];
    if (quoted) {
      if (c === '"' && text[i + 1] === '"') { field += '"'; i += 1; } else if (c === '"') quoted = false; else field += c;
    } else if (c === '"') quoted = true;
    else if (c === ',') { row.push(field); field = ''; } else if (c === '\r' && text[i + 1] === '\n') {
      row.push(field); rows.push(row); row = []; field = ''; i += 1;
    } else field += c;
  }
  return rows;
}

/**
 * The tables of docs/csv.md's "Tables" section: per table name (`noise table`, `weights`,
 * `history`, `compare`…) its `where` cell and its columns, the backticked names in order, a
 * compare table's "then the noise table's columns" spelled out.
 */
export async function csvContract() {
  const text = await readFile(new URL('../../docs/csv.md', import.meta.url), 'utf8');
  const section = text.slice(text.indexOf('## Tables'));
  const names = (cell) => [...cell.matchAll(/`([a-z0-9_]+)`/g)].map((m) => m[1]);
  const tables = {};
  for (const line of section.split('\n').filter((l) => l.startsWith('| ') && !l.startsWith('| table') && !l.startsWith('|---'))) {
    const [name, where, columns] = line.slice(2, -2).split(/(?<!\\)\|/).map((c) => c.trim());
    tables[name] = { where, columns: names(columns), then: /then the noise table's columns/.test(columns) };
  }
  for (const table of Object.values(tables)) if (table.then) table.columns.push(...tables['noise table'].columns);
  return tables;
}

/**
 * Saves a screenshot for the README when OPTIMIS_SCREENSHOT_DIR is set: the page from the top of
 * `from` (or of the page) to the bottom of `until`.
 */
export async function docScreenshot(page, name, from, until) {
  const dir = process.env.OPTIMIS_SCREENSHOT_DIR;
  if (!dir) return;
  const [top, bottom] = await page.evaluate(([a, b]) => [
    a ? document.querySelector(a).getBoundingClientRect().top + window.scrollY - 12 : 0,
    document.querySelector(b).getBoundingClientRect().bottom + window.scrollY + 12,
  ], [from, until]);
  const file = path.join(dir, name);
  await page.screenshot({ path: file, fullPage: true, clip: { x: 0, y: Math.max(0, Math.floor(top)), width: page.viewportSize().width, height: Math.ceil(bottom - top) } });
  const size = (await readFile(file)).length;
  check(size < DOC_SCREENSHOT_LIMIT, `${file} is ${Math.round(size / 1000)} KB (under ${DOC_SCREENSHOT_LIMIT / 1000} KB)`);
}
