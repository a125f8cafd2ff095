// A ray-budget plan (POST /v1/jobs/{id}/budget's answer) in the page's words: the headline a user
// acts on — the strategy to use, its fastest (N_F, N_B), the time to the target and its speed-up
// ± SE over the paper's switch at (10⁷, 100), whether that budget lies on the edge of what the run
// can predict and whether the run's noise left faster budgets unsupported — the plan's warnings,
// and every strategy's fastest supported budget: those that keep the fixed weights ranked by time,
// the others listed after them, unranked, as the server orders them.
// No state: budget.js asks for the plan and puts these elements in its panel.

import { fixed, formatDuration, formatRms, formatScientific, h, withError } from './format.js';

/** A count as the plan's tables print it: 10⁸, 3.16·10⁷, 1,000. */
const count = (n) => formatScientific(n);
/** Seconds, with days or hours beside them when they are many. */
const seconds = (s) => `${formatScientific(s)} s${s >= 3600 ? ` (${formatDuration(s)})` : ''}`;
/** A speed-up ± its SE: "12.1 ± 1.9×". */
const speedup = (x, se) => (x === null || x === undefined ? '—' : `${withError(x, se ?? null, (v) => fixed(v, v >= 100 ? 0 : v >= 10 ? 1 : 2))}×`);
/** The plan's limit on a supported prediction, as a percentage: RMS SE at most this share of the RMS. */
const supportPercent = (plan) => Number((100 * plan.support_relative_se).toPrecision(6));
/** RMS % ± SE. */
const rms = (p) => withError(p.rms_percent, p.rms_percent_stderr ?? null, formatRms);

/** Which edges of the searched range `point`'s budget lies on, in words (empty if none). */
export function edgesOf(point, search) {
  const edges = [];
  const { light_paths: f, camera_paths: b } = point.budget;
  if (f === search.light_paths[1]) edges.push(`the largest N_F searched (${count(f)})`);
  else if (f === search.light_paths[0]) edges.push(`the smallest N_F searched (${count(f)})`);
  if (b === search.camera_paths[1]) edges.push(`the largest N_B searched (${count(b)})`);
  else if (b === search.camera_paths[0]) edges.push(`the smallest N_B searched (${count(b)})`);
  return edges;
}

/** The headline and the plan's warnings, as paragraphs: what to do, and how far to trust it. */
export function headlineOf(plan, { iterations }) {
  const out = [];
  const best = plan.best.find((b) => b.strategy === plan.headline);
  const target = `${Number(plan.target_rms_percent.toPrecision(6))} % RMS`;
  const at = (b) => `N_F = ${count(b.budget.light_paths)}, N_B = ${count(b.budget.camera_paths)}`;
  if (!best) {
    out.push(h('p', { class: 'budget-headline', 'data-ref': 'budget-headline' },
      plan.headline ? `${plan.headline} could not be predicted at any budget.` : 'No strategy of this run could be planned.'));
  } else {
    const own = plan.headline === plan.recommended ? ', the run\'s recommendation,' : '';
    const paper = plan.paper ? [' — ', h('strong', { 'data-ref': 'budget-speedup' }, `${speedup(best.speedup, best.speedup_stderr)} sooner`),
      ` than the paper's switch at (10⁷, 100), which takes ${seconds(plan.paper.seconds_to_target)}`] : [' (the paper\'s configuration could not be predicted: no speed-up)'];
    out.push(h('p', { class: 'budget-headline', 'data-ref': 'budget-headline', 'data-strategy': best.strategy },
      'To reach ', target, ': ', h('code', {}, best.strategy), own, ' at ', h('strong', { 'data-ref': 'budget-best' }, at(best)),
      `, ${rms(best)} % per iteration, ${seconds(best.seconds_to_target)}`, ...paper, '.'));
    // The headline is the server's pick (the recommendation's family); a faster ranked row is worth knowing.
    const fastest = plan.best.find((b) => b.respects_fixed);
    if (fastest && fastest.strategy !== best.strategy) {
      out.push(h('p', { class: 'budget-fastest', 'data-ref': 'budget-fastest', 'data-strategy': fastest.strategy },
        'Fastest of the strategies that keep the fixed weights: ', h('code', {}, fastest.strategy), ` at ${at(fastest)}, ${seconds(fastest.seconds_to_target)}`,
        plan.paper ? `, ${speedup(fastest.speedup, fastest.speedup_stderr)} sooner than the paper's switch.` : '.'));
    }
  }
  const warnings = [];
  const limit = supportPercent(plan);
  if (plan.headline_note) warnings.push(['headline', `Note: ${plan.headline_note}.`]);
  if (best?.at_edge) {
    warnings.push(['edge', `At the edge: ${edgesOf(best, plan.search).join(' and ')}${plan.search.at_limit ? ', as far as this run can predict (two decades from its own budget)' : ''}. The optimum may lie beyond; to look further, run a job with noise components nearer this budget and plan from it.`]);
  }
  if (best && !best.supported) {
    warnings.push(['unsupported', `Not supported: no budget of ${best.strategy} is predicted with an RMS standard error below ${limit} % of the RMS; these figures are more noise than prediction. Run the job longer before planning.`]);
  } else if (best?.faster_unsupported) {
    warnings.push(['unsupported', `Budgets predicted to be faster for ${best.strategy} have an RMS standard error above ${limit} % of the RMS, which this run cannot support: they are left aside. A longer run, or one nearer them, can resolve them.`]);
  }
  if (plan.partial) {
    warnings.push(['partial', `Planned from the job's latest checkpoint (${iterations} iterations) while it is ${plan.state}: the figures change as it runs; plan again when it has finished.`]);
  }
  if (warnings.length) {
    out.push(h('ul', { class: 'notice notice-warning warnings', 'data-ref': 'budget-warnings' },
      warnings.map(([kind, text]) => h('li', { 'data-warning': kind }, text))));
  }
  return out;
}

