// Browser test of the built-in dashboard: drives headless Chromium (playwright-core, no browser
// download) through what a user does, against a running server.
//
// Usage: node dashboard.mjs BASE_URL OUT_DIR
//   BASE_URL  the server, e.g. http://127.0.0.1:8080 (its database should start empty)
//   OUT_DIR   where the screenshots go
// Environment: CHROMIUM = the Chromium executable (default /usr/bin/chromium); OPTIMIS_TOKEN = the
// server's bearer token, if it has one: the page must then ask for it before anything else works.
//
// Exits non-zero with the reason if a check fails, the page throws, or it logs a console error.

import { mkdir, readFile } from 'node:fs/promises';
import path from 'node:path';
import { chromium } from 'playwright-core';

const STRATEGIES = ['plane1', 'plane2', 'plane3', 'switch', 'optimal', 'optimal_holdout', 'optimal_cv', 'balance', 'power', 'correlation_aware'];
// Strategies with fixed per-path weights: they always have numbers (fits may fail on little data).
const PER_PATH = new Set(['plane1', 'plane2', 'plane3', 'switch', 'balance', 'power', 'correlation_aware']);
// Weights fitted on one half and evaluated on the other: far off on little data (even negative).
const NOISY = new Set(['optimal_holdout']);
// Big enough to be seen running for a few seconds on two cores, small enough to finish quickly.
// The brute force, so that the job runs long enough to be watched while it runs.
const JOB = { preset: 'paper-table1', engine: 'brute', light_paths: '200000', camera_paths: '500', merge_radius: '0.02', iterations: '300' };
const SMALL_JOBS = 30; // more than one page of 25
// A 2 × 2 grid at a small budget (restricted engine: well under a second per run).
const SWEEP = {
  base: { iterations: 300, light_paths: 1000000, seed: 3 },
  axes: [{ field: 'merge_radius', values: [0.003, 0.01] }, { field: 'scene.l3', values: [1, 3] }],
  mode: 'grid',
};
// Runs far longer than the test: cancelled from its page.
const LONG_SWEEP = { base: { iterations: 1000000, light_paths: 1000000 }, axes: [{ field: 'seed', values: [1, 2] }] };
// Cells whose weights the server copied from a neighbour: gaps in the weight charts, without a bar.
const UNFITTED = new Set(['empty', 'uninformative']);
const OVERALL_TIMEOUT_MS = 240_000;

const [base, outDir] = process.argv.slice(2);
if (!base || !outDir) {
  console.error('usage: node dashboard.mjs BASE_URL OUT_DIR');
  process.exit(2);
}

let passed = 0;
function check(condition, what) {
  if (!condition) throw new Error(`check failed: ${what}`);
  passed += 1;
  console.log(`ok ${passed} - ${what}`);
}

// Page errors, console errors and server errors, reported by the next wait or check.
const problems = [];
// HTTP errors a step provokes on purpose: Chromium logs each failed request as a console error.
const allowedHttpErrors = [];
// Until the token is entered, the page's API calls are expected to be refused with 401.
let signedOut = Boolean(process.env.OPTIMIS_TOKEN);

function watchPage(page) {
  page.on('pageerror', (error) => problems.push(`uncaught exception in the page: ${error.stack || error}`));
  page.on('console', (message) => {
    if (message.type() !== 'error') return;
    const status = /status of (\d{3})/.exec(message.text())?.[1];
    const url = message.location().url;
    if (signedOut && status === '401') return;
    const allowed = allowedHttpErrors.findIndex((a) => String(a.status) === status && url === new URL(a.path, base).href);
    if (allowed >= 0) allowedHttpErrors.splice(allowed, 1);
    else problems.push(`console error: ${message.text()}${url ? ` (${url})` : ''}`);
  });
  page.on('response', (response) => {
    if (response.status() >= 500) problems.push(`server error ${response.status()} for ${response.url()}`);
  });
}

