// The ray-budget steps of the browser test: a paper job run with noise components (1,000
// iterations of the restricted engine), its page's budget panel asked for a plan with the costs it
// fills in, read against the API's own plan for the same request — the headline (strategy, best
// (N_F, N_B), speed-up ± SE, its warnings: the server's note, the edge of the search, a partial
// run), every strategy's row with its SEs, ranked only where it keeps the fixed weights, the
// paper's configuration last —, its JSON download, its refusals (a non-number before asking, the
// server's 422 naming the field, as the submit form shows them), and a job without noise
// components, whose panel says how to get one.

import { allowedHttpErrors, base, callApi, check, parseWithError, waitFor } from './harness.mjs';
import { downloadFrom } from './files.mjs';

const NOISE_JOB = { preset: 'paper-table1', iterations: 1000, noise_components: true };
// The panel's fields as it fills them in (budget.js): its costs left blank, the reference's — the
// request the API is asked for beside it, and the plan `optimis budget` prints by default.
const REQUEST = { target_rms: 1, pixels: 1e6 };

const SUPERSCRIPT = { '⁻': '-', '⁰': '0', '¹': '1', '²': '2', '³': '3', '⁴': '4', '⁵': '5', '⁶': '6', '⁷': '7', '⁸': '8', '⁹': '9' };
/** "3.16·10⁸" → 3.16e8, "10⁷" → 1e7, "1,000" → 1000. */
export function parseScientific(text) {
  const m = /^(?:([\d.,−-]+)·)?10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)$/.exec(text.trim());
  if (!m) return Number(text.replace(/,/g, '').replace('−', '-'));
  const exponent = Number([...m[2]].map((c) => SUPERSCRIPT[c]).join(''));
  return Number((m[1] ?? '1').replace(/,/g, '').replace('−', '-')) * 10 ** exponent;
}
/** Whether `shown` (3 significant digits) is `value`. */
const near = (shown, value) => Math.abs(shown - value) <= 0.006 * Math.abs(value);

/** Submits the noise-components job through the API; its id (it runs while other steps go on). */
export async function submitNoiseJob() {
  const response = await callApi('/v1/jobs', { method: 'POST', body: NOISE_JOB });
  if (response.status !== 202) throw new Error(`submitting ${JSON.stringify(NOISE_JOB)} answered ${response.status}`);
  return response.json.id;
}

