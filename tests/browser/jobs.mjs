// The job steps of the browser test: the empty list, an invalid and a valid submission through the
// form, the job page followed live to the end, its noise table (columns read by their data-col),
// its reload, the list's row of it, and paging through more jobs than a page holds (one a shard).

import {
  STRATEGIES, allowedHttpErrors, base, callApi, check, parseWithError, screenshot, waitFor,
} from './harness.mjs';

// Strategies with fixed per-path weights: they always have numbers (fits may fail on little data).
const PER_PATH = new Set(['plane1', 'plane2', 'plane3', 'switch', 'balance', 'power', 'correlation_aware', 'balance_planes23',
  'power_planes23', 'correlation_aware_planes23']);
// Weights fitted on one half and evaluated on the other: far off on little data (even negative).
const NOISY = new Set(['optimal_holdout']);
// Big enough to be seen running for a few seconds on two cores, small enough to finish quickly.
// The brute force, so that the job runs long enough to be watched while it runs.
const JOB = { preset: 'paper-table1', engine: 'brute', light_paths: '200000', camera_paths: '500', merge_radius: '0.02', iterations: '300' };
const SMALL_JOBS = 30; // more than one page of 25

async function fillForm(page, values) {
  const form = page.locator('form[data-ref="form"]');
  await form.locator('select[name="preset"]').selectOption(values.preset);
  if (values.engine) await form.locator('select[name="engine"]').selectOption(values.engine);
  for (const name of ['iterations', 'light_paths', 'camera_paths', 'merge_radius']) {
    await form.locator(`input[name="${name}"]`).fill(values[name]);
  }
  return form;
}