function assertNoProblems() {
  if (problems.length > 0) throw new Error(`the page reported problems:\n  ${problems.join('\n  ')}`);
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

const authHeaders = () => (process.env.OPTIMIS_TOKEN ? { Authorization: `Bearer ${process.env.OPTIMIS_TOKEN}` } : {});

/** Calls the server's API directly (not through the page): { status, body } with the body parsed if JSON. */
async function callApi(urlPath, { method = 'GET', body } = {}) {
  const headers = { ...authHeaders(), ...(body === undefined ? {} : { 'Content-Type': 'application/json' }) };
  const response = await fetch(new URL(urlPath, base), { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const text = await response.text();
  const json = (response.headers.get('content-type') || '').includes('json') ? JSON.parse(text) : null;
  return { status: response.status, text, json };
}

/** Polls `probe` until it returns a truthy value, failing early on page problems. */
async function waitFor(what, probe, timeoutMs = 30_000) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    assertNoProblems();
    const value = await probe();
    if (value) return value;
    if (Date.now() > deadline) throw new Error(`timed out after ${timeoutMs / 1000} s waiting for ${what}`);
    await sleep(50);
  }
}

async function screenshot(page, name) {
  const file = path.join(outDir, name);
  await page.screenshot({ path: file, fullPage: true });
  console.log(`   screenshot ${file}`);
}

/** "26.26 ± 0.75" → [26.26, 0.75]; "8.29" → [8.29, null]. */
function parseWithError(text) {
  const numbers = text.replace(/,/g, '').split('±').map((part) => Number.parseFloat(part.trim()));
  return [numbers[0], numbers.length > 1 ? numbers[1] : null];
}

async function fillForm(page, values) {
  const form = page.locator('form[data-ref="form"]');
  await form.locator('select[name="preset"]').selectOption(values.preset);
  if (values.engine) await form.locator('select[name="engine"]').selectOption(values.engine);
  for (const name of ['iterations', 'light_paths', 'camera_paths', 'merge_radius']) {
    await form.locator(`input[name="${name}"]`).fill(values[name]);
  }
  return form;
}

async function checkListPage(page) {
  await page.goto(`${base}/#/`);
  await waitFor('the job list', () => page.locator('h1', { hasText: 'Jobs' }).isVisible());
  const empty = await waitFor('the empty-list message', async () => {
    const el = page.locator('[data-ref="empty"]');
    return (await el.isVisible()) && el.textContent();
  });
  check(empty.includes('No jobs yet'), `an empty database shows "${empty}"`);
  const unlabelled = await page.evaluate(() =>
    [...document.querySelectorAll('form input, form select, form textarea')].filter((el) => el.labels.length === 0).map((el) => el.name));
  check(unlabelled.length === 0, `every form control has a label${unlabelled.length ? ` (not: ${unlabelled})` : ''}`);
}

async function checkInvalidSubmission(page) {
  const form = await fillForm(page, { ...JOB, merge_radius: '-1' });
  allowedHttpErrors.push({ status: 422, path: '/v1/jobs' });
  await form.locator('button[type="submit"]').click();
  const message = await waitFor('the form error', async () => {
    const el = page.locator('#form-error');
    return (await el.isVisible()) && el.textContent();
  });
  check(message.includes('merge_radius'), `an invalid merge radius is explained next to the form: "${message}"`);
  const invalid = await form.locator('input[name="merge_radius"]').getAttribute('aria-invalid');
  check(invalid === 'true', 'the merge radius input is marked invalid');
  check(new URL(page.url()).hash === '#/', 'a rejected job stays on the list page');
}

async function submitJob(page) {
  const form = await fillForm(page, JOB);
  await form.locator('button[type="submit"]').click();
  const id = await waitFor('the job page', () => /^#\/jobs\/(\d+)$/.exec(new URL(page.url()).hash)?.[1]);
  await waitFor('the job heading', () => page.locator('h1', { hasText: `Job ${id}` }).isVisible());
  check(true, `submitting the form opens the new job's page (#/jobs/${id})`);
  return id;
}

/** Reads the progress bar until the job succeeds; screenshots it once while it runs with results. */
async function followProgress(page) {
  const seen = [];
  let total = 0;
  let shotRunning = false;
  await waitFor('the job to succeed', async () => {
    const state = await page.evaluate(() => {
      const bar = document.querySelector('[data-ref="progress"]');
      return {
        done: Number(bar.getAttribute('aria-valuenow')),
        total: Number(bar.getAttribute('aria-valuemax')),
        badge: document.querySelector('[data-ref="state"] .badge')?.textContent,
        results: !document.querySelector('[data-ref="noise-table"]').hidden,
      };
    });
    total = state.total;
    if (seen.at(-1) !== state.done) seen.push(state.done);
    const midway = state.done > 0 && state.done < state.total;
    if (state.badge === 'failed' || state.badge === 'cancelled') throw new Error(`the job ended ${state.badge}`);
    if (!shotRunning && state.badge === 'running' && midway && (state.results || state.done >= state.total / 2)) {
      await screenshot(page, 'job-running.png');
      shotRunning = true;
    }
    return state.badge === 'succeeded';
  }, 180_000);
  console.log(`   progress values seen: ${seen.join(', ')}`);
  check(seen.every((v, i) => i === 0 || v > seen[i - 1]), 'the progress bar only moves forward');
  check(seen.some((v) => v > 0 && v < total) && seen.at(-1) === total && total === Number(JOB.iterations),
    `the progress bar advanced live (${seen.length} distinct values) to ${total} / ${total}`);
  check(shotRunning, 'the job page was captured while running');
}

async function checkNoiseTable(page) {
  await waitFor('the final results', async () =>
    (await page.locator('[data-ref="result-status"]').textContent()).startsWith('final'));
  const reference = parseWithError((await page.locator('[data-ref="reference"]').textContent()).split('=')[1]);
  check(reference[0] > 5 && reference[0] < 100, `the quadrature reference L·10⁵ = ${reference[0]} is shown`);
  const rows = await page.locator('table.noise-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy,
    cells: [...tr.querySelectorAll('td')].map((td) => td.textContent.trim()),
    error: tr.querySelector('.row-error')?.textContent,
  })));
  check(JSON.stringify(rows.map((r) => r.strategy)) === JSON.stringify(STRATEGIES), `the noise table has the ${STRATEGIES.length} strategies in order`);
  for (const row of rows) {
    check(row.cells[0].length > 0, `${row.strategy}: its weights are described ("${row.cells[0]}")`);
    if (row.error) {
      check(!PER_PATH.has(row.strategy), `${row.strategy}: shows its fit error instead of numbers ("${row.error.slice(0, 60)}…")`);
      continue;
    }
    const [luminance, luminanceError] = parseWithError(row.cells[1]);
    const [rms] = parseWithError(row.cells[2]);
    const plausible = NOISY.has(row.strategy)
      ? Number.isFinite(luminance) && Number.isFinite(rms)
      : luminance > 5 && luminance < 100 && luminanceError > 0 && rms > 0;
    check(plausible, `${row.strategy}: L·10⁵ = ${row.cells[1]}, RMS % = ${row.cells[2]}`);
  }
  const marks = await page.locator('table.noise-table tbody tr').evaluateAll((trs) => Object.fromEntries(
    trs.map((tr) => [tr.dataset.strategy, [...tr.querySelectorAll('th span')].map((s) => s.textContent)])));
  check(marks.optimal.includes('in-sample') && STRATEGIES.every((s) => s === 'optimal' || !marks[s].includes('in-sample')),
    'only the paper\'s optimal row is marked in-sample');
  check(marks.optimal_cv.includes('recommended'), 'the cross-validated optimum is marked recommended');
  const outside = STRATEGIES.filter((s) => marks[s].includes('outside fixed weights'));
  check(outside.join() === 'plane1,balance,power,correlation_aware',
    `the rows that merge at the pixel are marked outside the fixed weights w0 = 0 (${outside.join(', ')})`);
  check(!outside.some((s) => marks[s].includes('best')), 'no row outside the fixed weights is marked best');
  const gain = await page.locator('[data-ref="gain"]').textContent();
  check(gain.includes('variance ratio'), `the gain is shown ("${gain.slice(0, 80)}…")`);
  const warnings = await page.locator('[data-ref="warnings"] li code').allTextContents();
  check(warnings.length > 0 && warnings.every((w) => /^[a-z_]+$/.test(w)),
    `the result's warnings are listed by code (${warnings.join(', ')})`);
  const describes = Object.fromEntries(rows.map((r) => [r.strategy, r.cells[0]]));
  check(describes.plane1 === 'w₀ = 1' && describes.switch.includes('r₃ ≤ a') && describes.optimal.includes('w₀ = 0')
    && describes.optimal_cv.includes('cross-validation'), 'the weights column reads like the paper');
}