/** The budget panel of job `id` (run with noise components) and of job `plain` (run without). */
export async function checkBudget(page, id, plain) {
  await waitFor('the noise-components job to succeed', async () => (await callApi(`/v1/jobs/${id}`)).json.state === 'succeeded', 120_000);
  await page.goto(`${base}/#/jobs/${id}`);
  const panel = page.locator('[data-ref="budget"]');
  const button = panel.getByRole('button', { name: 'Plan the budget' });
  await waitFor('the budget panel', async () => (await button.isVisible()) && (await button.isEnabled()));
  check(await panel.locator('[data-ref="budget-unavailable"]').isHidden(), `job ${id}, run with noise components, has a budget form`);
  await button.click();
  const headline = panel.locator('[data-ref="budget-headline"]');
  await waitFor('the plan', () => headline.isVisible(), 60_000);
  const plan = (await callApi(`/v1/jobs/${id}/budget`, { method: 'POST', body: REQUEST })).json;
  const best = plan.best.find((b) => b.strategy === plan.headline);
  const text = await headline.textContent();
  const budget = (await panel.locator('[data-ref="budget-best"]').textContent()).match(/N_F = (.+), N_B = (.+)/);
  check(await headline.getAttribute('data-strategy') === plan.headline && text.includes(`${plan.headline} `)
    && near(parseScientific(budget[1]), best.budget.light_paths) && near(parseScientific(budget[2]), best.budget.camera_paths),
  `the headline is the plan's: ${plan.headline} at N_F = ${budget[1]}, N_B = ${budget[2]} ("${text.slice(0, 90)}…")`);
  const [speedup, speedupSe] = parseWithError((await panel.locator('[data-ref="budget-speedup"]').textContent()).replace(/×.*/, ''));
  check(Math.abs(speedup - best.speedup) <= 0.006 * best.speedup + 0.006 && Math.abs(speedupSe - best.speedup_stderr) <= 0.006 * best.speedup_stderr + 0.006
    && text.includes("than the paper's switch at (10⁷, 100)"),
  `it gives the speed-up over the paper's switch at (10⁷, 100) with its SE: ${speedup} ± ${speedupSe}× (API ${best.speedup.toFixed(3)} ± ${best.speedup_stderr.toFixed(3)})`);
  const fastest = plan.best.find((b) => b.respects_fixed);
  const fastestLine = panel.locator('[data-ref="budget-fastest"]');
  check(fastest.strategy === plan.headline ? (await fastestLine.count()) === 0
    : (await fastestLine.getAttribute('data-strategy')) === fastest.strategy,
  fastest.strategy === plan.headline ? 'the headline is also the fastest ranked strategy'
    : `the fastest ranked strategy, ${fastest.strategy}, is named beside the headline ("${(await fastestLine.textContent()).slice(0, 80)}…")`);
  const warnings = await panel.locator('[data-ref="budget-warnings"] li').evaluateAll((lis) => Object.fromEntries(lis.map((li) => [li.dataset.warning, li.textContent])));
  check(Boolean(warnings.headline) === Boolean(plan.headline_note) && (!plan.headline_note || warnings.headline.includes(plan.headline_note)),
    plan.headline_note ? `the server's note on the headline is shown ("${plan.headline_note.slice(0, 60)}…")` : 'the server has no note on the headline, and none is shown');
  check(Boolean(warnings.edge) === best.at_edge && (!best.at_edge || /searched/.test(warnings.edge)),
    best.at_edge ? `the headline's budget lies on the edge of the search, and the panel says which ("${warnings.edge.slice(0, 70)}…")` : 'the headline\'s budget is inside the searched range: no edge warning');
  const unsupported = !best.supported || best.faster_unsupported;
  check(Boolean(warnings.unsupported) === unsupported && (!unsupported || warnings.unsupported.includes(`${100 * plan.support_relative_se} % of the RMS`)),
    unsupported ? `the run's noise left ${best.supported ? 'faster budgets' : 'every budget'} of the headline unsupported, and the panel says so ("${warnings.unsupported.slice(0, 70)}…")`
      : 'every faster budget of the headline is supported by the run: no support warning');
  check(!warnings.partial && !plan.partial, 'a finished job\'s plan carries no partial-run warning');

  const rows = await panel.locator('table.budget-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy, ranked: tr.dataset.ranked, edge: tr.dataset.atEdge, headline: tr.classList.contains('recommended'),
    marks: [...tr.querySelectorAll('th span')].map((s) => s.textContent),
    cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
  })));
  check(rows.length === plan.best.length + 1 && rows.slice(0, -1).map((r) => r.strategy).join() === plan.best.map((b) => b.strategy).join()
    && rows.at(-1).strategy === 'paper', `the table has the plan's ${plan.best.length} strategies in its order, then the paper's configuration`);
  let rank = 0;
  const agree = plan.best.every((b, k) => {
    const row = rows[k];
    if (b.respects_fixed) rank += 1;
    const [rms, rmsSe] = parseWithError(row.cells.rms);
    return row.cells.rank === (b.respects_fixed ? String(rank) : '—')
      && row.marks.includes('outside fixed weights, not ranked') === !b.respects_fixed
      && row.marks.includes('at edge') === b.at_edge && row.marks.includes('not supported') === !b.supported
      && row.headline === (b.strategy === plan.headline)
      && near(parseScientific(row.cells.light_paths), b.budget.light_paths) && near(parseScientific(row.cells.camera_paths), b.budget.camera_paths)
      && Math.abs(rms - b.rms_percent) < 0.06 && (b.rms_percent_stderr === null ? rmsSe === null : Math.abs(rmsSe - b.rms_percent_stderr) < 0.06)
      && near(parseScientific(row.cells.seconds_to_target), b.seconds_to_target);
  });
  const outside = plan.best.filter((b) => !b.respects_fixed).map((b) => b.strategy);
  check(agree && outside.length > 0, `each row is the API's: rank among those that keep the fixed weights, N_F, N_B, RMS ± SE, time, the support mark; ${outside.join(', ')} marked outside the fixed weights, not ranked`);
  const paper = rows.at(-1);
  check(near(parseScientific(paper.cells.seconds_to_target), plan.paper.seconds_to_target) && paper.cells.speedup === '1×',
    `the paper's switch at (10⁷, 100) closes the table (${paper.cells.seconds_to_target} s to ${REQUEST.target_rms} %)`);
  const search = await panel.locator('[data-ref="budget-search"]').textContent();
  check(search.includes('half-decade steps') && search.includes('t_F = 7.3·10⁻⁹ s') && search.includes('the reference costs') && plan.costs.source === 'reference',
    `the panel says what was searched and with which costs, the reference's ("${search.slice(0, 80)}…")`);
  const placeholder = await panel.locator('input[name="light_cost"]').getAttribute('placeholder');
  check(placeholder === 'reference 7.3·10⁻⁹', `a blank cost says which reference value it took ("${placeholder}")`);
  const json = await downloadFrom(page, panel.getByRole('button', { name: 'Plan (JSON)' }));
  const saved = JSON.parse(json.bytes.toString('utf8'));
  check(json.name === `optimis-job-${id}-budget.json` && saved.job_id === id && JSON.stringify(saved.best) === JSON.stringify(plan.best),
    `"Plan (JSON)" saves ${json.name}, the API's plan`);

  // Refusals: a field that is not a number is named before anything is sent; one the server
  // refuses (422) is named by the problem's `field`, the input marked, as the submit form does.
  const target = panel.locator('input[name="target_rms"]');
  await target.fill('one');
  await button.click();
  const error = panel.locator('[data-ref="budget-error"]');
  await waitFor('the form error', () => error.isVisible());
  check((await error.textContent()).startsWith('target_rms: “one” is not a number') && await target.getAttribute('aria-invalid') === 'true',
    `a target that is not a number is refused in the page ("${await error.textContent()}")`);
  allowedHttpErrors.push({ status: 422, path: `/v1/jobs/${id}/budget` });
  await target.fill('0');
  await button.click();
  await waitFor('the server\'s refusal', async () => (await error.textContent()).includes('positive percentage'));
  check((await error.textContent()).startsWith('target_rms: must be a positive percentage') && await target.getAttribute('aria-invalid') === 'true'
    && (await panel.locator('[data-ref="budget-result"]').textContent()) === '',
  `a target of 0 % is refused by the server (422), the field named and marked, the old plan cleared ("${await error.textContent()}")`);
  await target.fill('1');

  await page.goto(`${base}/#/jobs/${plain}`);
  const note = page.locator('[data-ref="budget-unavailable"]');
  await waitFor('the plain job\'s budget panel', () => note.isVisible());
  check((await note.textContent()).includes('"noise_components": true') && await page.locator('[data-ref="budget-form"]').isHidden(),
    `a job without noise components (#${plain}) has no budget form, and says how to run one ("${(await note.textContent()).slice(0, 70)}…")`);
}
