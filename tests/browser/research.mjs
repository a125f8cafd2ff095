// The research steps of the browser test: a job in the paper's configuration and one under uniform
// light, submitted through the API (2000 iterations of the restricted engine: about a second each);
// the spot job's page — Table 1 with the paper's column, case numbers and z against each row's
// expectation at R, Fig. 2 (checkFigure2: its two panels — the recommended row's effective weights,
// w₁ and w₂ with ± 1 SE bars per r₂ bin with light, whatever the kind of recommendation, and the
// in-sample λ = 0 table with its off-scale cells marked at the frame's edge and its copied cells
// left out —, the r₃ = a marker), the luminance chart with SE bands and the reference line —, their
// axes and legends (checkAxes), a kept solve, and the compare page of the two jobs, reached from
// the list's checkboxes, with its CSVs. (The job's downloads: downloads.mjs.)
//
// With OPTIMIS_SCREENSHOT_DIR set, also writes the README's dashboard-job.png and dashboard-compare.png there.

import { PNG_MIN_WIDTH } from './downloads.mjs';
import { csvContract, docScreenshot, downloadFrom, parseCsv, pngSize } from './files.mjs';
import {
  STRATEGIES, callApi, check, checkAxes, edgeText, effectiveMarks, expectedFigure, figureMarks, lambdaZeroMarks, parseWithError,
  r2Words, readPlot, screenshot, sleep, waitFor,
} from './harness.mjs';
import { checkZ, readNoiseRows } from './jobs.mjs';

const SPOT_JOB = { preset: 'paper-table1', iterations: 2000 };
const UNIFORM_JOB = { preset: 'uniform-illumination', iterations: 2000 };
// The paper's Table 1 (Ershov et al. 2020): case, L·10⁵ and RMS % as the page prints them.
const PAPER = {
  plane1: ['1', '26.484', '208'], plane2: ['2', '26.352', '254'], plane3: ['3', '25.997', '146'],
  switch: ['4', '26.352', '61'], optimal: ['5', '25.961', '54'],
};
// Jobs whose recommendation is fitted (the paper's scene at a larger merge radius, 10⁴ iterations:
// a few seconds each): at R = 0.01 a heuristic corrected by a table (a stack: Fig. 2 draws it whole,
// the caption its β), at R = 0.02 a table. Seeded, so the recommendations are reproducible; a
// solver change that turns them both per-path fails checkTableJobs.
const TABLE_JOBS = [
  { preset: 'paper-table1', iterations: 10000, merge_radius: 0.01 },
  { preset: 'paper-table1', iterations: 10000, merge_radius: 0.02 },
];

/** Submits the spot and the uniform job through the API and waits until both have succeeded. */
export async function submitPaperPair() {
  const ids = [];
  for (const body of [SPOT_JOB, UNIFORM_JOB]) {
    const response = await callApi('/v1/jobs', { method: 'POST', body });
    if (response.status !== 202) throw new Error(`submitting ${JSON.stringify(body)} answered ${response.status}`);
    ids.push(response.json.id);
  }
  await waitFor('the spot and the uniform job to succeed', async () => {
    const states = await Promise.all(ids.map(async (id) => (await callApi(`/v1/jobs/${id}`)).json.state));
    if (states.some((s) => s === 'failed' || s === 'cancelled')) throw new Error(`a paper job ended ${states}`);
    return states.every((s) => s === 'succeeded');
  }, 120_000);
  check(true, `a paper-table1 job (#${ids[0]}) and a uniform-illumination job (#${ids[1]}) of 2000 iterations succeed`);
  return { spot: ids[0], uniform: ids[1] };
}

/** Queues TABLE_JOBS through the API (they run while the paper pair is checked); their ids. */
export async function submitTableJobs() {
  const ids = [];
  for (const body of TABLE_JOBS) {
    const response = await callApi('/v1/jobs', { method: 'POST', body });
    if (response.status !== 202) throw new Error(`submitting ${JSON.stringify(body)} answered ${response.status}`);
    ids.push(response.json.id);
  }
  return ids;
}