/**
 * What a uPlot chart in `container` shows: its canvas size and drawn pixels, the labels of its
 * legend (the y series; the x series left out), and the error bars the sweep charts report drawing.
 */
async function readPlot(container) {
  return container.evaluate((el) => {
    const canvas = el.querySelector('canvas');
    if (!canvas) return null;
    const { data } = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height);
    let inked = 0;
    for (let i = 3; i < data.length; i += 4) if (data[i] > 0) inked += 1;
    return {
      width: canvas.width, height: canvas.height, inked,
      labels: [...el.querySelectorAll('.u-legend .u-series .u-label')].slice(1).map((l) => l.textContent.trim()),
      errorBars: el.dataset.errorBars === undefined ? null : Number(el.dataset.errorBars),
    };
  });
}

/** The canvas of a uPlot chart has a size, has been drawn on, and its legend names the series. */
async function checkPlot(page, ref, what, expectedLabels) {
  const plot = await readPlot(page.locator(`[data-ref="${ref}"]`));
  check(plot !== null, `the ${what} plot has a canvas`);
  check(plot.width > 0 && plot.height > 0 && plot.inked > 1000,
    `the ${what} plot is ${plot.width}×${plot.height} px with ${plot.inked} drawn pixels`);
  for (const label of expectedLabels) {
    check(plot.labels.some((l) => l.startsWith(label)), `the ${what} legend names "${label}"`);
  }
}

