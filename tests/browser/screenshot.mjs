// Screenshots a job's or a sweep's page in the dashboard, for the README (docs/dashboard-job.png,
// docs/dashboard-sweep.png).
//
//   node tests/browser/screenshot.mjs http://127.0.0.1:8080 1 docs/dashboard-job.png
//   node tests/browser/screenshot.mjs http://127.0.0.1:8080 sweeps/1 docs/dashboard-sweep.png
//
// Environment: CHROMIUM = the Chromium executable (default /usr/bin/chromium); OPTIMIS_TOKEN =
// the server's bearer token, if it has one. Waits until the job's noise table (a sweep's charts)
// are drawn and the run is final.
import { chromium } from 'playwright-core';

const [base = 'http://127.0.0.1:8080', target = '1', out = 'dashboard-job.png'] = process.argv.slice(2);
const sweep = target.startsWith('sweeps/');
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 }, deviceScaleFactor: 1 });
  if (process.env.OPTIMIS_TOKEN) {
    await page.addInitScript((token) => sessionStorage.setItem('optimis-token', token), process.env.OPTIMIS_TOKEN);
  }
  await page.goto(new URL(sweep ? `/#/${target}` : `/#/jobs/${target}`, base).toString());
  if (sweep) {
    await page.waitForSelector('[data-ref="state"] .badge-succeeded', { timeout: 30_000 });
    await page.waitForSelector('[data-ref="w1-grid"] canvas', { timeout: 30_000 });
  } else {
    await page.waitForSelector('table.noise-table tbody tr', { timeout: 30_000 });
    await page.waitForSelector('.badge-final', { timeout: 30_000 });
  }
  await page.waitForTimeout(1000); // let the charts finish their first draw
  await page.mouse.move(0, 0); // no cursor on a chart: its legend reads as a key
  await page.screenshot({ path: out, fullPage: true });
  console.log(`wrote ${out}`);
} finally {
  await browser.close();
}
