// A plan to a target *error* (the budget answer's `error_plan`, asked for with `target_rmse`) in
// the page's words: the relative RMSE about the true pixel value — the noise and the merge radius's
// bias together — reached soonest over (strategy, R′, N_F, N_B): the fastest point, the best at the
// job's own R, the paper's setup, the two speed-ups ± SE, the progressive schedule, the strategies
// whose bias alone is out of reach, the plan's notes and every candidate. Every figure is a
// prediction from the run's noise components and its biases, with its standard error.
// No state: budget.js puts the section in its panel.

import { fixed, formatDuration, formatParameter, formatRms, formatScientific, formatScientificWithError, h, withError } from './format.js';

/** A number to 3 significant digits with a real minus: 0.0123, −4.5·10⁻³, 3.16·10⁷. */
const num = (x) => formatScientific(x).replace(/^-/, '−');
/** Seconds ± SE, with days or hours beside them when they are many. */
const seconds = (s, se) => `${formatScientificWithError(s, se)} s${s >= 3600 ? ` (${formatDuration(s)})` : ''}`;
/** A speed-up ± its SE: "3.4 ± 0.8×". */
const speedup = (x, se) => `${withError(x, se ?? null, (v) => fixed(v, v >= 100 ? 0 : v >= 10 ? 1 : 2))}×`;
/** A budget: "N_F = 10⁶, N_B = 31.6". */
const budget = (b) => `N_F = ${num(b.light_paths)}, N_B = ${num(b.camera_paths)}`;
/** Bias % ± its error. */
const bias = (p) => formatScientificWithError(p.bias_percent, p.bias_percent_stderr);
/** RMS % of one iteration ± SE. */
const rms = (p) => withError(p.rms_percent, p.rms_percent_stderr ?? null, formatRms);

/** One point's figures in words: where, how long, from what. */
function pointWords(p) {
  return [h('code', {}, p.strategy), ` at R′ = ${formatParameter(p.merge_radius)}, `, h('strong', { 'data-ref': 'error-budget' }, budget(p.budget)), ': ',
    h('strong', { 'data-ref': 'error-seconds' }, seconds(p.seconds_to_target, p.seconds_to_target_stderr)),
    ` (${num(p.iterations)} iterations of ${num(p.seconds_per_iteration)} s; RMS ${rms(p)} % per iteration, bias ${bias(p)} %)`,
    p.supported ? '' : ' — not supported: its RMS is too uncertain'];
}

/** The attributes a point's paragraph carries for a reader of the page (and the tests). */
const pointData = (ref, p) => ({
  'data-ref': ref, 'data-strategy': p.strategy, 'data-radius': String(p.merge_radius),
  'data-light-paths': String(p.budget.light_paths), 'data-camera-paths': String(p.budget.camera_paths),
});

/** The error plan `ep` as a section of the budget panel. */
export function errorPlanSection(ep) {
  const target = `${Number(ep.target_rmse_percent.toPrecision(6))} %`;
  const radii = ep.radii.map(formatParameter).join(', ');
  const out = [h('h3', {}, `To ${target} RMSE about the true value (noise and bias) over R′ ∈ {${radii}}`)];
  if (ep.best) {
    out.push(h('p', { class: 'budget-headline', ...pointData('error-best', ep.best) },
      'Predicted fastest: ', ...pointWords(ep.best), '.'));
  } else {
    out.push(h('p', { class: 'budget-headline', 'data-ref': 'error-best' }, 'No supported point that keeps the fixed weights reaches the target.'));
  }
  const own = ep.at_own_radius;
  out.push(own
    ? h('p', pointData('error-own', own), `Best at the job's own R = ${formatParameter(own.merge_radius)}: `, ...pointWords(own),
      ep.speedup_over_own_radius === null || ep.speedup_over_own_radius === undefined ? '.'
        : ['; the fastest is ', h('strong', { 'data-ref': 'error-speedup-own' }, speedup(ep.speedup_over_own_radius, ep.speedup_over_own_radius_stderr)), ' sooner (predicted).'])
    : h('p', { 'data-ref': 'error-own' }, `At the job's own R = ${formatParameter(ep.radii.at(-1))}: no supported point that keeps the fixed weights reaches the target.`));
  const paper = ep.paper;
  out.push(paper
    ? h('p', pointData('error-paper', paper), "The paper's setup, ", ...pointWords(paper),
      ep.speedup_over_paper === null || ep.speedup_over_paper === undefined ? '.'
        : ['; the fastest is ', h('strong', { 'data-ref': 'error-speedup-paper' }, speedup(ep.speedup_over_paper, ep.speedup_over_paper_stderr)), ' sooner (predicted).'])
    : h('p', { 'data-ref': 'error-paper' }, "The paper's setup (switch at N_F = 10⁷, N_B = 100, R = 0.003): not predicted — the run did not tally R = 0.003, so there is no speed-up over it."));
  out.push(progressiveLine(ep.progressive, target));
  if (ep.out_of_reach.length) {
    const byRadius = new Map();
    for (const o of ep.out_of_reach) byRadius.set(o.merge_radius, [...(byRadius.get(o.merge_radius) ?? []), o]);
    out.push(h('div', { 'data-ref': 'error-out-of-reach' },
      h('p', {}, `Out of reach — the bias alone is at least ${target}, so no number of iterations gets there:`),
      h('ul', { class: 'out-of-reach' }, [...byRadius].sort((a, b) => a[0] - b[0]).map(([r, list]) => h('li', { 'data-radius': String(r) },
        `R′ = ${formatParameter(r)}: `, ...list.flatMap((o, i) => [i ? ', ' : '', h('code', {}, o.strategy), ` (bias ${num(o.bias_percent)} %)`]))))));
  }
  if (ep.notes.length) {
    out.push(h('ul', { class: 'notice notice-warning warnings', 'data-ref': 'error-notes' }, ep.notes.map((n) => h('li', {}, `Note: ${n}.`))));
  }
  out.push(candidatesTable(ep));
  const c = ep.costs;
  out.push(h('p', { class: 'hint', 'data-ref': 'error-method' },
    `Predicted: after n iterations the error is √(σ²/n + b²), σ the RMS % of one iteration at the budget and radius, b the strategy's bias there (against the R → 0 reference); a point needs σ²/(P² − b²) iterations, at least one. `
    + `An iteration costs t_F·N_F + t_B·N_B·P + t_0 + t_M·m·P seconds, m the merges per pixel at R′ scaled to the budget, with t_M = ${num(c.merge ?? 0)} s per merge and pixel. `
    + 'Times ± 1 SE (delta method on σ and b); speed-ups ± SE treat both times as independent. Only points that keep the fixed weights and whose RMS the run supports are chosen.'));
  return h('section', { class: 'error-plan', 'data-ref': 'error-plan' }, out);
}