/** A job page opened directly (bookmark, reload) rather than from the list. */
async function checkDirectLoad(page, id) {
  await page.reload();
  await waitFor('the reloaded job page', async () =>
    (await page.locator('h1', { hasText: `Job ${id}` }).isVisible())
    && (await page.locator('table.noise-table tbody tr').count()) === STRATEGIES.length);
  check(true, `reloading #/jobs/${id} shows the job and its ${STRATEGIES.length} results again`);
}

async function checkJobInList(page, id) {
  await page.getByRole('link', { name: 'All jobs' }).click();
  const state = await waitFor(`job ${id} in the list`, async () => {
    const badge = page.locator(`tr[data-job="${id}"] .badge`);
    return (await badge.count()) > 0 && badge.textContent();
  });
  check(state === 'succeeded', `the list shows job ${id} as ${state}`);
  const progress = await page.locator(`tr[data-job="${id}"] .progress-text`).textContent();
  check(progress === `${JOB.iterations} / ${JOB.iterations}`, `its progress bar reads ${progress}`);
}

/** With more jobs than a page holds: Older/Newer page through them, the filter narrows them. */
async function checkPagination(page) {
  for (let i = 0; i < SMALL_JOBS; i += 1) {
    const response = await callApi('/v1/jobs', {
      method: 'POST',
      body: { light_paths: 20000, camera_paths: 200, merge_radius: 0.02, iterations: 1, seed: i + 1 },
    });
    if (response.status !== 202) throw new Error(`submitting small job ${i + 1} answered ${response.status}`);
  }
  const rowCount = () => page.locator('table.jobs-table tbody tr').count();
  await waitFor('a full first page', async () => (await rowCount()) === 25, 10_000);
  check(true, 'the list shows 25 jobs on its first page');
  await page.getByRole('button', { name: 'Older' }).click();
  await waitFor('the second page', async () => (await rowCount()) === SMALL_JOBS + 1 - 25);
  check(await page.getByText('Page 2').isVisible(), `"Older" shows page 2 with the ${SMALL_JOBS + 1 - 25} oldest jobs`);
  await page.getByRole('button', { name: 'Newer' }).click();
  await waitFor('the first page again', async () => (await rowCount()) === 25 && page.getByText('Page 1').isVisible());
  check(true, '"Newer" goes back to page 1');
  await page.locator('select[data-ref="filter"]').selectOption('failed');
  const empty = await waitFor('the filtered list', async () => {
    const el = page.locator('[data-ref="empty"]');
    return (await el.isVisible()) && el.textContent();
  });
  check(empty === 'No failed jobs.', `filtering by state "failed" shows "${empty}"`);
  await page.locator('select[data-ref="filter"]').selectOption('');
  await waitFor('the unfiltered list', async () => (await rowCount()) === 25);
}

// ---------------------------------------------------------------------------------------------
// Sweeps

/** A sweep's values in the page's words: `merge_radius=0.003, scene.l3=1`. */
const describePoint = (sweep, point) => sweep.fields.map((f) => `${f}=${JSON.stringify(point.values[f])}`).join(', ');

