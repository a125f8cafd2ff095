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

import { mkdir } from 'node:fs/promises';
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

/** The canvas of a uPlot chart has a size, has been drawn on, and its legend names the series. */
async function checkPlot(page, ref, what, expectedLabels) {
  const plot = await page.locator(`[data-ref="${ref}"]`).evaluate((el) => {
    const canvas = el.querySelector('canvas');
    if (!canvas) return null;
    const { data } = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height);
    let inked = 0;
    for (let i = 3; i < data.length; i += 4) if (data[i] > 0) inked += 1;
    return {
      width: canvas.width, height: canvas.height, inked,
      labels: [...el.querySelectorAll('.u-legend .u-series .u-label')].map((l) => l.textContent.trim()),
    };
  });
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
    const response = await fetch(new URL('/v1/jobs', base), {
      method: 'POST',
      headers: {
        'Content-Type': 'application/json',
        ...(process.env.OPTIMIS_TOKEN ? { Authorization: `Bearer ${process.env.OPTIMIS_TOKEN}` } : {}),
      },
      body: JSON.stringify({ light_paths: 20000, camera_paths: 200, merge_radius: 0.02, iterations: 1, seed: i + 1 }),
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