/**
 * The pages of TABLE_JOBS: each recommends a fitted row, marked in the noise table; Fig. 2's
 * effective panel draws it whole (a stack's caption gives β), and "Weights (CSV)" offers its table.
 */
export async function checkTableJobs(page, ids) {
  await waitFor('the table jobs to succeed', async () => {
    const states = await Promise.all(ids.map(async (id) => (await callApi(`/v1/jobs/${id}`)).json.state));
    if (states.some((s) => s === 'failed' || s === 'cancelled')) throw new Error(`a table job ended ${states}`);
    return states.every((s) => s === 'succeeded');
  }, 120_000);
  const kinds = [];
  const offScale = [];
  for (const id of ids) {
    await page.goto(`${page.url().split('#')[0]}#/jobs/${id}`);
    await waitFor(`job ${id}'s final results`, async () =>
      (await page.locator('[data-ref="result-status"]').textContent()).startsWith('final')
      && (await page.locator('[data-ref="weights-plot"] canvas').count()) > 0);
    const result = (await callApi(`/v1/jobs/${id}/result`)).json;
    const { recommended } = result;
    const rows = await readNoiseRows(page);
    check(rows.filter((r) => r.recommendedRow).map((r) => r.strategy).join() === recommended.strategy,
      `job ${id} (R = ${TABLE_JOBS[ids.indexOf(id)].merge_radius}) marks its recommended row, ${recommended.strategy}, in the noise table`);
    const { eff, zero } = await checkFigure2(page, id, result);
    kinds.push(eff.kind);
    offScale.push(zero.off.length);
    if (eff.kind === 'stack') {
      const note = await page.locator('[data-ref="weights-note"]').textContent();
      const row = rows.find((r) => r.strategy === recommended.strategy);
      check(note.includes('Drawn whole') && recommended.heuristics.every((b) => note.includes(`${b.strategy} `)) && row.betas.startsWith('β: '),
        `a table with ${recommended.heuristics.map((b) => b.strategy).join(', ')} stacked on it: Fig. 2 draws it whole, its caption and row give β`);
    }
    const weights = page.getByRole('button', { name: 'Weights (CSV)', exact: true });
    check((await weights.isVisible()) === (result.weights.length > 0),
      `"Weights (CSV)" is offered exactly when there is a recommended table (${result.weights.length} cells)`);
  }
  check(kinds.some((k) => k !== 'heuristic'), `a fitted recommendation's effective weights were drawn (${kinds.join(', ')})`);
  // Seeded: at 10⁴ iterations some cells' in-sample λ = 0 fits are noise far outside [0, 1].
  check(offScale.some((n) => n > 0), `a λ = 0 panel had cells beyond its frame to mark at the edge (${offScale.join(', ')} per job)`);
}

/**
 * Fig. 2 of job `id` (its page open), both panels. (a) the recommended row's effective weights (as
 * GET …/effective serves them): a w₁ and a w₂ series per r₂ bin with light, a filled w₁ and a hollow
 * w₂ marker per bin with weights, its bars, a caption naming the row, its kind and paths_per_side,
 * and a note for each r₂ bin without light instead of an empty series. (b) the λ = 0 table (GET
 * …/result?lambda=0): a series per r₂ bin with data, a marker per cell fitted to data within the
 * frame, none for a copied cell, an edge mark with its value per cell beyond the frame, labelled
 * not recommended. Both mark r₃ = a. Returns the documents and their marks.
 */
