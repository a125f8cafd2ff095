// Browser test of the built-in dashboard: drives headless Chromium (playwright-core, no browser
// download) through what a user does, against a running server.
//
// Usage: node dashboard.mjs BASE_URL OUT_DIR
//   BASE_URL  the server, e.g. http://127.0.0.1:8080 (its database should start empty)
//   OUT_DIR   where the screenshots go
// Environment: CHROMIUM = the Chromium executable (default /usr/bin/chromium); OPTIMIS_TOKEN = the
// server's bearer token, if it has one: the page must then ask for it before anything else works.
//
// OPTIMIS_SCREENSHOT_DIR = where to write the README's screenshots (dashboard-job.png,
// dashboard-compare.png), if set. (docs/dashboard-sweep.png, of a paper-scale sweep, is
// screenshot.mjs's.)
//
// Exits non-zero with the reason if a check fails, the page throws, or it logs a console error.
//
// The steps are in harness.mjs (checks, waiting, the API, charts and their axes), files.mjs
// (downloads, CSV, PNG, docs/csv.md's columns, the README's screenshots), jobs.mjs (the list, the
// form, a job followed live), research.mjs (the paper's Table 1, Fig. 2, the compare page),
// downloads.mjs (a job's CSV, SVG and PNG files), budget.mjs (the ray-budget panel), radii.mjs (a
// job with smaller merge radii: its table per radius and its plan to a target RMSE), sweeps.mjs and
// runs.mjs (the runs table's varying columns, the list's state in the URL, a sweep's compare page);
// this module signs in and runs them in order.

import { mkdir } from 'node:fs/promises';
import { chromium } from 'playwright-core';

import {
  STRATEGIES, allowedHttpErrors, assertNoProblems, base, callApi, check, checkPlot, outDir, passed, screenshot, signedIn, sleep,
  waitFor, watchPage,
} from './harness.mjs';
import {
  checkDirectLoad, checkInvalidSubmission, checkJobInList, checkListPage, checkNoiseTable, checkPagination, followProgress,
  submitJob,
} from './jobs.mjs';
import { checkBudget, submitNoiseJob } from './budget.mjs';
import { checkRadii, submitRadiiJob } from './radii.mjs';
import { checkDownloads } from './downloads.mjs';
import {
  checkCompare, checkFigure2, checkPaperJob, checkSolves, checkTableJobs, submitPaperPair, submitTableJobs,
} from './research.mjs';
import { checkRunsTable } from './runs.mjs';
import { checkCsv, checkPredictedSweep, checkSweepCancel, checkSweepCharts, checkSweepLinks, checkSweepSummary, openSweep } from './sweeps.mjs';

const OVERALL_TIMEOUT_MS = 240_000;

/** With a token on the server: the page asks for it, and works once it is given. */
async function signIn(page, token) {
  await page.goto(base);
  const form = page.locator('#sign-in');
  await waitFor('the sign-in banner', () => form.isVisible());
  check(/needs its access token/.test(await form.innerText()), 'a server with a token asks for it in plain words');
  await page.locator('#token-input').fill(token);
  await page.locator('#sign-in button[type="submit"]').click();
  await waitFor('the banner to go away', async () => !(await form.count()));
  signedIn();
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
  const result = await checkNoiseTable(page, id);
  await checkFigure2(page, id, result);
  await checkPlot(page, 'luminance-plot', 'luminance', STRATEGIES);
  await checkPlot(page, 'history-plot', 'RMS history', STRATEGIES);
  await screenshot(page, 'job-finished.png');
  await checkDirectLoad(page, id);
  await checkJobInList(page, id);
  await checkPagination(page);
  await screenshot(page, 'list.png');
  const pair = await submitPaperPair();
  const tableJobs = await submitTableJobs();
  const noiseJob = await submitNoiseJob();
  const radiiJob = await submitRadiiJob(page);
  const spot = await checkPaperJob(page, pair.spot);
  await checkDownloads(page, pair.spot, spot);
  await checkSolves(page, pair.spot);
  await checkTableJobs(page, tableJobs);
  await checkBudget(page, noiseJob, pair.spot);
  await checkRadii(page, radiiJob);
  await checkCompare(page, pair, [spot.result, (await callApi(`/v1/jobs/${pair.uniform}/result`)).json]);
  const sweep = await openSweep(page);
  await checkSweepSummary(page, sweep);
  await checkSweepCharts(page, sweep);
  await screenshot(page, 'sweep.png');
  await checkCsv(page, sweep);
  await checkSweepLinks(page, sweep);
  await checkRunsTable(page, sweep);
  await checkPredictedSweep(page);
  await checkSweepCancel(page);
  await sleep(500); // let late console messages arrive
  assertNoProblems();
  check(allowedHttpErrors.length === 0, 'the browser logged exactly the expected 422s (the invalid job, the refused budget)');
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
