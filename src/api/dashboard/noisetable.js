// The noise table of a job (the paper's Table 1): per strategy its weights in words, L ± SE, the z
// of L against the quadrature reference, RMS % ± SE, the paper's case number and — when the job
// runs the paper's configuration — the paper's L and RMS; and the same table as CSV rows.

import { fixed, formatLuminance, formatParameter, formatRms, h, withError } from './format.js';
import { PAPER_TABLE1, paperMismatches, zScore } from './paper.js';

/** z in words: two decimals and a sign. */
const formatZ = (z) => `${z > 0 ? '+' : z < 0 ? '−' : ''}${fixed(Math.abs(z), 2)}`;

/**
 * The rows of the table body, and the note under it about the paper's column: `paper` is whether
 * the paper's values apply (the header's paper columns are shown only then).
 */
export function noiseRows(result, job) {
  const paper = paperMismatches(job.spec).length === 0;
  const best = job.progress.best?.strategy;
  const recommended = result.recommended?.strategy;
  const rows = result.noise_table.map((row) => noiseRow(row, { spec: job.spec, best, recommended, folds: result.folds, reference: result.reference_luminance, paper }));
  return { rows, paper };
}

/** The note beside the table: where the paper's values come from, or why they are not shown. */
export function paperNote(spec) {
  const differs = paperMismatches(spec);
  if (differs.length === 0) {
    return "Paper: Ershov et al. 2020, Table 1 (10⁴ iterations; its case 5 is fitted and scored in-sample, like our optimal row). Its L and RMS do not depend on the number of iterations; ours carry ± 1 SE.";
  }
  return `Paper values apply to the paper-table1 configuration only (this job differs in ${differs.map((f) => `${f}`).join(', ')}).`;
}

function noiseRow(row, { spec, best, recommended, folds, reference, paper }) {
  const z = row.error ? null : zScore(row.luminance, row.luminance_stderr, reference);
  const zCell = h('td', {
    class: `num${row.in_sample ? ' optimistic' : ''}`, 'data-col': 'z',
    title: row.in_sample ? 'In-sample: the SE is too small and L biased, so this z is optimistic (too large in magnitude)' : null,
  }, z === null ? '—' : `${formatZ(z)}${row.in_sample ? ' †' : ''}`);
  const numbers = row.error
    ? [h('td', { class: 'row-error', colspan: 3, 'data-col': 'error' }, row.error)]
    : [
      h('td', { class: 'num', 'data-col': 'luminance' }, withError(row.luminance, row.luminance_stderr, formatLuminance)),
      zCell,
      h('td', { class: 'num', 'data-col': 'rms' }, withError(row.rms_percent, row.rms_percent_stderr, formatRms)),
    ];
  const ours = PAPER_TABLE1[row.strategy];
  const paperCells = paper ? [
    h('td', { class: 'num paper-col', 'data-col': 'paper-luminance' }, ours ? fixed(ours.luminance * 1e5, 3) : ''),
    h('td', { class: 'num paper-col', 'data-col': 'paper-rms' }, ours ? `${ours.rms_percent}` : ''),
  ] : [];
  return h('tr', { 'data-strategy': row.strategy, class: row.strategy === best ? 'best' : null },
    h('th', { scope: 'row' }, h('code', {}, row.strategy),
      row.strategy === best ? h('span', { class: 'best-mark', title: "Lowest honest RMS among the rows that keep the solver's fixed weights (in-sample fits are left out)" }, 'best') : null,
      row.strategy === recommended ? h('span', { class: 'recommended-mark', title: 'The weights table and chart show these weights' }, 'recommended') : null,
      row.in_sample ? h('span', { class: 'in-sample-mark', title: 'Fitted and scored on the same iterations: optimistic (L biased, SE and RMS too small)' }, 'in-sample') : null,
      row.respects_fixed === false ? h('span', { class: 'outside-mark', title: "Does not keep the solver's fixed weights: shown for comparison, never best" }, 'outside fixed weights') : null),
    h('td', { class: 'num', 'data-col': 'case' }, ours ? String(ours.case) : ''),
    h('td', { 'data-col': 'weights' }, describeWeights(row, spec, folds)),
    ...numbers,
    ...paperCells);
}

/** The weights of each strategy in words, as in the paper's Table 1. */
function describeWeights(row, spec, folds) {
  switch (row.strategy) {
    case 'plane1': return 'w₀ = 1';
    case 'plane2': return 'w₁ = 1';
    case 'plane3': return 'w₂ = 1';
    case 'switch': return describeSwitch(spec.scene.illumination);
    case 'optimal': return `fitted and scored on all iterations (${describeSolver(spec.solver)})`;
    case 'optimal_holdout': return `fitted, ${folds}-fold cross-fitted (${describeSolver(spec.solver)})`;
    case 'optimal_cv': return describeCrossValidation(row, folds);
    case 'balance': return 'balance heuristic';
    case 'power': return 'power heuristic';
    case 'correlation_aware': return 'correlation-aware heuristic';
    default: return '';
  }
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
  return `fitted, λ by cross-validation, ${folds}-fold cross-fitted${parts.length ? ` (${parts.join('; ')})` : ''}`;
}

/** The noise table as CSV rows (luminance in model units, RMS in percent; the paper's columns empty unless they apply). */
export function noiseCsv(result, spec) {
  const paper = paperMismatches(spec).length === 0;
  const columns = ['strategy', 'paper_case', 'luminance_model_units', 'luminance_stderr_model_units', 'reference_luminance_model_units',
    'z_vs_reference', 'rms_percent', 'rms_percent_stderr', 'in_sample', 'respects_fixed', 'recommended', 'lambda',
    'paper_luminance_model_units', 'paper_rms_percent', 'error'];
  const rows = result.noise_table.map((row) => {
    const ours = PAPER_TABLE1[row.strategy];
    return {
      strategy: row.strategy,
      paper_case: ours?.case,
      luminance_model_units: row.luminance,
      luminance_stderr_model_units: row.luminance_stderr,
      reference_luminance_model_units: result.reference_luminance,
      z_vs_reference: zScore(row.luminance, row.luminance_stderr, result.reference_luminance),
      rms_percent: row.rms_percent,
      rms_percent_stderr: row.rms_percent_stderr,
      in_sample: row.in_sample,
      respects_fixed: row.respects_fixed,
      recommended: row.strategy === result.recommended?.strategy,
      lambda: row.lambda,
      paper_luminance_model_units: paper ? ours?.luminance : null,
      paper_rms_percent: paper ? ours?.rms_percent : null,
      error: row.error,
    };
  });
  return { columns, rows };
}