export async function checkFigure2(page, id, result) {
  const eff = (await callApi(`/v1/jobs/${id}/effective`)).json;
  check(eff.strategy === result.recommended.strategy && ['heuristic', 'table', 'stack'].includes(eff.kind),
    `GET /v1/jobs/${id}/effective averages the recommended ${eff.strategy} (${eff.kind})`);
  const marks = effectiveMarks(eff);
  const slot = page.locator('[data-ref="weights-plot"]');
  const plot = await waitFor('Fig. 2\'s effective panel with its markers', async () => {
    const p = await readPlot(slot);
    return p?.markers !== null && p?.markers + p?.offScale === 2 * marks.drawn && p;
  }, 15_000);
  const labels = marks.lit.flatMap((r2) => [`w₁, ${r2Words(r2)}`, `w₂, ${r2Words(r2)}`]);
  check(JSON.stringify(plot.labels) === JSON.stringify(labels),
    `the effective panel has a w₁ and a w₂ series per r₂ bin with light (${plot.labels.join(' | ')})`);
  check(plot.markers > 0 && plot.markers - plot.openMarkers > 0 && plot.inked > 1000,
    `they have points: ${plot.markers - plot.openMarkers} filled w₁ and ${plot.openMarkers} hollow w₂ markers, one per bin with weights (${marks.drawn})`);
  check(plot.offScale > 0 || plot.errorBars === marks.bars, `with ${plot.errorBars} error bars of ± 1 SE`);
  const kind = await page.locator('[data-ref="weights-kind"]').textContent();
  const kindAttr = await page.locator('[data-ref="weights-kind"]').getAttribute('data-kind');
  const note = await page.locator('[data-ref="weights-note"]').textContent();
  check(kind.startsWith(`recommended: ${eff.strategy} (`) && kindAttr === eff.kind && note.startsWith(`Recommended: ${eff.strategy}`),
    `Fig. 2 is labelled "${kind}"`);
  check(note.includes('effective weights') && note.includes(`paths_per_side = ${eff.paths_per_side.toLocaleString('en-US')}`) && note.includes('± 1 standard error'),
    'its caption says these are effective weights, with their SE, over paths_per_side paths');
  check(marks.dark.every((r2) => note.includes(`${r2Words(r2)}: no light path reaches it`)),
    marks.dark.length ? `its caption notes the r₂ bins without light instead of drawing them (${marks.dark.map(r2Words).join(', ')})`
      : 'every r₂ bin has light');
  check(plot.guides === 'x=0.02', `the effective panel marks r₃ = a = 0.02 (${plot.guides})`);

  const lz = (await callApi(`/v1/jobs/${id}/result?lambda=0`)).json;
  const zero = lambdaZeroMarks(lz.weights);
  const lzSlot = page.locator('[data-ref="lambda0-plot"]');
  const lzPlot = await waitFor('Fig. 2\'s λ = 0 panel', async () => {
    const p = await readPlot(lzSlot);
    return p?.markers === zero.markers && p;
  }, 15_000);
  const lzNote = await page.locator('[data-ref="lambda0-note"]').textContent();
  check(JSON.stringify(lzPlot.labels) === JSON.stringify(zero.lit.map((r2) => `w₁ (λ = 0), ${r2Words(r2)}`))
    && lzNote.includes('in-sample fit: not an honest estimate, not recommended'),
  `the λ = 0 panel has a series per r₂ bin with data and says it is an in-sample fit, not recommended (${lzPlot.labels.join(' | ')})`);
  check(lzPlot.openMarkers === zero.open && lzPlot.errorBars === zero.bars,
    `it draws ${lzPlot.markers} markers (${lzPlot.openMarkers} open) and ${lzPlot.errorBars} error bars, none for the ${zero.copied} copied cells`);
  check(zero.dark.every((r2) => lzNote.includes(`${r2Words(r2)}: every cell is a copy of a neighbour`)),
    zero.dark.length ? `its caption says ${zero.dark.map(r2Words).join(', ')} has only copied cells` : 'every r₂ bin has data');
  const biggest = zero.off.reduce((a, w) => (a && Math.abs(a.w1) >= Math.abs(w.w1) ? a : w), null);
  check(lzPlot.offScale === zero.off.length && (!biggest || (lzPlot.offScaleText.includes(edgeText(biggest.w1, biggest.w1_stderr))
    && lzNote.includes('beyond the axis'))),
  zero.off.length ? `it marks the ${zero.off.length} cells beyond [−0.5, 1.5] at the frame's edge with their value (${lzPlot.offScaleText})`
    : 'no cell lies beyond [−0.5, 1.5] here, so there is no edge mark');
  check(lzPlot.guides === 'x=0.02', `the λ = 0 panel marks r₃ = a too (${lzPlot.guides})`);
  return { eff, marks, lz, zero };
}
/** The spot job's page: Table 1 with the paper's column, Fig. 2 and the luminance chart. */
export async function checkPaperJob(page, id) {
  await page.goto(`${page.url().split('#')[0]}#/jobs/${id}`);
  await waitFor('the paper job\'s final results', async () =>
    (await page.locator('[data-ref="result-status"]').textContent()).startsWith('final')
    && (await page.locator('[data-ref="weights-plot"] canvas').count()) > 0);
  const result = (await callApi(`/v1/jobs/${id}/result`)).json;
  check(await page.locator('table.noise-table thead th.paper-col:visible').count() === 4,
    'the paper configuration shows the columns "Paper L·10⁵" and "Paper RMS %", each with its z');
  const rows = await page.locator('table.noise-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy,
    cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
    optimistic: tr.querySelector('td[data-col="z"]')?.classList.contains('optimistic') ?? false,
  })));
  for (const row of rows) {
    const [kase, luminance, rms] = PAPER[row.strategy] ?? ['', '', ''];
    check(row.cells.case === kase && row.cells['paper-luminance'] === luminance && row.cells['paper-rms'] === rms,
      `${row.strategy}: paper case "${row.cells.case}", L·10⁵ "${row.cells['paper-luminance']}", RMS "${row.cells['paper-rms']}"`);
    // z against the paper's figure: (ours − paper)/SE(ours), from the API's row.
    const api = result.noise_table.find((r) => r.strategy === row.strategy);
    const expected = luminance && api.luminance_stderr > 0 ? (api.luminance - Number(luminance) * 1e-5) / api.luminance_stderr : null;
    const shown = row.cells['paper-luminance-z'] === '' ? null : Number(row.cells['paper-luminance-z'].replace('−', '-'));
    check(expected === null ? shown === null : Math.abs(shown - expected) < 0.006,
      `${row.strategy}: z against the paper's L "${row.cells['paper-luminance-z']}"${expected === null ? '' : ` (${expected.toFixed(3)})`}`);
  }
  checkZ(await readNoiseRows(page), result);
  const fit = await page.locator('table.noise-table').evaluate((table) => {
    const wrap = table.closest('.table-wrap') ?? table.parentElement;
    return { scroll: wrap.scrollWidth, client: wrap.clientWidth };
  });
  check(fit.scroll <= fit.client, `at 1366 px the noise table with the paper's four columns fits its card (${fit.scroll} of ${fit.client} px)`);
  const note = await page.locator('[data-ref="paper-note"]').textContent();
  check(note.includes('Ershov') && note.includes('Table 1') && note.includes(result.references[0].source),
    `the paper's column cites its source, as the server serves it ("${note.slice(0, 50)}…")`);
  const figure = await checkFigure2(page, id, result);

  const lum = await readPlot(page.locator('[data-ref="luminance-plot"]'));
  check(lum.inked > 1000 && STRATEGIES.every((s) => lum.labels.some((l) => l.startsWith(s))),
    `the luminance chart has a series per strategy (${lum.inked} pixels)`);
  const shown = new Set(['plane1', 'plane2', 'plane3', 'switch', 'optimal_cv', result.recommended.strategy]).size;
  check(lum.bands === shown, `it shades ± 1 SE bands under the ${lum.bands} series shown at first (cases 1–4, optimal_cv, the recommended row)`);
  check(lum.guides === `y=${result.reference_luminance * 1e5}`, `it draws the quadrature reference as a horizontal line (${lum.guides})`);
  for (const [ref, what] of [['weights-plot', 'Fig. 2 (effective)'], ['lambda0-plot', 'Fig. 2 (λ = 0)'], ['luminance-plot', 'the luminance chart'],
    ['history-plot', 'the RMS history']]) {
    await checkAxes(page, page.locator(`[data-ref="${ref}"]`), what);
  }
  await screenshot(page, 'paper-job.png');
  // The noise table with its captions (with Fig. 2 beside it the picture would exceed the limit).
  await docScreenshot(page, 'dashboard-job.png', '[aria-labelledby="noise-heading"]', '[data-ref="honesty"]');
  return { result, figure };
}

