// The download steps of the browser test, on the paper job's page: the noise table, the weights
// (the recommended table where there is one, the effective weights Fig. 2 draws for any kind of
// recommendation) and the history as CSV — their headers exactly docs/csv.md's columns, their
// numbers the API's in full —, Fig. 2's two panels as
// SVG (vector figures of what the charts draw), a chart as a PNG fit for print (at least 1,600 px
// wide), and the moments.

import { callApi, check, r2Words } from './harness.mjs';
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

  // The recommended table, offered only when there is one (a per-path heuristic has none).
  const weightsButton = page.getByRole('button', { name: 'Weights (CSV)', exact: true });
  check((await weightsButton.isVisible()) === (result.weights.length > 0),
    result.weights.length ? '"Weights (CSV)" is offered: the recommendation has a table' : `"Weights (CSV)" is not offered: ${result.recommended.strategy} has no table`);
  if (result.weights.length > 0) {
    const weights = await downloadFrom(page, weightsButton);
    const [weightsHeader, ...weightRows] = parseCsv(weights.bytes.toString('utf8'));
    // docs/csv.md's weights columns, `table`, `strategy`, `lambda` first, as the server writes them.
    check(weightsHeader.join() === contract.weights.columns.join() && weightRows.length === result.weights.length,
      `"Weights (CSV)" has docs/csv.md's weights columns, a row per cell (${weightRows.length})`);
  }
  // The effective weights Fig. 2 draws, for any kind of recommendation.
  const { eff } = figure;
  const effective = await downloadFrom(page, page.getByRole('button', { name: 'Effective weights (CSV)' }));
  const [effHeader, ...effRows] = parseCsv(effective.bytes.toString('utf8'));
  const e = (r, name) => r[effHeader.indexOf(name)];
  check(effective.name === `optimis-job-${id}-effective-weights.csv` && effHeader.join() === contract.effective.columns.join() && effRows.length === eff.bins.length,
    `"Effective weights (CSV)" saves ${effective.name}: ${effRows.length} bins under docs/csv.md's effective columns`);
  check(effRows.every((r, k) => e(r, 'strategy') === eff.strategy && e(r, 'kind') === eff.kind && Number(e(r, 'paths_per_side')) === eff.paths_per_side
    && cell(e(r, 'r3_hi')) === eff.bins[k].r3[1] && cell(e(r, 'r2_lo')) === eff.bins[k].r2[0] && Number(e(r, 'paths')) === eff.bins[k].paths
    && cell(e(r, 'w1')) === (eff.bins[k].w?.[1] ?? null) && cell(e(r, 'w1_stderr')) === (eff.bins[k].stderr?.[1] ?? null)
    && cell(e(r, 'w2')) === (eff.bins[k].w?.[2] ?? null) && cell(e(r, 'luminance_share')) === eff.bins[k].luminance_share),
  `each row is its bin: the API's w and SE in full, empty where no path carries light (${effRows.filter((r) => e(r, 'w1') === '').length} bins), an open edge empty`);

  const history = (await callApi(`/v1/jobs/${id}/history`)).json;
  const historyCsv = await downloadFrom(page, page.getByRole('button', { name: 'History (CSV)' }));
  const historyRows = parseCsv(historyCsv.bytes.toString('utf8'));
  check(historyRows[0].join() === contract.history.columns.join()
    && historyRows.length === 1 + history.points.reduce((n, p) => n + p.strategies.length, 0),
  `"History (CSV)" has docs/csv.md's history columns (${historyRows[0].join(', ')}), one row per checkpoint and strategy (${historyRows.length - 1})`);

  const svg = await downloadFrom(page, page.locator('[data-ref="weights-downloads"] button[data-download="svg"]'));
  const text = svg.bytes.toString('utf8');
  const count = (doc, needle) => doc.split(needle).length - 1;
  check(svg.name === `optimis-job-${id}-fig2-w1.svg` && text.startsWith('<svg xmlns="http://www.w3.org/2000/svg"'),
    `Fig. 2's effective panel "SVG" saves ${svg.name}, an SVG document`);
  const { marks, zero } = figure;
  const lines = 2 * marks.lit.length;
  check(count(text, 'class="series"') === lines && count(text, 'class="marker"') === marks.drawn && count(text, 'class="marker-open"') === marks.drawn
    && count(text, 'class="error-bar"') === marks.bars && count(text, 'class="guide" data-axis="x" data-value="0.02"') === 1
    && marks.lit.every((r2) => text.includes(`w₁, ${r2Words(r2)}`) && text.includes(`w₂, ${r2Words(r2)}`)) && count(text, 'class="axis-label"') === 2,
  `the SVG draws the ${lines} series as paths, ${marks.drawn} filled w₁ and ${marks.drawn} hollow w₂ markers, ${marks.bars} error bars, the r₃ = a marker, both axis labels and a legend`);
  check(/<title>Job [^<]*effective weights of the recommended [^<]*<\/title>/.test(text)
    && marks.dark.every((r2) => text.includes(`${r2Words(r2)}: no light path reaches it`)),
  `its title says these are the recommended row's effective weights${marks.dark.length ? ', its legend notes the r₂ bins without light' : ''}`);
  const zeroSvg = await downloadFrom(page, page.locator('[data-ref="lambda0-downloads"] button[data-download="svg"]'));
  const zeroText = zeroSvg.bytes.toString('utf8');
  check(zeroSvg.name === `optimis-job-${id}-fig2-lambda0.svg` && /<title>[^<]*λ = 0[^<]*not recommended[^<]*<\/title>/.test(zeroText)
    && count(zeroText, 'class="marker"') + count(zeroText, 'class="marker-open"') === zero.markers
    && count(zeroText, 'class="off-scale-mark"') === zero.off.length && zeroText.includes('in-sample fit: not an honest estimate, not recommended'),
  `the λ = 0 panel's "SVG" saves ${zeroSvg.name}: ${zero.markers} markers, ${zero.off.length} edge marks, labelled not recommended`);
  const wellFormed = await page.evaluate((docs) => docs.every((doc) => {
    const parsed = new DOMParser().parseFromString(doc, 'image/svg+xml');
    return parsed.documentElement.nodeName === 'svg' && parsed.getElementsByTagName('parsererror').length === 0;
  }), [text, zeroText]);
  check(wellFormed, 'both SVGs are well-formed XML');

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
