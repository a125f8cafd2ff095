// The noise table of a job (the paper's Table 1 and the rows issue 21 added): per strategy its
// weights in words (β of the heuristics stacked on a table beneath), L ± SE, the z of L against the
// row's expected luminance at the job's merge radius R, RMS % ± SE, the paper's case number and —
// when the job runs the paper's configuration — the paper's L and RMS; the recommended row marked
// (the server's `recommended`, which is not always the lowest RMS: the reason says why), the
// in-sample, unstable and outside-the-fixed-weights rows marked (its CSV is csvtables.js's).

import { fixed, formatBetas, formatLuminance, formatParameter, formatRms, h, signed, withError } from './format.js';
import { paperMismatches } from './paper.js';

// The paper's case numbers of the strategies that have one: which row is which case, whatever the
// configuration (the published figures themselves come with the result, where they apply).
export const CASES = { plane1: '1', plane2: '2', plane3: '3', switch: '4', optimal: '5' };

const MARKS = {
  'in-sample': 'Fitted and scored on the same iterations: optimistic (L biased, SE and RMS too small)',
  unstable: 'Its fitted weights (or β) change from fold to fold by more than 0.25 (jackknife SE): never recommended',
  tail: 'Its L lies more than 3 SE below its exact expectation at R: the run lacks the rare large contributions that carry its variance, so its RMS is far too small; never recommended',
  beyond: 'Its weights move further from the best per-path row\'s than the trust region (solver.trust_region) allows: its advantage may rest on rare events the run did not draw; never recommended',
  outside: "Does not keep the solver's fixed weights: shown for comparison, never recommended",
};

/**
 * The rows of the table body, and whether the paper's values apply (the header's paper columns
 * are shown only then).
 */
export function noiseRows(result, job) {
  const paper = (result.references ?? []).length > 0;
  const context = { spec: job.spec, recommended: result.recommended, folds: result.folds, paper, result };
  return { rows: result.noise_table.map((row) => noiseRow(row, context)), paper };
}

/** Why the recommended row is recommended, as the server says it, for under the table. */
export function recommendedNote(result) {
  const rec = result.recommended;
  if (!rec) return [];
  const what = rec.lambda === null || rec.lambda === undefined ? 'a per-path strategy: no weights table'
    : `a table at λ = ${formatParameter(rec.lambda)}${rec.heuristics?.length ? ` with β: ${formatBetas(rec.heuristics)}` : ''}`;
  return ['Recommended: ', h('code', {}, rec.strategy), ` (${what})`, rec.reason ? ` — ${rec.reason}.` : '.'];
}

/** The caption of the z column: the expectation at R, and the R → 0 reference beside it. */
export function referenceNote(result, spec) {
  const expected = result.noise_table.some((r) => r.z !== null && r.z !== undefined);
  const parts = [expected
    ? `z = (L − L_R) / SE(L), L_R the row's expected luminance at the job's R = ${formatParameter(spec.merge_radius)} by quadrature (hover a z for it). Fitted rows show —: their expectation depends on weights fitted to these iterations; compare their L with the per-path rows'.`
    : `No expected luminance at the job's R = ${formatParameter(spec.merge_radius)} in this result, so no z (hover a — for why).`];
  if (result.reference_luminance !== null) parts.push(`Reference in the limit R → 0 (quadrature): L·10⁵ = ${formatLuminance(result.reference_luminance)}.`);
  return parts.join(' ');
}

/**
 * A strategy's published row (case, L, RMS %) in the tables the server attached to the result
 * (`references`: the repository's references/*.json, for a job with the paper's configuration).
 */
export function published(result, strategy) {
  for (const table of result.references ?? []) {
    const row = table.rows.find((r) => r.strategy === strategy);
    if (row) return row;
  }
  return undefined;
}

/** The paper's column: where its values come from, or why they are not shown. */
export function paperNote(spec, result) {
  const table = (result?.references ?? [])[0];
  if (table) {
    return `Paper: ${table.source} (${table.iterations} iterations; its case 5 is fitted and scored in-sample, like our optimal row). Its L and RMS do not depend on the number of iterations; ours carry ± 1 SE.`;
  }
  const differs = paperMismatches(spec);
  if (differs.length === 0) {
    return 'The paper\'s values are not in this result (it was read from an older checkpoint or a solve that changes the fixed weights).';
  }
  return `Paper values apply to the paper-table1 configuration only (this job differs in ${differs.join(', ')}).`;
}