/** Ticks the two jobs in the list, compares them, and checks the compare page. */
export async function checkCompare(page, { spot, uniform }, results) {
  await page.locator('.topnav').getByRole('link', { name: 'Jobs' }).click();
  const row = page.locator(`tr[data-job="${spot}"]`);
  await waitFor(`job ${spot} in the list`, async () => (await row.count()) > 0);
  const cells = await row.locator('td[data-col]').evaluateAll((tds) => Object.fromEntries(tds.map((td) => [td.dataset.col, td.textContent])));
  check(cells.engine === 'restricted' && cells.light_paths === '10⁷' && cells.camera_paths === '100' && cells.seed === '1',
    `the list shows job ${spot}'s engine, N_F, N_B and seed (${Object.values(cells).join(', ')})`);
  const compare = page.locator('button[data-ref="compare"]');
  check(await compare.isDisabled(), 'Compare is disabled until two jobs are ticked');
  for (const id of [uniform, spot]) await page.locator(`tr[data-job="${id}"] input[name="compare"]`).check();
  check(await compare.isEnabled() && (await compare.textContent()) === 'Compare (2)', 'ticking two jobs enables "Compare (2)"');
  check(new URL(page.url()).hash === '#/', 'ticking a box does not open the job');
  await compare.click();
  await waitFor('the compare page', () => page.locator('h1', { hasText: 'Compare jobs' }).isVisible());
  check(new URL(page.url()).hash === `#/compare?ids=${spot},${uniform}`, `it opens ${new URL(page.url()).hash}`);
  await waitFor('the compare chart', async () => (await readPlot(page.locator('[data-ref="w1-plot"]')))?.inked > 1000);

  const params = await page.locator('.compare-table tbody.params tr').evaluateAll((trs) => Object.fromEntries(
    trs.map((tr) => [tr.dataset.param, [...tr.querySelectorAll('td')].map((td) => td.textContent)])));
  check(params.preset.join() === 'paper-table1,uniform-illumination' && params.illumination.join() === 'spot a = 0.02,uniform'
    && params.light_paths.join('|') === '10⁷|10⁷' && params.camera_paths.join() === '100,100'
    && params.merge_radius.join() === '0.003,0.003' && params.iterations_done.join('|') === '2,000|2,000' && params.seed.join() === '1,1',
  `the compare table heads each job's column with its parameters (${params.illumination.join(' | ')})`);
  const table = await page.locator('.compare-table tbody:not(.params) tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy, cells: [...tr.querySelectorAll('td')].map((td) => td.textContent),
  })));
  check(table.map((r) => r.strategy).join() === STRATEGIES.join(), `it has a row per strategy (${table.length})`);
  const marked = await page.locator('.compare-table td.recommended-cell').evaluateAll((tds) => Object.fromEntries(
    tds.map((td) => [td.dataset.job, td.closest('tr').dataset.strategy])));
  check(Object.keys(marked).length === 2 && [spot, uniform].every((id, k) => marked[id] === results[k].recommended.strategy),
    `each job's recommended row is marked (${Object.entries(marked).map(([id, s]) => `#${id} ${s}`).join(', ')})`);
  const agree = table.every(({ strategy, cells: [a, b] }) => [a, b].every((text, k) => {
    const row = results[k].noise_table.find((r) => r.strategy === strategy);
    return row.error ? text === 'no fit' : Math.abs(parseWithError(text)[0] - row.rms_percent) < 0.06;
  }));
  check(agree, 'each cell is its job\'s RMS %, or "no fit" where its fit failed');

  // Against the first job: the server's comparison (GET /v1/compare), ratios with their SEs.
  const comparison = (await callApi(`/v1/compare?ids=${spot},${uniform}`)).json;
  await waitFor('the ratios table', async () => (await page.locator('.ratios-table tbody tr').count()) === comparison.strategies.length);
  const switchRow = page.locator('.ratios-table tbody tr[data-strategy="switch"]');
  const ratioText = await switchRow.locator('td[data-col="rms-ratio"]').textContent();
  const expected = comparison.strategies.find((x) => x.strategy === 'switch').runs[1];
  const [ratio, ratioSe] = parseWithError(ratioText);
  check(Math.abs(ratio - expected.rms_ratio) < 6e-4 && Math.abs(ratioSe - expected.rms_ratio_stderr) < 6e-4,
    `the ratios table gives switch's RMS ratio against the first job as the API does (${ratioText})`);

  // Each job's table: its recommended one, or its table optimum (a per-path strategy recommended).
  const figures = await Promise.all([spot, uniform].map((id, k) => expectedFigure(id, results[k])));
  const plot = await readPlot(page.locator('[data-ref="w1-plot"]'));
  const named = [`#${spot} paper-table1 (spot a = 0.02): `, `#${uniform} uniform-illumination (uniform): `];
  check(plot.labels.length === 2 && plot.labels.every((l, k) => l.startsWith(named[k])
    && l.endsWith(figures[k].kind === 'table-optimum' ? 'not recommended' : `recommended ${figures[k].strategy}`)),
  `the w₁(r₃) overlay has one series per job, saying which table it is (${plot.labels.join(' | ')})`);
  const marksIn = (r2) => figures.map((f) => figureMarks(f.weights, [r2])).reduce((a, m) => ({ bars: a.bars + m.bars, open: a.open + m.open }), { bars: 0, open: 0 });
  const first = marksIn(0);
  check(plot.errorBars === first.bars && plot.openMarkers === first.open && plot.guides === 'x=0.02',
    `it draws ${plot.errorBars} error bars and ${plot.openMarkers} open markers in the first r₂ bin, and the spot's r₃ = a`);
  await page.locator('select[data-ref="r2"]').selectOption({ index: 1 });
  const second = marksIn(0.5);
  await waitFor('the second r₂ bin', async () => {
    const p = await readPlot(page.locator('[data-ref="w1-plot"]'));
    return p.errorBars === second.bars && p.openMarkers === second.open;
  }, 5_000);
  check(true, `the r₂ selector redraws it for r₂ ∈ [0.5, ∞) (${second.bars} bars, ${second.open} open markers)`);
  await page.locator('select[data-ref="r2"]').selectOption({ index: 0 });
  await waitFor('the first r₂ bin again', async () => (await readPlot(page.locator('[data-ref="w1-plot"]'))).errorBars === first.bars, 5_000);

  await checkAxes(page, page.locator('[data-ref="w1-plot"]'), 'the compare chart');
  const contract = await csvContract();
  const csv = await downloadFrom(page, page.getByRole('button', { name: 'Compare table (CSV)' }));
  const [header, ...rows] = parseCsv(csv.bytes.toString('utf8'));
  const ids = new Set(rows.map((r) => r[header.indexOf('job_id')]));
  check(header.join() === contract.compare.columns.join() && rows.length === results.reduce((n, r) => n + r.noise_table.length, 0)
    && ids.size === 2 && ids.has(String(spot)),
  `"Compare table (CSV)" saves ${csv.name}: docs/csv.md's compare columns (the job's, then the noise table's), ${rows.length} rows, one per job and strategy`);
  const weights = await downloadFrom(page, page.getByRole('button', { name: 'Weights (CSV)' }));
  const [weightsHeader, ...weightRows] = parseCsv(weights.bytes.toString('utf8'));
  check(weightsHeader.join() === ['job_id', ...contract.weights.columns].join()
    && weightRows.length === figures.reduce((n, f) => n + f.weights.length, 0),
  `its "Weights (CSV)" has job_id, table, strategy, lambda, then docs/csv.md's weights columns: ${weightRows.length} rows, one per job and cell`);
  const png = await downloadFrom(page, page.locator('[data-ref="w1-downloads"] button[data-download="png"]'));
  check(pngSize(png.bytes).width >= PNG_MIN_WIDTH, `the compare chart's PNG is ${pngSize(png.bytes).width} px wide`);
  await sleep(300); // the chart's first draw settles
  await screenshot(page, 'compare.png');
  await docScreenshot(page, 'dashboard-compare.png', null, '[aria-labelledby="compare-w1-heading"]');

  await page.goto(`${page.url().split('#')[0]}#/compare?ids=${spot}`);
  const error = await waitFor('the refusal', async () => {
    const el = page.locator('[data-ref="load-error"]');
    return (await el.isVisible()) && el.textContent();
  });
  check(error.includes('Compare 2 to 8 different jobs'), `#/compare with one job says "${error}"`);
}