/** The progressive schedule's row, in one paragraph. */
function progressiveLine(p, target) {
  if (!p) return h('p', { 'data-ref': 'error-progressive' }, 'Progressive radius: not predicted (it needs the fastest point and at least two radii with its strategy\'s bias).');
  const radii = `R′ from ${formatParameter(p.first_radius)} down to ${formatParameter(p.last_radius)}${p.floored ? ' (held at the smallest radius tallied: the run cannot predict below it)' : ''}`;
  const time = p.seconds_to_target === null || p.seconds_to_target === undefined
    ? `does not reach ${target} within 10¹² iterations`
    : ['reaches it in ', h('strong', { 'data-ref': 'error-progressive-seconds' }, seconds(p.seconds_to_target, p.seconds_to_target_stderr)), ` (${num(p.iterations)} iterations)`];
  return h('p', { 'data-ref': 'error-progressive', 'data-strategy': p.strategy, 'data-first-radius': String(p.first_radius), 'data-last-radius': String(p.last_radius) },
    `Progressive radius (R_i² = R₁²·i^(α−1), α = ${fixed(p.alpha, 3)}), predicted: `, h('code', {}, p.strategy), ` at ${budget(p.budget)}, ${radii}, `, time, '.');
}

/** Every (strategy, R′) that can reach the target, its fastest point, by time: a compact table. */
function candidatesTable(ep) {
  const best = ep.best;
  const isBest = (p) => best && p.strategy === best.strategy && p.merge_radius === best.merge_radius;
  const rows = ep.candidates.map((p) => h('tr', {
    'data-strategy': p.strategy, 'data-radius': String(p.merge_radius), 'data-supported': String(p.supported), 'data-respects-fixed': String(p.respects_fixed),
    class: isBest(p) ? 'recommended' : null,
  },
  h('th', { scope: 'row' }, h('code', {}, p.strategy),
    p.supported ? null : h('span', { class: 'edge-mark', title: 'Its RMS is predicted too uncertainly to be chosen' }, 'not supported'),
    p.respects_fixed ? null : h('span', { class: 'outside-mark', title: "Does not keep the solver's fixed weights: shown for comparison, never chosen" }, 'outside fixed weights')),
  h('td', { class: 'num', 'data-col': 'radius' }, formatParameter(p.merge_radius)),
  h('td', { class: 'num', 'data-col': 'light_paths' }, num(p.budget.light_paths)),
  h('td', { class: 'num', 'data-col': 'camera_paths' }, num(p.budget.camera_paths)),
  h('td', { class: 'num', 'data-col': 'rms' }, rms(p)),
  h('td', { class: 'num', 'data-col': 'bias' }, bias(p)),
  h('td', { class: 'num', 'data-col': 'seconds_to_target' }, formatScientificWithError(p.seconds_to_target, p.seconds_to_target_stderr))));
  const head = ['Strategy', 'R′', ['N', h('sub', {}, 'F')], ['N', h('sub', {}, 'B')], 'RMS % / iteration ± SE', 'Bias % ± err', 's to target ± SE'];
  return h('details', { class: 'error-candidates', 'data-ref': 'error-candidates' },
    h('summary', {}, `All ${ep.candidates.length} candidates — each (strategy, R′)'s fastest predicted point, by time`),
    h('div', { class: 'table-wrap' }, h('table', { class: 'budget-table error-table', 'data-ref': 'error-table' },
      h('thead', {}, h('tr', {}, head.map((t, i) => h('th', { scope: 'col', class: i === 0 ? null : 'num' }, t)))),
      h('tbody', {}, rows))));
}