/** z in words: two decimals and a sign. */
const formatZ = (z) => `${z > 0 ? '+' : ''}${signed(z, 2)}`;

/** A mark after a row's name. */
const mark = (cls, text, title) => h('span', { class: cls, title }, text);

function noiseRow(row, context) {
  const { recommended, paper, result } = context;
  const isRecommended = row.strategy === recommended?.strategy;
  const numbers = row.error
    ? [h('td', { class: 'row-error', colspan: 3, 'data-col': 'error' }, row.error)]
    : [
      h('td', { class: 'num', 'data-col': 'luminance' }, withError(row.luminance, row.luminance_stderr, formatLuminance)),
      zCell(row),
      h('td', { class: 'num', 'data-col': 'rms' }, withError(row.rms_percent, row.rms_percent_stderr, formatRms)),
    ];
  const ours = published(result, row.strategy);
  // z against the paper's figure, in our standard errors (the paper gives none).
  const zPaper = (value, se, theirs) => (ours && Number.isFinite(value) && se > 0 ? formatZ((value - theirs) / se) : '');
  const zTitle = 'z = (ours − paper) / SE(ours): how many of our standard errors the paper\'s figure lies away (the paper gives no error)';
  const paperCells = paper ? [
    h('td', { class: 'num paper-col', 'data-col': 'paper-luminance' }, ours ? fixed(ours.luminance * 1e5, 3) : ''),
    h('td', { class: 'num paper-col', 'data-col': 'paper-luminance-z', title: zTitle }, zPaper(row.luminance, row.luminance_stderr, ours?.luminance)),
    h('td', { class: 'num paper-col', 'data-col': 'paper-rms' }, ours ? `${ours.rms_percent}` : ''),
    h('td', { class: 'num paper-col', 'data-col': 'paper-rms-z', title: zTitle }, zPaper(row.rms_percent, row.rms_percent_stderr, ours?.rms_percent)),
  ] : [];
  return h('tr', { 'data-strategy': row.strategy, class: isRecommended ? 'recommended' : null },
    h('th', { scope: 'row' }, h('code', {}, row.strategy),
      isRecommended ? mark('recommended-mark', 'recommended', recommended.reason ?? 'The recommended weights') : null,
      row.in_sample ? mark('in-sample-mark', 'in-sample', MARKS['in-sample']) : null,
      row.unstable ? mark('unstable-mark', 'unstable', MARKS.unstable) : null,
      row.tail_missing ? mark('unstable-mark', 'tail missing', MARKS.tail) : null,
      row.beyond_trust_region ? mark('unstable-mark', 'beyond trust region', `${MARKS.beyond}${row.deviation == null ? '' : ` (deviation ${row.deviation.toFixed(2)})`}`) : null,
      row.respects_fixed === false ? mark('outside-mark', 'outside fixed weights', MARKS.outside) : null),
    h('td', { class: 'num', 'data-col': 'case' }, CASES[row.strategy] ?? ''),
    weightsCell(row, context),
    ...numbers,
    ...paperCells);
}

/** z against the row's expectation at R; "—" with the reason when it has none. */
function zCell(row) {
  const has = row.z !== null && row.z !== undefined;
  const optimistic = has && row.in_sample;
  const title = has
    ? `Expected at R: L·10⁵ = ${formatLuminance(row.expected_luminance)}${optimistic ? '; in-sample: the SE is too small and L biased, so this z is optimistic' : ''}`
    : row.expected_error ?? 'No expected luminance at R for this row';
  return h('td', { class: `num${optimistic ? ' optimistic' : ''}`, 'data-col': 'z', title },
    has ? `${formatZ(row.z)}${optimistic ? ' †' : ''}` : '—');
}