/** A kept solve: free w₀ under a name, shown instead of the job's own options, then back. */
export async function checkSolves(page, id) {
  await page.goto(`${page.url().split('#')[0]}#/jobs/${id}`);
  const select = page.locator('[data-ref="solve-select"]');
  await waitFor('the solves selector', async () => (await select.locator('option').count()) === 1);
  check((await select.inputValue()) === 'default', 'the solves selector starts at the job\'s own options (default)');
  const rmsCell = page.locator('table.noise-table tbody tr[data-strategy="optimal_cv"] td[data-col="rms"]');
  await waitFor('the noise table', async () => (await rmsCell.count()) === 1);
  const ownText = (await rmsCell.textContent()).trim();
  const own = (await callApi(`/v1/jobs/${id}/result`)).json.noise_table.find((r) => r.strategy === 'optimal_cv');
  await page.locator('.solve-form input[name="name"]').fill('free-w0');
  await page.locator('.solve-form input[name="free-w0"]').check();
  await page.locator('.solve-form button[type="submit"]').click();
  await waitFor('the kept solve shown', async () => (await select.inputValue()) === 'free-w0'
    && (await rmsCell.textContent()).trim() !== ownText);
  const keptResult = (await callApi(`/v1/jobs/${id}/solves/free-w0`)).json;
  const kept = keptResult.noise_table.find((r) => r.strategy === 'optimal_cv');
  check(kept.rms_percent < own.rms_percent,
    `freeing w₀ lowers the cross-fitted optimum's RMS (${kept.rms_percent.toFixed(2)} < ${own.rms_percent.toFixed(2)} %)`);
  const keptText = (await rmsCell.textContent()).trim();
  check(keptText.startsWith(kept.rms_percent.toFixed(1)), `the page shows the kept solve's optimal_cv RMS (${keptText})`);
  const recommended = page.locator('table.noise-table tbody tr.recommended');
  await waitFor('the kept solve\'s recommendation marked', async () => (await recommended.getAttribute('data-strategy')) === keptResult.recommended.strategy);
  check(true, `the kept solve's recommended row, ${keptResult.recommended.strategy}, is marked`);
  const keptRec = keptResult.recommended;
  if (keptRec.lambda === null && !keptRec.heuristics.length) {
    // A per-path heuristic is the same function under any options: its effective weights are drawn.
    await waitFor('Fig. 2 of the kept solve\'s heuristic', async () =>
      (await page.locator('[data-ref="weights-note"]').textContent()).includes('The kept solve\'s recommendation'));
    check((await page.locator('[data-ref="weights-kind"]').textContent()).startsWith(`recommended: ${keptRec.strategy}`)
      && (await readPlot(page.locator('[data-ref="weights-plot"]'))).markers > 0,
    `under kept options recommending the heuristic ${keptRec.strategy} Fig. 2 draws its effective weights`);
  } else {
    // A kept solve's fitted row: the effective weights exist for the job's own options only.
    const message = await waitFor('Fig. 2\'s message', () => page.locator('[data-ref="weights-plot"] .empty').textContent().catch(() => null));
    check(message.includes(`recommends ${keptRec.strategy}`) && message.includes('job\'s own solver options only'),
      `with a fitted recommendation under kept options Fig. 2 says why it draws no effective weights ("${message.slice(0, 80)}…")`);
  }
  const listed = (await callApi(`/v1/jobs/${id}/solves`)).json.solves;
  check(listed.length === 2 && listed[0].default && listed[1].name === 'free-w0' && listed[1].solver.fixed.w0 === undefined,
    'the server keeps it after the default, with w₀ freed');
  await select.selectOption('default');
  await waitFor('the job\'s own options shown again', async () => (await rmsCell.textContent()).trim() === ownText
    && (await page.locator('[data-ref="weights-plot"] canvas').count()) > 0);
  check(true, `choosing default shows the job's own table and Fig. 2 again (${ownText})`);
}
