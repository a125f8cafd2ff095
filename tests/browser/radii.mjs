// The merge-radii steps of the browser test (issue 44): a small job submitted through the form with
// smaller radii R′ (its radii field, refused in the page when an entry is not a number) and noise
// components; its page's table at each radius (RMS ± SE and bias ± error per strategy, read against
// the result's `radii`); and its budget panel asked for a target RMSE of 1 %, whose error plan —
// the fastest (strategy, R′, N_F, N_B) with its time ± SE, the best at the job's own R and the
// speed-up over it ± SE, the paper's setup (not tallied here, so not predicted: the plan's note),
// the progressive row, the strategies out of reach, every candidate — is read against the API's plan
// for the same request; then a cost per merge, sent and used.

import { base, callApi, check, parseWithError, waitFor } from './harness.mjs';
import { parseScientific } from './budget.mjs';

// Finishes in about two seconds (restricted engine, 3,000 iterations at N_F = 10⁶, N_B = 20).
const FORM = { preset: 'paper-table1', engine: 'restricted', iterations: '3000', light_paths: '1000000', camera_paths: '20', merge_radius: '0.02' };
const RADII = [0.005, 0.01];
const RADII_TEXT = '0.005, 0.01';
const ALL_RADII = ['0.005', '0.01', '0.02'];

const SUPERSCRIPT = { '⁻': '-', '⁰': '0', '¹': '1', '²': '2', '³': '3', '⁴': '4', '⁵': '5', '⁶': '6', '⁷': '7', '⁸': '8', '⁹': '9' };
/** "(4.06 ± 0.476)·10⁵" → [4.06e5, 4.76e4]; "0.0118 ± 2·10⁻⁵" → [0.0118, 2e-5]; "3.3" → [3.3, null]. */
export function parseScientificWithError(text) {
  const t = text.trim();
  const m = /^\((.+) ± (.+)\)·10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)$/.exec(t);
  if (m) {
    const power = 10 ** Number([...m[3]].map((c) => SUPERSCRIPT[c]).join(''));
    return [parseScientific(m[1]) * power, parseScientific(m[2]) * power];
  }
  const [value, error] = t.split(' ± ');
  return [parseScientific(value), error === undefined ? null : parseScientific(error)];
}
/** Whether `shown` (3 significant digits) is `value`. */
const near = (shown, value) => Math.abs(shown - value) <= 0.006 * Math.abs(value) + 1e-12;
/** Whether a shown value ± error is the API's (either error absent in both). */
const nearWithError = ([v, e], value, error) => near(v, value) && (error === null || error === undefined ? e === null : near(e, error));
/** RMS % as the page prints it (two decimals below 10, one above). */
const nearRms = (shown, value) => Math.abs(shown - value) < 0.06;

