// Screenshots a job's page in the dashboard, for the README (docs/dashboard-job.png).
//
//   node tests/browser/screenshot.mjs http://127.0.0.1:8080 1 docs/dashboard-job.png
//
// Environment: CHROMIUM = the Chromium executable (default /usr/bin/chromium); OPTIMIS_TOKEN =
// the server's bearer token, if it has one. Waits until the job's noise table is drawn.
import { chromium } from 'playwright-core';

const [base = 'http://127.0.0.1:8080', id = '1', out = 'dashboard-job.png'] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 }, deviceScaleFactor: 1 });
  if (process.env.OPTIMIS_TOKEN) {
    await page.addInitScript((token) => sessionStorage.setItem('optimis-token', token), process.env.OPTIMIS_TOKEN);
  }
  await page.goto(new URL(`/#/jobs/${id}`, base).toString());
  await page.waitForSelector('table.noise-table tbody tr', { timeout: 30_000 });
  await page.waitForSelector('.badge-final', { timeout: 30_000 });
  await page.waitForTimeout(1000); // let the charts finish their first draw
  await page.screenshot({ path: out, fullPage: true });
  console.log(`wrote ${out}`);
} finally {
  await browser.close();
}