/** The error bars the RMS chart of `field` should draw: rows with a positive RMS and standard error at the points where the other axes take the values `fixed`. */
function expectedRmsBars(sweep, field, fixed) {
  const points = sweep.points.filter((p) => Object.entries(fixed).every(([f, v]) => f === field || p.values[f] === v));
  return points.flatMap((p) => p.figures.noise_table).filter((r) => r.rms_percent > 0 && r.rms_percent_stderr > 0).length;
}

/** The error bars of the w₁(r₃) chart: per point, the fitted cells of the first r₂ and φ bins, tail left out, with a positive SE. */
function expectedW1Bars(sweep) {
  return sweep.points.map(({ figures: { weights } }) => {
    const r2 = Math.min(...weights.map((w) => w.r2[0]));
    const phi = Math.min(...weights.map((w) => w.phi[0]));
    return weights.filter((w) => w.r2[0] === r2 && w.phi[0] === phi && w.r3[1] !== null && !UNFITTED.has(w.status)
      && w.w1_stderr > 0).length;
  }).reduce((a, b) => a + b, 0);
}

/** The sweep list (from the header) leads to a sweep created through the API; its page follows it to the end. */
async function openSweep(page) {
  const created = await callApi('/v1/sweeps', { method: 'POST', body: SWEEP });
  check(created.status === 201, `POST /v1/sweeps creates a 2 × 2 sweep (${created.status})`);
  const id = created.json.id;
  await page.locator('.topnav').getByRole('link', { name: 'Sweeps' }).click();
  const row = page.locator(`tr[data-sweep="${id}"]`);
  await waitFor(`sweep ${id} in the sweep list`, async () => (await row.count()) > 0);
  const axes = (await row.locator('td').nth(2).textContent()).replace(/\s+/g, ' ').trim();
  check(axes === 'merge_radius (2) × scene.l3 (2)', `the sweep list shows sweep ${id} with its axes "${axes}"`);
  await row.getByRole('link', { name: `#${id}` }).click();
  await waitFor('the sweep page', () => page.locator('h1', { hasText: `Sweep ${id}` }).isVisible());
  check(new URL(page.url()).hash === `#/sweeps/${id}`, `the list links to the sweep page #/sweeps/${id}`);
  await waitFor('the sweep to succeed', async () => {
    const badge = await page.locator('[data-ref="state"] .badge').textContent().catch(() => '');
    if (badge === 'failed' || badge === 'cancelled') throw new Error(`the sweep ended ${badge}`);
    return badge === 'succeeded';
  }, 150_000);
  const sweep = (await callApi(`/v1/sweeps/${id}`)).json;
  check(sweep.state === 'succeeded' && sweep.points.every((p) => p.figures && !p.figures.partial),
    'the API agrees: the sweep succeeded and every point has final figures');
  return sweep;
}

async function checkSweepSummary(page, sweep) {
  const progress = await page.locator('[data-ref="progress"] .progress-text').textContent();
  check(progress === '1,200 / 1,200', `the sweep's progress bar reads ${progress} (4 runs × 300 iterations)`);
  const runs = (await page.locator('[data-ref="runs-by-state"]').textContent()).replace(/\s+/g, ' ').trim();
  check(runs === 'succeeded 4', `the runs by state read "${runs}"`);
  check(await page.locator('[data-ref="cancel"]').isHidden(), 'a finished sweep has no Cancel button');
  const rows = await page.locator('.points-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    cells: [...tr.cells].map((td) => td.textContent.trim()),
    job: tr.querySelector('a')?.getAttribute('href'),
  })));
  check(rows.length === 4, `the points table has the ${rows.length} points`);
  sweep.points.forEach((p, i) => {
    const [index, radius, l3, job, state, , rms] = rows[i].cells;
    const chosen = p.figures.noise_table.find((r) => r.strategy === p.figures.recommended.strategy);
    const shown = Number.parseFloat(rms.replace(/,/g, ''));
    check(index === String(p.index) && radius === String(p.values.merge_radius) && l3 === String(p.values['scene.l3'])
      && job === `#${p.job_id}` && rows[i].job === `#/jobs/${p.job_id}` && state === 'succeeded'
      && Math.abs(shown - chosen.rms_percent) < 0.06 && rms.includes(chosen.strategy),
      `point ${p.index}: ${radius}, ${l3}, job ${job}, recommended RMS ${rms}`);
  });
}

