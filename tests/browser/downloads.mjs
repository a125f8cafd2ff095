// The download steps of the browser test, on the paper job's page: the noise table, Fig. 2's
// weights and the history as CSV — their headers exactly docs/csv.md's columns, their numbers the
// API's in full —, Fig. 2 as SVG (a vector figure of what the chart draws), a chart as a PNG fit for
// print (at least 1,600 px wide), and the moments.

import { callApi, check } from './harness.mjs';
import { PNG_SIGNATURE, csvContract, downloadFrom, parseCsv, pngSize } from './files.mjs';

/** PNG charts are at least this wide: twice the 820 px figure, for print. */
export const PNG_MIN_WIDTH = 1600;

/** A CSV number cell as the API's value: empty is null. */
const cell = (text) => (text === '' ? null : Number(text));

export async function checkDownloads(page, id, { result, figure }) {
  const contract = await csvContract();
  const quoting = await page.evaluate(async () => (await import('/assets/csv.js')).toCsv(['a', 'b'], [{ a: 'x,"y"', b: 'line\nbreak' }, { a: 1.5, b: null }]));
  check(quoting === 'a,b\r\n"x,""y""","line\nbreak"\r\n1.5,\r\n', 'the CSV writer quotes as RFC 4180 says');

  const csv = await downloadFrom(page, page.getByRole('button', { name: 'Noise table (CSV)' }));
  const [header, ...rows] = parseCsv(csv.bytes.toString('utf8'));
  const col = (name) => header.indexOf(name);
  check(csv.name === `optimis-job-${id}-noise.csv` && header.join() === contract['noise table'].columns.join() && rows.length === result.noise_table.length,
    `"Noise table (CSV)" saves ${csv.name}: ${rows.length} rows under docs/csv.md's ${header.length} noise-table columns, in its order`);
  const api = result.noise_table;
  check(rows.every((r, i) => cell(r[col('luminance')]) === api[i].luminance && cell(r[col('luminance_stderr')]) === api[i].luminance_stderr
    && cell(r[col('rms_percent')]) === api[i].rms_percent && r[col('strategy')] === api[i].strategy
    && cell(r[col('reference_luminance')]) === result.reference_luminance),
  'its luminance, its SE (model units), RMS (percent) and reference are the API\'s numbers, in full');
  check(rows.every((r, i) => cell(r[col('z')]) === api[i].z && cell(r[col('expected_luminance')]) === (api[i].expected_luminance ?? null)
    && (r[col('recommended')] === 'true') === (api[i].strategy === result.recommended.strategy)),
  'its z is the API\'s z against the expected luminance at R, and it marks the recommended row');
  const inSample = ['in_sample_luminance', 'in_sample_luminance_stderr', 'in_sample_rms_percent'];
  const withInSample = rows.filter((r) => r[col('in_sample_rms_percent')] !== '');
  check(rows.every((r, i) => inSample.every((c) => cell(r[col(c)]) === (api[i][c] ?? null))) && withInSample.length > 0,
    `it carries the cross-fitted rows' in-sample figures beside the honest ones (${withInSample.map((r) => r[0]).join(', ')})`);
  const stacked = rows.find((r) => r[col('strategy')] === 'optimal_stacked');
  check(JSON.stringify(JSON.parse(stacked[col('heuristics')] || '[]')) === JSON.stringify(api.find((r) => r.strategy === 'optimal_stacked').heuristics),
    'it carries the stacked row\'s β as JSON');
  const plane1 = rows.find((r) => r[col('strategy')] === 'plane1');
  check(plane1[col('paper_case')] === '1' && Number(plane1[col('paper_luminance')]) === 26.484e-5 && plane1[col('paper_rms_percent')] === '208',
    'it carries the paper\'s case and values');

  const weights = await downloadFrom(page, page.getByRole('button', { name: 'Weights (CSV)' }));
  const [weightsHeader, ...weightRows] = parseCsv(weights.bytes.toString('utf8'));
  // docs/csv.md: the dashboard's weights table has "`table`, `strategy`, `lambda` in front".
  const front = [.../with (.*) in front/.exec(contract.weights.where)[1].matchAll(/`([a-z_]+)`/g)].map((m) => m[1]);
  check(weightsHeader.join() === [...front, ...contract.weights.columns].join(),
    `"Weights (CSV)" has docs/csv.md's weights columns with ${front.join(', ')} in front (${weightsHeader.length})`);
  const w = (r, name) => r[weightsHeader.indexOf(name)];
  const table = new Set(weightRows.map((r) => w(r, 'table')));
  const expectedTable = figure.fig.kind === 'table-optimum' ? 'table_optimum_not_recommended' : 'recommended';
  check(weightRows.length === figure.fig.weights.length && table.size === 1 && table.has(expectedTable),
    `it saves the ${weightRows.length} cells Fig. 2 draws from, as "${expectedTable}"`);
  check(weightRows.every((r, k) => Number(w(r, 'cell')) === k && cell(w(r, 'phi_hi_rad')) === figure.fig.weights[k].phi[1]
    && cell(w(r, 'r3_hi')) === figure.fig.weights[k].r3[1] && cell(w(r, 'w1_stderr')) === (figure.fig.weights[k].w1_stderr ?? null)),
  'each row is its cell (index in the document\'s order), φ in radians, an open edge empty, w₁\'s SE as the API gives it');

  const history = (await callApi(`/v1/jobs/${id}/history`)).json;
  const historyCsv = await downloadFrom(page, page.getByRole('button', { name: 'History (CSV)' }));
  const historyRows = parseCsv(historyCsv.bytes.toString('utf8'));
  check(historyRows[0].join() === contract.history.columns.join()
    && historyRows.length === 1 + history.points.reduce((n, p) => n + p.strategies.length, 0),
  `"History (CSV)" has docs/csv.md's history columns (${historyRows[0].join(', ')}), one row per checkpoint and strategy (${historyRows.length - 1})`);

  const svg = await downloadFrom(page, page.locator('[data-ref="weights-downloads"] button[data-download="svg"]'));
  const text = svg.bytes.toString('utf8');
  const count = (needle) => text.split(needle).length - 1;
  check(svg.name === `optimis-job-${id}-fig2-w1.svg` && text.startsWith('<svg xmlns="http://www.w3.org/2000/svg"'),
    `Fig. 2's "SVG" saves ${svg.name}, an SVG document`);
  const { marks, fig } = figure;
  check(count('class="series"') === 2 && count('class="error-bar"') === marks.bars && count('class="guide" data-axis="x" data-value="0.02"') === 1
    && count('class="marker-open"') === marks.open && count('class="marker"') === marks.filled
    && text.includes(`${fig.prefix}, r₂ ∈ [0.5, ∞)`) && text.includes('<title>Job') && count('class="axis-label"') === 2,
  `the SVG draws the 2 series as paths, ${marks.filled} filled and ${marks.open} open markers, ${marks.bars} error bars, the r₃ = a marker, both axis labels and a legend`);
  check((fig.kind !== 'table-optimum' || /<title>[^<]*not recommended[^<]*<\/title>/.test(text)) && (marks.open === 0 || text.includes('open: no data SE')),
    'its title says when it is the table optimum, not the recommendation, and its legend explains the open markers');
  const wellFormed = await page.evaluate((doc) => {
    const parsed = new DOMParser().parseFromString(doc, 'image/svg+xml');
    return parsed.documentElement.nodeName === 'svg' && parsed.getElementsByTagName('parsererror').length === 0;
  }, text);
  check(wellFormed, 'the SVG is well-formed XML');

  const png = await downloadFrom(page, page.locator('[data-ref="luminance-downloads"] button[data-download="png"]'));
  const size = pngSize(png.bytes);
  check(png.name === `optimis-job-${id}-luminance.png` && png.bytes.subarray(0, 8).equals(PNG_SIGNATURE) && png.bytes.length > 20_000,
    `the luminance chart's "PNG" saves ${png.name} (${Math.round(png.bytes.length / 1000)} KB)`);
  check(size.width >= PNG_MIN_WIDTH, `the PNG is ${size.width} × ${size.height} px: print resolution (≥ ${PNG_MIN_WIDTH} px wide), whatever the screen's pixel ratio (${await page.evaluate(() => devicePixelRatio)})`);

  const moments = await downloadFrom(page, page.getByRole('button', { name: 'Download moments' }));
  const doc = JSON.parse(moments.bytes.toString('utf8'));
  check(moments.name === `optimis-job-${id}-moments.json` && typeof doc === 'object' && doc !== null,
    `"Download moments" saves ${moments.name} (named by the server's Content-Disposition)`);
}