// Where the costs come from, as the plan's `costs.source` says.
const COST_SOURCES = {
  reference: "the reference costs: this crate's brute force on the paper's scene, 2 cores — the same in optimis budget and the API",
  given: 'your costs',
  mixed: "your costs, the others the reference's",
  measured: 'measured on the machine that planned',
};

/** What the plan searched and with which costs, in one line. */
export function searchNote(plan, measured) {
  const { search: s, costs: c } = plan;
  return `Predicted from the run at (N_F, N_B) = (${count(measured.light_paths)}, ${count(measured.camera_paths)}); searched N_F ${count(s.light_paths[0])}–${count(s.light_paths[1])}, N_B ${count(s.camera_paths[0])}–${count(s.camera_paths[1])} in half-decade steps${s.at_limit ? ' (widened to the limit of what the run can predict)' : ''}. Time per iteration t = t_F·N_F + t_B·N_B·P + t_0 with t_F = ${formatScientific(c.light_path)} s, t_B = ${formatScientific(c.camera_path)} s, t_0 = ${formatScientific(c.iteration)} s (${COST_SOURCES[c.source] ?? c.source}), P = ${formatScientific(c.pixels)} pixels; an iteration at least, (RMS / target)² iterations. RMS and speed-up ± 1 SE (jackknife over the folds; the speed-up's treats both RMS as independent, which overstates it). Only budgets whose RMS is predicted with an SE of at most ${supportPercent(plan)} % of itself are chosen: beyond, the fastest budget would be picked for its noise.`;
}

/** The table of every strategy's fastest budget, the headline's row marked, then the paper's configuration. */
export function planTable(plan) {
  let rank = 0;
  const rows = plan.best.map((b) => {
    const ranked = b.respects_fixed;
    if (ranked) rank += 1;
    const marks = [
      b.strategy === plan.headline ? h('span', { class: 'recommended-mark', title: 'The plan\'s headline' }, 'headline') : null,
      b.at_edge ? h('span', { class: 'edge-mark', title: 'On the edge of the searched range: the optimum may lie beyond' }, 'at edge') : null,
      b.supported ? null : h('span', { class: 'edge-mark', title: `No budget of this strategy is predicted with an RMS SE below ${supportPercent(plan)} % of the RMS` }, 'not supported'),
      ranked ? null : h('span', { class: 'outside-mark', title: "Does not keep the solver's fixed weights: shown for comparison, not ranked" }, 'outside fixed weights, not ranked'),
    ];
    return h('tr', { 'data-strategy': b.strategy, 'data-ranked': String(ranked), 'data-at-edge': String(b.at_edge), 'data-supported': String(b.supported), class: b.strategy === plan.headline ? 'recommended' : null },
      h('td', { class: 'num', 'data-col': 'rank' }, ranked ? String(rank) : '—'),
      h('th', { scope: 'row' }, h('code', {}, b.strategy), ...marks),
      h('td', { class: 'num', 'data-col': 'light_paths' }, count(b.budget.light_paths)),
      h('td', { class: 'num', 'data-col': 'camera_paths' }, count(b.budget.camera_paths)),
      h('td', { class: 'num', 'data-col': 'rms' }, rms(b)),
      h('td', { class: 'num', 'data-col': 'seconds_per_iteration' }, formatScientific(b.seconds_per_iteration)),
      h('td', { class: 'num', 'data-col': 'seconds_to_target' }, formatScientific(b.seconds_to_target)),
      h('td', { class: 'num', 'data-col': 'speedup' }, speedup(b.speedup, b.speedup_stderr)));
  });
  const p = plan.paper;
  const paper = p ? h('tr', { class: 'paper-row', 'data-strategy': 'paper' },
    h('td', { class: 'num' }, ''), h('th', { scope: 'row' }, h('code', {}, 'switch'), ' at the paper\'s (10⁷, 100)'),
    h('td', { class: 'num', 'data-col': 'light_paths' }, count(p.budget.light_paths)),
    h('td', { class: 'num', 'data-col': 'camera_paths' }, count(p.budget.camera_paths)),
    h('td', { class: 'num', 'data-col': 'rms' }, rms(p)),
    h('td', { class: 'num', 'data-col': 'seconds_per_iteration' }, formatScientific(p.seconds_per_iteration)),
    h('td', { class: 'num', 'data-col': 'seconds_to_target' }, formatScientific(p.seconds_to_target)),
    h('td', { class: 'num', 'data-col': 'speedup' }, '1×')) : null;
  const head = ['#', 'Strategy', ['N', h('sub', {}, 'F')], ['N', h('sub', {}, 'B')], 'RMS % / iteration ± SE', 's / iteration', `s to ${Number(plan.target_rms_percent.toPrecision(6))} %`, 'Speed-up ± SE'];
  return h('div', { class: 'table-wrap' }, h('table', { class: 'budget-table', 'data-ref': 'budget-table' },
    h('thead', {}, h('tr', {}, head.map((t, i) => h('th', { scope: 'col', class: i < 2 ? null : 'num' }, t)))),
    h('tbody', {}, rows, paper)));
}