export async function checkListPage(page) {
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

export async function checkInvalidSubmission(page) {
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

export async function submitJob(page) {
  const form = await fillForm(page, JOB);
  await form.locator('button[type="submit"]').click();
  const id = await waitFor('the job page', () => /^#\/jobs\/(\d+)$/.exec(new URL(page.url()).hash)?.[1]);
  await waitFor('the job heading', () => page.locator('h1', { hasText: `Job ${id}` }).isVisible());
  check(true, `submitting the form opens the new job's page (#/jobs/${id})`);
  return id;
}

/** Reads the progress bar until the job succeeds; screenshots it once while it runs with results. */
export async function followProgress(page) {
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

/** The rows of the page's noise table: name, cells by data-col, marks, β line, the z cell's tooltip. */
export async function readNoiseRows(page) {
  return page.locator('table.noise-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy,
    recommendedRow: tr.classList.contains('recommended'),
    cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
    marks: [...tr.querySelectorAll('th span')].map((s) => s.textContent),
    betas: tr.querySelector('.betas')?.textContent ?? null,
    zTitle: tr.querySelector('td[data-col="z"]')?.title ?? null,
    optimistic: tr.querySelector('td[data-col="z"]')?.classList.contains('optimistic') ?? false,
    error: tr.querySelector('.row-error')?.textContent,
  })));
}

/** "−1.56 †" → -1.56 */
export const parseZ = (text) => Number.parseFloat(text.replace('−', '-').replace('+', ''));

/**
 * The z column: each row's z against its expected luminance at R, as the API gives it, with the
 * expectation as a tooltip; "—" with the API's reason where the row has none.
 */
export function checkZ(rows, result) {
  const api = Object.fromEntries(result.noise_table.map((r) => [r.strategy, r]));
  const shown = rows.filter((r) => !r.error);
  const withZ = shown.filter((r) => api[r.strategy].z !== null);
  check(withZ.length > 0 && withZ.every((r) => Math.abs(parseZ(r.cells.z) - api[r.strategy].z) < 0.006 && r.zTitle.startsWith('Expected at R: L·10⁵ =')),
    `every row with an expectation at R shows the API's z against it (${withZ.map((r) => `${r.strategy} ${r.cells.z}`).join(', ')})`);
  const without = shown.filter((r) => api[r.strategy].z === null);
  check(without.every((r) => r.cells.z === '—' && r.zTitle === (api[r.strategy].expected_error ?? 'No expected luminance at R for this row')),
    `the ${without.length} rows without one show — with the reason as a tooltip ("${without[0]?.zTitle.slice(0, 50)}…")`);
  check(shown.every((r) => r.optimistic === (api[r.strategy].in_sample && api[r.strategy].z !== null)),
    'a z is marked optimistic (†) only on an in-sample row that has one');
}

export async function checkNoiseTable(page, id) {
  await waitFor('the final results', async () =>
    (await page.locator('[data-ref="result-status"]').textContent()).startsWith('final'));
  const result = (await callApi(`/v1/jobs/${id}/result`)).json;
  const caption = await page.locator('[data-ref="reference"]').textContent();
  const reference = Number.parseFloat(/R → 0 \(quadrature\): L·10⁵ = ([\d.]+)/.exec(caption)?.[1]);
  check(reference > 5 && reference < 100 && Math.abs(reference - result.reference_luminance * 1e5) < 0.006,
    `the z caption keeps the quadrature reference R → 0, L·10⁵ = ${reference}, as a second figure`);
  check(caption.includes(`expected luminance at the job's R = ${JOB.merge_radius}`),
    `the z caption says z is taken against the expectation at the job's R ("${caption.slice(0, 90)}…")`);
  const rows = await readNoiseRows(page);
  const order = result.noise_table.map((r) => r.strategy);
  check(JSON.stringify(rows.map((r) => r.strategy)) === JSON.stringify(order) && JSON.stringify(order) === JSON.stringify(STRATEGIES),
    `the noise table has the API's ${order.length} strategies in order, the planes-2–3 heuristics, the stacked and corrected rows among them`);
  const api = Object.fromEntries(result.noise_table.map((r) => [r.strategy, r]));
  for (const row of rows) {
    check(row.cells.weights.length > 0, `${row.strategy}: its weights are described ("${row.cells.weights.slice(0, 70)}")`);
    if (row.error) {
      check(!PER_PATH.has(row.strategy), `${row.strategy}: shows its fit error instead of numbers ("${row.error.slice(0, 60)}…")`);
      continue;
    }
    const [luminance, luminanceError] = parseWithError(row.cells.luminance);
    const [rms] = parseWithError(row.cells.rms);
    const plausible = NOISY.has(row.strategy) || api[row.strategy].unstable
      ? Number.isFinite(luminance) && Number.isFinite(rms)
      : luminance > 5 && luminance < 100 && luminanceError > 0 && rms > 0;
    check(plausible, `${row.strategy}: L·10⁵ = ${row.cells.luminance}, RMS % = ${row.cells.rms}`);
  }
  const numbers = rows.filter((r) => !r.error);
  const withSe = numbers.filter((r) => parseWithError(r.cells.rms)[1] !== null).map((r) => r.strategy);
  check(withSe.join() === numbers.filter((r) => api[r.strategy].rms_percent_stderr !== null).map((r) => r.strategy).join()
    && withSe.includes('optimal_cv') && withSe.includes('optimal_stacked'),
  `RMS carries ± its SE exactly where the API has one, fitted rows too (all but ${numbers.filter((r) => !withSe.includes(r.strategy)).map((r) => r.strategy).join(', ')})`);
  const stacked = rows.filter((r) => api[r.strategy].heuristics.length > 0);
  check(stacked.length > 0 && rows.every((r) => (r.betas !== null) === stacked.includes(r))
    && stacked.every((r) => api[r.strategy].heuristics.every((b) => r.betas.includes(`${b.strategy} `))),
  `the stacked and corrected rows, and only they, name β of each heuristic under their weights (${stacked[0]?.betas})`);
  checkZ(rows, result);
  const marked = (m) => rows.filter((r) => r.marks.includes(m)).map((r) => r.strategy);
  check(marked('in-sample').join() === 'optimal', 'only the paper\'s optimal row is marked in-sample');
  check(marked('unstable').join() === result.noise_table.filter((r) => r.unstable).map((r) => r.strategy).join(),
    `the unstable rows are marked (${marked('unstable').join(', ') || 'none'})`);
  check(marked('tail missing').join() === result.noise_table.filter((r) => r.tail_missing).map((r) => r.strategy).join(),
    `the rows missing their tail are marked (${marked('tail missing').join(', ') || 'none'})`);
  check(marked('beyond trust region').join() === result.noise_table.filter((r) => r.beyond_trust_region).map((r) => r.strategy).join(),
    `the rows beyond the trust region are marked (${marked('beyond trust region').join(', ') || 'none'})`);
  const recommended = result.recommended.strategy;
  check(marked('recommended').join() === recommended && rows.filter((r) => r.recommendedRow).map((r) => r.strategy).join() === recommended,
    `the row the API recommends, ${recommended}, is marked and highlighted, and no other`);
  const outside = marked('outside fixed weights');
  check(outside.join() === 'plane1,balance,power,correlation_aware',
    `the rows that merge at the pixel are marked outside the fixed weights w0 = 0 (${outside.join(', ')})`);
  check(!outside.includes(recommended), 'no row outside the fixed weights is recommended');
  const reason = await page.locator('[data-ref="recommended-note"]').textContent();
  check(reason.startsWith(`Recommended: ${recommended}`) && reason.includes(result.recommended.reason),
    `the reason is shown under the table ("${reason.slice(0, 110)}…")`);
  const gain = await page.locator('[data-ref="gain"]').textContent();
  check(gain.includes('variance ratio') && gain.includes(result.gain.versus), `the gain is shown ("${gain.slice(0, 80)}…")`);
  const warnings = await page.locator('[data-ref="warnings"] li code').allTextContents();
  check(warnings.length > 0 && warnings.every((w) => /^[a-z_]+$/.test(w)),
    `the result's warnings are listed by code (${warnings.join(', ')})`);
  const describes = Object.fromEntries(rows.map((r) => [r.strategy, r.cells.weights]));
  check(describes.plane1 === 'w₀ = 1' && describes.switch.includes('r₃ ≤ a') && describes.optimal.includes('w₀ = 0')
    && describes.optimal_cv.includes('cross-validation') && describes.power_planes23.includes('planes 2–3')
    && describes.optimal_stacked.includes('Σ β') && describes.switch_corrected.includes('corrected by a table'),
  'the weights column reads like the paper, and says what the new rows are');
  const cases = Object.fromEntries(rows.map((r) => [r.strategy, r.cells.case]));
  check(['plane1', 'plane2', 'plane3', 'switch', 'optimal'].every((s, i) => cases[s] === String(i + 1)) && cases.optimal_cv === '',
    'the paper\'s case numbers 1–5 label plane1, plane2, plane3, switch, optimal');
  const note = await page.locator('[data-ref="paper-note"]').textContent();
  const paperCells = await page.locator('table.noise-table .paper-col:visible').count();
  check(note.startsWith('Paper values apply to the paper-table1 configuration only') && note.includes('light_paths') && paperCells === 0,
    `this job is not the paper's configuration: no paper column, and "${note}"`);
  return result;
}

/** A job page opened directly (bookmark, reload) rather than from the list. */
export async function checkDirectLoad(page, id) {
  await page.reload();
  await waitFor('the reloaded job page', async () =>
    (await page.locator('h1', { hasText: `Job ${id}` }).isVisible())
    && (await page.locator('table.noise-table tbody tr').count()) === STRATEGIES.length);
  check(true, `reloading #/jobs/${id} shows the job and its ${STRATEGIES.length} rows again`);
}

export async function checkJobInList(page, id) {
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
export async function checkPagination(page) {
  for (let i = 0; i < SMALL_JOBS; i += 1) {
    // The last one is the second shard of a 2-iteration study: the list says so.
    const shard = i === SMALL_JOBS - 1 ? { iterations: 2, shard: { index: 1, count: 2 } } : {};
    const response = await callApi('/v1/jobs', {
      method: 'POST',
      body: {
        light_paths: 20000, camera_paths: 200, merge_radius: 0.02, iterations: 1, seed: i + 1, ...shard,
        name: `small job ${i + 1}`, labels: { batch: (i + 1) % 2 === 0 ? 'even' : 'odd' },
      },
    });
    if (response.status !== 202) throw new Error(`submitting small job ${i + 1} answered ${response.status}`);
  }
  const rowCount = () => page.locator('table.jobs-table tbody tr').count();
  const newest = page.locator('table.jobs-table tbody tr').first();
  // 25 rows can show before the list has caught up with the last submissions: wait for the newest.
  await waitFor('a full first page with the newest job', async () => (await rowCount()) === 25
    && (await newest.locator('td[data-col="seed"]').textContent()) === String(SMALL_JOBS), 10_000);
  check(true, 'the list shows 25 jobs on its first page');
  const kind = await newest.locator('[data-kind]').allTextContents();
  const seed = await newest.locator('td[data-col="seed"]').textContent();
  const sizes = await newest.locator('td[data-col="light_paths"], td[data-col="camera_paths"]').allTextContents();
  check(kind.join() === 'shard 2/2' && seed === String(SMALL_JOBS) && sizes.join() === '20,000,200',
    `the newest row reads as a shard ("${kind.join()}") with its N_F, N_B (${sizes.join(', ')}) and seed ${seed}`);
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
  const name = await newest.locator('[data-col="name"]').textContent();
  check(name === `small job ${SMALL_JOBS}`, `a job's name heads its row ("${name}")`);

  // Labels: the label filter lists only the jobs with that label, as the API does; a label chip
  // filters by itself.
  const evens = Math.floor(SMALL_JOBS / 2);
  const fromApi = (await callApi('/v1/jobs?label=batch%3Deven&limit=100')).json.jobs;
  check(fromApi.length === evens && fromApi.every((j) => j.spec.labels.batch === 'even'),
    `GET /v1/jobs?label=batch=even lists the ${fromApi.length} jobs with an even seed`);
  const filter = page.locator('input[data-ref="label-filter"]');
  await filter.fill('batch=even');
  await filter.press('Enter');
  await waitFor('the list filtered by label', async () => (await rowCount()) === evens);
  const seeds = (await page.locator('table.jobs-table tbody td[data-col="seed"]').allTextContents()).map(Number);
  check(seeds.every((seed) => seed % 2 === 0), `the label filter "batch=even" lists the ${seeds.length} jobs with an even seed`);
  await filter.fill('');
  await filter.press('Enter');
  await waitFor('the unfiltered list', async () => (await rowCount()) === 25);
  await newest.locator('button.label-chip').click();
  await waitFor('the list filtered by a label chip', async () => (await rowCount()) === evens
    && (await filter.inputValue()) === 'batch=even');
  check(true, 'clicking the chip "batch=even" filters the list by it');
  await filter.fill('');
  await filter.press('Enter');
  await waitFor('the unfiltered list', async () => (await rowCount()) === 25);
}