/** Submits the radii job through the form (after a refused radii entry); its id. */
export async function submitRadiiJob(page) {
  await page.goto(`${base}/#/`);
  const form = page.locator('form[data-ref="form"]');
  await waitFor('the submit form', () => form.isVisible());
  await form.locator('select[name="preset"]').selectOption(FORM.preset);
  await form.locator('select[name="engine"]').selectOption(FORM.engine);
  for (const [name, value] of Object.entries(FORM)) {
    if (name !== 'preset' && name !== 'engine') await form.locator(`input[name="${name}"]`).fill(value);
  }
  await form.locator('textarea[name="extra"]').fill('{"noise_components": true}');
  const radii = form.locator('input[name="radii"]');
  await radii.fill('0.005, x');
  await form.locator('button[type="submit"]').click();
  const message = await waitFor('the form error', async () => (await page.locator('#form-error').isVisible()) && page.locator('#form-error').textContent());
  check(message.startsWith('radii: “x” is not a number') && await radii.getAttribute('aria-invalid') === 'true' && new URL(page.url()).hash === '#/',
    `a radii entry that is not a number is refused in the page, the field marked ("${message.slice(0, 60)}…")`);
  await radii.fill(RADII_TEXT);
  await form.locator('button[type="submit"]').click();
  const id = await waitFor('the radii job\'s page', () => /^#\/jobs\/(\d+)$/.exec(new URL(page.url()).hash)?.[1]);
  const { spec } = (await callApi(`/v1/jobs/${id}`)).json;
  check(JSON.stringify(spec.radii) === JSON.stringify(RADII) && spec.noise_components === true && spec.merge_radius === 0.02,
    `the form's radii field "${RADII_TEXT}" is sent as the JSON array ${JSON.stringify(spec.radii)} (job ${id}, R = ${spec.merge_radius}, noise components)`);
  return id;
}

/** The radii job's page: its spec, its table at each radius, its error plan. */
export async function checkRadii(page, id) {
  const started = Date.now();
  await waitFor('the radii job to succeed', async () => (await callApi(`/v1/jobs/${id}`)).json.state === 'succeeded', 60_000);
  console.log(`   the radii job finished ${((Date.now() - started) / 1000).toFixed(1)} s after its check began`);
  await page.goto(`${base}/#/jobs/${id}`);
  const field = page.locator('dl[data-ref="spec"] [data-field="radii"] dd');
  await waitFor('the spec', () => field.isVisible());
  check(await field.textContent() === RADII_TEXT, `the job page lists its radii R′: ${await field.textContent()}`);
  await checkRadiusTable(page, id);
  await checkErrorPlan(page, id);
}

async function checkRadiusTable(page, id) {
  const section = page.locator('[data-ref="radii-table"]');
  await waitFor('the table at each radius', () => section.isVisible(), 30_000);
  const result = (await callApi(`/v1/jobs/${id}/result`)).json;
  const shown = await section.locator('details').evaluateAll((ds) => ds.map((d) => ({
    radius: d.dataset.radius, own: d.dataset.own, open: d.open, summary: d.querySelector('summary').textContent,
    rows: [...d.querySelectorAll('tbody tr')].map((tr) => ({
      strategy: tr.dataset.strategy, recommended: tr.classList.contains('recommended'),
      cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
    })),
  })));
  check(shown.map((d) => d.radius).join() === ALL_RADII.join() && result.radii.map((r) => String(r.merge_radius)).join() === ALL_RADII.join()
    && shown.every((d, k) => d.summary.startsWith(`R′ = ${ALL_RADII[k]}`) && (d.own === 'true') === (k === 2) && d.open === (k === 2))
    && shown[2].summary.includes("the job's own R"),
  `the job page has a table per radius, ascending, the job's own R last and open: ${shown.map((d) => d.summary.split(' — ')[0]).join(' · ')}`);
  let compared = 0;
  const agree = result.radii.every((report, k) => {
    const rows = shown[k].rows;
    const merges = /merges per iteration \(planes 1 · 2 · 3\): (.+?)(?: — |$)/.exec(shown[k].summary)?.[1].split(' · ').map(parseScientific) ?? [];
    return merges.length === 3 && merges.every((m, i) => near(m, report.merges_per_iteration[i])) && rows.length === report.rows.length && report.rows.every((r, i) => {
      const row = rows[i];
      const [rms, rmsSe] = parseWithError(row.cells.rms);
      const [bias, biasErr] = parseScientificWithError(row.cells.bias);
      compared += 1;
      return row.strategy === r.strategy && row.recommended === (r.strategy === report.recommended)
        && nearRms(rms, r.rms_percent) && nearRms(rmsSe, r.rms_percent_stderr)
        && nearWithError([bias, biasErr], r.bias_percent, r.bias_percent_stderr)
        && row.cells.bias_source === { quadrature: 'quad.', monte_carlo: 'MC' }[r.bias_source];
    });
  });
  const sample = shown[0].rows.find((r) => r.strategy === 'switch');
  check(agree && compared >= 3 * 10, `each radius's rows are the API's: RMS % ± SE, bias % ± error and its source, the recommended row marked (${compared} rows; switch at R′ = 0.005: RMS ${sample.cells.rms} %, bias ${sample.cells.bias} %, ${sample.cells.bias_source})`);
  const biases = result.radii.map((r) => r.rows.find((x) => x.strategy === 'switch').bias_percent);
  check(biases[0] < biases[1] && biases[1] < biases[2], `the switch's bias grows with the radius, as shown: ${shown.map((d) => d.rows.find((r) => r.strategy === 'switch').cells.bias).join(' < ')} %`);
}

/** The plan's figures of one point's paragraph (errorplan.js's pointWords). */
async function readPoint(locator) {
  const text = await locator.textContent();
  const budget = (await locator.locator('[data-ref="error-budget"]').textContent()).match(/N_F = (.+), N_B = (.+)/);
  const secondsText = await locator.locator('[data-ref="error-seconds"]').textContent();
  const [seconds, secondsSe] = parseScientificWithError(secondsText.replace(/ s( \(.*\))?$/, ''));
  return {
    text, strategy: await locator.getAttribute('data-strategy'), radius: await locator.getAttribute('data-radius'),
    light: parseScientific(budget[1]), camera: parseScientific(budget[2]), seconds, secondsSe, secondsText,
  };
}

const samePoint = (shown, p) => shown.strategy === p.strategy && shown.radius === String(p.merge_radius)
  && near(shown.light, p.budget.light_paths) && near(shown.camera, p.budget.camera_paths)
  && nearWithError([shown.seconds, shown.secondsSe], p.seconds_to_target, p.seconds_to_target_stderr)
  && shown.text.includes(`R′ = ${p.merge_radius}`);

/** Asks the radii job's budget panel for a target RMSE and checks the error plan against the API's. */
async function checkErrorPlan(page, id) {
  const panel = page.locator('[data-ref="budget"]');
  const button = panel.getByRole('button', { name: 'Plan the budget' });
  await waitFor('the budget panel', async () => (await button.isVisible()) && (await button.isEnabled()));
  const mergeCost = panel.locator('input[name="merge_cost"]');
  check(await panel.locator('input[name="target_rmse"]').inputValue() === '' && await mergeCost.getAttribute('placeholder') === 'reference',
    'the budget panel has a target RMSE (blank: no error plan) and a cost per merge (blank: the reference\'s)');
  await panel.locator('input[name="target_rmse"]').fill('1');
  const plan = await requestPlan(page, button);
  check(JSON.stringify(plan.body) === JSON.stringify({ target_rms: 1, target_rmse: 1, pixels: 1e6 }),
    `a target RMSE of 1 % is sent as target_rmse, no merge_cost while its field is blank (${JSON.stringify(plan.body)})`);
  const section = panel.locator('[data-ref="error-plan"]');
  await waitFor('the error plan', () => section.isVisible(), 60_000);
  const ep = (await callApi(`/v1/jobs/${id}/budget`, { method: 'POST', body: plan.body })).json.error_plan;
  check(await mergeCost.getAttribute('placeholder') === 'reference 8·10⁻⁸' && ep.costs.merge === 8e-8,
    `the blank cost per merge says which reference value it took ("${await mergeCost.getAttribute('placeholder')}")`);
  check((await section.locator('h3').textContent()).includes(`over R′ ∈ {${ALL_RADII.join(', ')}}`) && ep.radii.map(String).join() === ALL_RADII.join(),
    `the plan covers the job's radii and its own R: "${await section.locator('h3').textContent()}"`);

  const best = await readPoint(section.locator('[data-ref="error-best"]'));
  check(ep.best !== null && ALL_RADII.includes(best.radius) && samePoint(best, ep.best) && best.text.startsWith('Predicted fastest:')
    && ep.best.seconds_to_target_stderr > 0 && best.secondsSe > 0 && /\d/.test(best.secondsText),
  `the predicted fastest point is the API's: ${best.strategy} at R′ = ${best.radius}, N_F = ${best.light}, N_B = ${best.camera}, ${best.secondsText} (API ${ep.best.seconds_to_target.toPrecision(3)} ± ${ep.best.seconds_to_target_stderr.toPrecision(3)} s)`);
  const [rms, rmsSe] = parseWithError(/RMS (.+?) % per iteration/.exec(best.text)[1]);
  const [bias, biasErr] = parseScientificWithError(/bias (.+?) %\)/.exec(best.text)[1]);
  check(nearRms(rms, ep.best.rms_percent) && nearRms(rmsSe, ep.best.rms_percent_stderr) && nearWithError([bias, biasErr], ep.best.bias_percent, ep.best.bias_percent_stderr),
    `with its RMS per iteration ${rms} ± ${rmsSe} % and its bias ${bias} ± ${biasErr} % at that radius`);

  const own = await readPoint(section.locator('[data-ref="error-own"]'));
  const [speedup, speedupSe] = parseWithError((await section.locator('[data-ref="error-speedup-own"]').textContent()).replace('×', ''));
  check(own.radius === '0.02' && samePoint(own, ep.at_own_radius)
    && Math.abs(speedup - ep.speedup_over_own_radius) <= 0.006 * ep.speedup_over_own_radius + 0.006
    && Math.abs(speedupSe - ep.speedup_over_own_radius_stderr) <= 0.006 * ep.speedup_over_own_radius_stderr + 0.006,
  `the best at the job's own R = 0.02 is the API's (${own.strategy}, ${own.secondsText}), the fastest ${speedup} ± ${speedupSe}× sooner (API ${ep.speedup_over_own_radius.toFixed(2)} ± ${ep.speedup_over_own_radius_stderr.toFixed(2)})`);
  const paper = await section.locator('[data-ref="error-paper"]').textContent();
  const notes = await section.locator('[data-ref="error-notes"] li').allTextContents();
  check(ep.paper === null && ep.speedup_over_paper === null && paper.includes('not predicted') && paper.includes('R = 0.003')
    && (await section.locator('[data-ref="error-speedup-paper"]').count()) === 0
    && notes.length === ep.notes.length && ep.notes.every((n, k) => notes[k].includes(n)) && ep.notes.some((n) => n.includes('0.003')),
  `without R = 0.003 among the radii the paper's setup is not predicted and no speed-up over it is shown; the plan's ${ep.notes.length} note(s) are ("${notes[0]?.slice(0, 60)}…")`);

  const progressive = section.locator('[data-ref="error-progressive"]');
  const pText = await progressive.textContent();
  const p = ep.progressive;
  let progressiveOk = p !== null && await progressive.getAttribute('data-strategy') === p.strategy
    && await progressive.getAttribute('data-first-radius') === String(p.first_radius) && await progressive.getAttribute('data-last-radius') === String(p.last_radius)
    && pText.includes(`R′ from ${p.first_radius} down to ${p.last_radius}`) && pText.includes('predicted') && pText.includes('held at the smallest radius') === p.floored;
  if (p?.seconds_to_target != null) {
    const [s, se] = parseScientificWithError((await progressive.locator('[data-ref="error-progressive-seconds"]').textContent()).replace(/ s( \(.*\))?$/, ''));
    progressiveOk &&= nearWithError([s, se], p.seconds_to_target, p.seconds_to_target_stderr);
  } else {
    progressiveOk &&= pText.includes('does not reach 1 % within 10¹² iterations');
  }
  check(progressiveOk, `the progressive row is the API's: "${pText.slice(0, 150)}…"`);

  const reach = await section.locator('[data-ref="error-out-of-reach"] li').evaluateAll((lis) => lis.map((li) => ({ radius: li.dataset.radius, text: li.textContent })));
  const reachOk = ep.out_of_reach.length > 0 && ep.out_of_reach.every((o) => {
    const li = reach.find((r) => r.radius === String(o.merge_radius));
    const shownBias = li && new RegExp(`(?:^|[\\s,:])${o.strategy} \\(bias (\\S+) %\\)`).exec(li.text)?.[1];
    return shownBias !== undefined && near(parseScientific(shownBias), o.bias_percent);
  }) && reach.every((li) => ep.out_of_reach.some((o) => String(o.merge_radius) === li.radius));
  check(reachOk, `the ${ep.out_of_reach.length} (strategy, R′) whose bias alone reaches 1 % are listed as out of reach with their bias (${reach[0]?.text.slice(0, 70)}…)`);

  const rows = await section.locator('table.error-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    strategy: tr.dataset.strategy, radius: tr.dataset.radius, best: tr.classList.contains('recommended'),
    marks: [...tr.querySelectorAll('th span')].map((s) => s.textContent),
    cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
  })));
  const candidatesOk = rows.length === ep.candidates.length && ep.candidates.every((c, k) => {
    const row = rows[k];
    const [r, rSe] = parseWithError(row.cells.rms);
    return row.strategy === c.strategy && row.radius === String(c.merge_radius) && row.cells.radius === String(c.merge_radius)
      && near(parseScientific(row.cells.light_paths), c.budget.light_paths) && near(parseScientific(row.cells.camera_paths), c.budget.camera_paths)
      && nearRms(r, c.rms_percent) && (c.rms_percent_stderr === null ? rSe === null : nearRms(rSe, c.rms_percent_stderr))
      && nearWithError(parseScientificWithError(row.cells.bias), c.bias_percent, c.bias_percent_stderr)
      && nearWithError(parseScientificWithError(row.cells.seconds_to_target), c.seconds_to_target, c.seconds_to_target_stderr)
      && row.marks.includes('not supported') === !c.supported && row.marks.includes('outside fixed weights') === !c.respects_fixed
      && row.best === (c.strategy === ep.best.strategy && c.merge_radius === ep.best.merge_radius);
  });
  const summary = await section.locator('[data-ref="error-candidates"] summary').textContent();
  check(candidatesOk && summary.startsWith(`All ${ep.candidates.length} candidates`),
    `the candidates table has the API's ${ep.candidates.length} (strategy, R′) in its order: R′, N_F, N_B, RMS % ± SE, bias % ± error, seconds ± SE, marks (first: ${rows[0].strategy} at ${rows[0].radius}, ${rows[0].cells.seconds_to_target} s)`);

  // A cost per merge is sent and used: its plan is the API's for the same costs.
  await mergeCost.fill('4e-7');
  const dearer = await requestPlan(page, button);
  check(dearer.body.merge_cost === 4e-7, `a cost per merge of 4e-7 s is sent as merge_cost (${JSON.stringify(dearer.body)})`);
  const method = section.locator('[data-ref="error-method"]');
  await waitFor('the plan with the dearer merges', async () => (await method.textContent()).includes('t_M = 4·10⁻⁷ s'), 60_000);
  const ep2 = (await callApi(`/v1/jobs/${id}/budget`, { method: 'POST', body: dearer.body })).json.error_plan;
  const best2 = await readPoint(section.locator('[data-ref="error-best"]'));
  check(ep2.costs.merge === 4e-7 && samePoint(best2, ep2.best) && best2.seconds > best.seconds,
    `with merges 5× dearer the fastest point is the API's: ${best2.strategy} at R′ = ${best2.radius}, ${best2.secondsText} — later than ${best.secondsText} at R′ = ${best.radius} with the reference's`);
  await mergeCost.fill('');
  await panel.locator('input[name="target_rmse"]').fill('');
}

/** Clicks "Plan the budget" and returns the request body the page sent. */
async function requestPlan(page, button) {
  const [request] = await Promise.all([
    page.waitForRequest((r) => r.method() === 'POST' && /\/v1\/jobs\/\d+\/budget$/.test(new URL(r.url()).pathname)),
    button.click(),
  ]);
  return { body: request.postDataJSON() };
}