/** The CSV link points at the table, and clicking it downloads the same bytes as the API serves. */
async function checkCsv(page, sweep) {
  const href = `/v1/sweeps/${sweep.id}/table?format=csv`;
  const link = page.getByRole('link', { name: 'Download the table (CSV)' });
  check(await link.getAttribute('href') === href, `the CSV link is ${href}`);
  const [download] = await Promise.all([page.waitForEvent('download'), link.click()]);
  const text = await readFile(await download.path(), 'utf8');
  const expected = await callApi(href);
  const lines = text.trimEnd().split('\r\n');
  const rows = sweep.points.reduce((n, p) => n + p.figures.noise_table.length, 0);
  check(download.suggestedFilename() === `sweep-${sweep.id}.csv` && lines[0].startsWith('point,merge_radius,scene.l3,source,')
    && lines.length === 1 + rows, `clicking it downloads ${download.suggestedFilename()}: a header and ${lines.length - 1} rows`);
  check(text === expected.text, 'the download is the table the API serves');
}

async function checkSweepCharts(page, sweep) {
  const strategies = [...new Set(sweep.points.flatMap((p) => p.figures.noise_table.map((r) => r.strategy)))];
  const outside = new Set(sweep.points.flatMap((p) => p.figures.noise_table.filter((r) => !r.respects_fixed).map((r) => r.strategy)));
  const first = Object.fromEntries(sweep.spec.axes.map((a) => [a.field, a.values[0]]));
  for (const axis of sweep.spec.axes) {
    const card = page.locator(`[data-field="${axis.field}"]`);
    const other = sweep.spec.axes.find((a) => a !== axis);
    const plot = await readPlot(card.locator('.plot'));
    check(plot !== null && plot.inked > 1000, `the RMS chart of ${axis.field} is drawn (${plot?.inked} pixels)`);
    check(plot.labels.length === strategies.length && strategies.every((s) => plot.labels.some((l) => l.startsWith(s))),
      `it has one series per strategy of the noise tables (${plot.labels.length})`);
    check(plot.labels.every((l) => l.includes('outside fixed weights') === outside.has(l.split(' ')[0])),
      `the strategies outside the fixed weights are marked (${[...outside].join(', ')})`);
    const bars = expectedRmsBars(sweep, axis.field, first);
    check(plot.errorBars === bars && bars > 0, `it draws ${plot.errorBars} error bars, one per row with a standard error`);
    const select = card.locator(`select[data-axis="${other.field}"]`);
    const options = await select.locator('option').allTextContents();
    check(options.join() === other.values.map(String).join(), `a selector fixes ${other.field} (${options.join(', ')})`);
    await select.selectOption({ index: 1 });
    const moved = expectedRmsBars(sweep, axis.field, { ...first, [other.field]: other.values[1] });
    const after = await waitFor('the redrawn chart', async () => {
      const p = await readPlot(card.locator('.plot'));
      return p.errorBars === moved && p;
    }, 5_000);
    check(after.labels.length === strategies.length, `with ${other.field} = ${other.values[1]} it redraws ${moved} bars, same series`);
  }
  const w1 = await readPlot(page.locator('[data-ref="w1-plot"]'));
  check(w1 !== null && w1.inked > 1000, `the w₁(r₃) chart is drawn (${w1?.inked} pixels)`);
  const labels = sweep.points.map((p) => describePoint(sweep, p));
  check(JSON.stringify(w1.labels) === JSON.stringify(labels), `it has one series per point, labelled ${labels.join(' | ')}`);
  const bars = expectedW1Bars(sweep);
  check(w1.errorBars === bars && bars > 0, `it draws ${w1.errorBars} error bars (± jackknife SE of w₁)`);
}