/** The weights in words; beneath, β of the heuristics stacked on a table; the λ path as a tooltip. */
function weightsCell(row, { spec, folds }) {
  const betas = row.heuristics?.length
    ? h('span', { class: 'betas', 'data-betas': row.heuristics.length, title: 'β of each heuristic stacked on the table (± jackknife SE): a path\'s weights are the table\'s plus Σ β × the heuristic\'s' },
      `β: ${formatBetas(row.heuristics)}`)
    : null;
  return h('td', { 'data-col': 'weights', title: describePath(row.cv_path) }, describeWeights(row, spec, folds), betas);
}

/** The λ grid a row's λ was chosen on, in words (the one-standard-error rule's curve). */
function describePath(path) {
  if (!path?.length) return null;
  const points = path.map((p) => `λ = ${formatParameter(p.lambda)}: ${p.rms_percent === null ? '—' : withError(p.rms_percent, p.rms_percent_stderr, formatRms)} %${p.stable ? '' : ' (unstable)'}`);
  return `Cross-fitted RMS by λ (chosen: the largest λ within one SE of the lowest, among stable fits):\n${points.join('\n')}`;
}

// A heuristic's name in words.
const HEURISTICS = { switch: 'the switch', balance: 'balance heuristic', power: 'power heuristic', correlation_aware: 'correlation-aware heuristic' };

/** A heuristic, possibly restricted to planes 2–3, in words: `power heuristic over planes 2–3 (w₀ = 0)`. */
function describeHeuristic(name, sayW0 = true) {
  const base = name.replace(/_planes23$/, '');
  if (!(base in HEURISTICS)) return name;
  return base === name ? HEURISTICS[base] : `${HEURISTICS[base]} over planes 2–3${sayW0 ? ' (w₀ = 0)' : ''}`;
}

/** The weights of each strategy in words, as in the paper's Table 1. */
function describeWeights(row, spec, folds) {
  const name = row.strategy;
  switch (name) {
    case 'plane1': return 'w₀ = 1';
    case 'plane2': return 'w₁ = 1';
    case 'plane3': return 'w₂ = 1';
    case 'switch': return describeSwitch(spec.scene.illumination);
    case 'optimal': return `fitted and scored on all iterations (${describeSolver(spec.solver)})`;
    case 'optimal_holdout': return `fitted, ${folds}-fold cross-fitted (${describeSolver(spec.solver)})`;
    case 'optimal_cv': return `table, ${describeCrossValidation(row, folds)}`;
    case 'optimal_stacked': return `table + Σ β × heuristic (each that keeps the fixed weights), ${describeCrossValidation(row, folds)}`;
    default:
      break;
  }
  if (name.endsWith('_corrected')) {
    const at = row.lambda === null ? '' : ` = ${formatParameter(row.lambda)}`;
    return `${describeHeuristic(name.slice(0, -'_corrected'.length), false)} corrected by a table (at optimal_stacked's λ${at}), ${folds}-fold cross-fitted`;
  }
  return describeHeuristic(name);
}

/** Mirrors the server's switch radius: the spot's a, the innermost ring, none for uniform light. */
function describeSwitch(ill) {
  const a = ill.kind === 'spot' ? ill.a : ill.kind === 'rings' ? ill.rings[0].outer_radius : null;
  return a === null ? 'w₂ = 1 (no bright core to switch on)' : `w₁ = 1 if r₃ ≤ a, else w₂ = 1 (a = ${formatParameter(a)})`;
}

function describeSolver(solver) {
  const names = { w0: 'w₀', w1: 'w₁', w2: 'w₂' };
  const fixedWeights = Object.keys(names)
    .filter((w) => solver.fixed[w] !== undefined && solver.fixed[w] !== null)
    .map((w) => `${names[w]} = ${formatParameter(solver.fixed[w])}`);
  const parts = fixedWeights.length > 0 ? fixedWeights : ['all weights free'];
  if (solver.lambda > 0) parts.push(`λ = ${formatParameter(solver.lambda)}`);
  return parts.join(', ');
}

function describeCrossValidation(row, folds) {
  const parts = [];
  if (row.lambda !== null) parts.push(`λ = ${formatParameter(row.lambda)}`);
  if (row.in_sample_rms_percent !== null) parts.push(`in-sample RMS ${formatRms(row.in_sample_rms_percent)} %`);
  return `λ by cross-validation (one-SE rule), ${folds}-fold cross-fitted${parts.length ? ` (${parts.join('; ')})` : ''}`;
}