/** A run's job page links back to its sweep, and so does the job list. */
async function checkSweepLinks(page, sweep) {
  const point = sweep.points[1];
  await page.locator(`.points-table tr[data-point="${point.index}"] a`).click();
  await waitFor('the job page', () => page.locator('h1', { hasText: `Job ${point.job_id}` }).isVisible());
  const link = page.locator('[data-ref="sweep"]');
  check(await link.isVisible() && await link.textContent() === `sweep ${sweep.id}` && await link.getAttribute('href') === `#/sweeps/${sweep.id}`,
    `job ${point.job_id}'s page shows "sweep ${sweep.id}" linked to the sweep`);
  await link.click();
  await waitFor('the sweep page again', () => page.locator('h1', { hasText: `Sweep ${sweep.id}` }).isVisible());
  check(true, 'the link leads back to the sweep page');
  await page.locator('.topnav').getByRole('link', { name: 'Jobs' }).click();
  const inList = page.locator(`tr[data-job="${point.job_id}"] a.sweep-link`);
  await waitFor(`job ${point.job_id} in the list`, async () => (await inList.count()) > 0);
  check(await inList.getAttribute('href') === `#/sweeps/${sweep.id}`, `the job list shows job ${point.job_id} as part of sweep ${sweep.id}`);
}

/** A running sweep is cancelled from its page: every run ends cancelled. */
async function checkSweepCancel(page) {
  const created = await callApi('/v1/sweeps', { method: 'POST', body: LONG_SWEEP });
  check(created.status === 201, 'a long sweep is created');
  const { id } = created.json;
  await page.goto(`${base}/#/sweeps/${id}`);
  const cancel = page.locator('[data-ref="cancel"]');
  await waitFor('the Cancel button', () => cancel.isVisible());
  await cancel.click();
  await waitFor('the sweep to be cancelled', async () => (await page.locator('[data-ref="state"] .badge').textContent()) === 'cancelled');
  const sweep = (await callApi(`/v1/sweeps/${id}`)).json;
  check(sweep.points.every((p) => p.state === 'cancelled') && (await cancel.isHidden()),
    `Cancel stops every run of sweep ${id} (${JSON.stringify(sweep.progress.runs_by_state)}) and goes away`);
}

/** With a token on the server: the page asks for it, and works once it is given. */
async function signIn(page, token) {
  await page.goto(base);
  const form = page.locator('#sign-in');
  await waitFor('the sign-in banner', () => form.isVisible());
  check(/needs its access token/.test(await form.innerText()), 'a server with a token asks for it in plain words');
  await page.locator('#token-input').fill(token);
  await page.locator('#sign-in button[type="submit"]').click();
  await waitFor('the banner to go away', async () => !(await form.count()));
  signedOut = false;
  check(true, 'the token is accepted');
}

async function run(browser) {
  const page = await browser.newPage({ viewport: { width: 1366, height: 900 }, locale: 'en-US' });
  watchPage(page);
  if (process.env.OPTIMIS_TOKEN) await signIn(page, process.env.OPTIMIS_TOKEN);

  await checkListPage(page);
  await checkInvalidSubmission(page);
  const id = await submitJob(page);
  await followProgress(page);
  await checkNoiseTable(page);
  await checkPlot(page, 'weights-plot', 'weights', ['w₁', 'w₂', 'w₁ − 2 SE', 'w₁ + 2 SE']);
  await checkPlot(page, 'history-plot', 'RMS history', STRATEGIES);
  await screenshot(page, 'job-finished.png');
  await checkDirectLoad(page, id);
  await checkJobInList(page, id);
  await checkPagination(page);
  await screenshot(page, 'list.png');
  const sweep = await openSweep(page);
  await checkSweepSummary(page, sweep);
  await checkSweepCharts(page, sweep);
  await screenshot(page, 'sweep.png');
  await checkCsv(page, sweep);
  await checkSweepLinks(page, sweep);
  await checkSweepCancel(page);
  await sleep(500); // let late console messages arrive
  assertNoProblems();
  check(allowedHttpErrors.length === 0, 'the browser logged exactly the expected 422 of the invalid job');
}

async function main() {
  await mkdir(outDir, { recursive: true });
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const timer = setTimeout(() => {
    console.error(`FAIL: the browser test took longer than ${OVERALL_TIMEOUT_MS / 1000} s`);
    process.exit(1);
  }, OVERALL_TIMEOUT_MS);
  try {
    await run(browser);
    console.log(`dashboard: ${passed} passed, 0 failed`);
  } finally {
    clearTimeout(timer);
    await browser.close();
  }
}

main().catch((error) => {
  console.error(`FAIL: ${error.message}`);
  console.error(`(${passed} checks had passed)`);
  process.exit(1);
});
