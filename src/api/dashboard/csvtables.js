// The CSV tables the page builds from the API's JSON, in the one vocabulary of docs/csv.md (the
// server's and the command line's CSVs use the same names): a job's noise table, its recommended
// weights table, the effective weights Fig. 2 draws (any kind of recommendation: the one CSV a
// per-path heuristic has) and its history, and the compare page's two tables, which put their
// context columns (the job and its parameters; which table) in front of the same columns and never
// rename one. Units: luminance in the model's units (not × 10⁵), RMS in percent, angles in radians.

import { tableColumns } from './fig2.js';
import { CASES, published } from './noisetable.js';
import { luminanceStderr } from './paper.js';

/** The noise table's columns, in docs/csv.md's order. */
export const NOISE_COLUMNS = ['strategy', 'paper_case', 'luminance', 'luminance_stderr', 'expected_luminance', 'z', 'tail_missing', 'expected_error',
  'reference_luminance', 'rms_percent', 'rms_percent_stderr', 'lambda', 'in_sample', 'respects_fixed', 'unstable', 'deviation',
  'beyond_trust_region', 'recommended',
  'heuristics', 'in_sample_luminance', 'in_sample_luminance_stderr', 'in_sample_rms_percent', 'paper_luminance', 'paper_rms_percent',
  'error'];

/** A weights table's columns, in docs/csv.md's order. */
export const WEIGHT_COLUMNS = ['cell', 'r2_lo', 'r2_hi', 'r3_lo', 'r3_hi', 'phi_lo_rad', 'phi_hi_rad', 'w0', 'w0_stderr', 'w1', 'w1_stderr',
  'w2', 'w2_stderr', 'samples', 'status'];

/** The compare table's columns of a job, in front of the noise table's. */
const JOB_COLUMNS = ['job_id', 'preset', 'illumination', 'spot_a', 'engine', 'light_paths', 'camera_paths', 'merge_radius', 'iterations', 'seed'];

/** The rows of `result`'s noise table (the paper's figures only where its published table applies). */
function noiseRows(result) {
  const paper = (result.references ?? []).length > 0;
  return result.noise_table.map((row) => {
    const ours = paper ? published(result, row.strategy) : undefined;
    return {
      strategy: row.strategy,
      paper_case: CASES[row.strategy],
      luminance: row.luminance,
      luminance_stderr: row.luminance_stderr,
      expected_luminance: row.expected_luminance,
      z: row.z,
      tail_missing: row.tail_missing ?? false,
      expected_error: row.expected_error,
      reference_luminance: result.reference_luminance,
      rms_percent: row.rms_percent,
      rms_percent_stderr: row.rms_percent_stderr,
      lambda: row.lambda,
      in_sample: row.in_sample,
      respects_fixed: row.respects_fixed,
      unstable: row.unstable,
      deviation: row.deviation,
      beyond_trust_region: row.beyond_trust_region ?? false,
      recommended: row.strategy === result.recommended?.strategy,
      // β of the stacked heuristics as JSON ([{strategy, beta, beta_stderr}]); empty for the others.
      heuristics: row.heuristics?.length ? JSON.stringify(row.heuristics) : null,
      in_sample_luminance: row.in_sample_luminance,
      in_sample_luminance_stderr: row.in_sample_luminance_stderr,
      in_sample_rms_percent: row.in_sample_rms_percent,
      paper_luminance: ours?.luminance,
      paper_rms_percent: ours?.rms_percent,
      error: row.error,
    };
  });
}

/** The noise table of `result` as CSV rows. */
export const noiseCsv = (result) => ({ columns: NOISE_COLUMNS, rows: noiseRows(result) });

/** One row per cell of `weights`, `cell` its index in the document's order (an open interval's upper edge empty). */
const weightRows = (weights) => weights.map((w, cell) => ({
  cell, r2_lo: w.r2[0], r2_hi: w.r2[1], r3_lo: w.r3[0], r3_hi: w.r3[1], phi_lo_rad: w.phi[0], phi_hi_rad: w.phi[1],
  w0: w.w0, w0_stderr: w.w0_stderr, w1: w.w1, w1_stderr: w.w1_stderr, w2: w.w2, w2_stderr: w.w2_stderr, samples: w.samples, status: w.status,
}));

/** The rows of the table a figure (fig2.js's figureSource) draws, with `table`, `strategy` and `lambda` in front. */
const figureRows = (figure) => weightRows(figure.weights).map((row) => ({ ...tableColumns(figure), lambda: figure.lambda, ...row }));

/**
 * Every cell's weights of the table `figure` (fig2.js's figureSource): `table` says whether it is
 * the recommended table (of a stacked row: its table part) or the table optimum the compare page
 * draws for reference; no rows when there is no table.
 */
export const weightsCsv = (figure) => ({
  columns: ['table', 'strategy', 'lambda', ...WEIGHT_COLUMNS],
  rows: figure?.weights ? figureRows(figure) : [],
});

/**
 * The effective weights' columns (GET /v1/jobs/{id}/effective): which row and what kind of weight
 * function, the paths each side drew, then per (r₂, r₃) bin its bounds (an open edge empty), its
 * sampled paths and luminance share, and w₀, w₁, w₂ with their total standard errors (empty where
 * no sampled path of the bin carries light). Named as the weights table's columns where they mean
 * the same.
 */
export const EFFECTIVE_COLUMNS = ['table', 'strategy', 'kind', 'paths_per_side', 'r2_lo', 'r2_hi', 'r3_lo', 'r3_hi', 'paths',
  'luminance_share', 'w0', 'w0_stderr', 'w1', 'w1_stderr', 'w2', 'w2_stderr', 'w0_sampling_stderr', 'w1_sampling_stderr',
  'w2_sampling_stderr', 'w0_fit_stderr', 'w1_fit_stderr', 'w2_fit_stderr', 'note'];

/**
 * The effective weights Fig. 2 draws (`doc`, null while there are none) as CSV rows, one per bin in
 * the document's order: the columns of the server's `?format=csv&table=effective` (docs/csv.md).
 */
export const effectiveCsv = (doc) => ({
  columns: EFFECTIVE_COLUMNS,
  rows: (doc?.bins ?? []).map((b) => ({
    table: 'effective', strategy: doc.strategy, kind: doc.kind, paths_per_side: doc.paths_per_side,
    r2_lo: b.r2[0], r2_hi: b.r2[1], r3_lo: b.r3[0], r3_hi: b.r3[1], paths: b.paths, luminance_share: b.luminance_share,
    w0: b.w?.[0], w0_stderr: b.stderr?.[0], w1: b.w?.[1], w1_stderr: b.stderr?.[1], w2: b.w?.[2], w2_stderr: b.stderr?.[2],
    w0_sampling_stderr: b.sampling_stderr?.[0], w1_sampling_stderr: b.sampling_stderr?.[1], w2_sampling_stderr: b.sampling_stderr?.[2],
    w0_fit_stderr: b.fit_stderr?.[0], w1_fit_stderr: b.fit_stderr?.[1], w2_fit_stderr: b.fit_stderr?.[2],
    note: b.w ? '' : 'no sampled path of this bin carries light',
  })),
});

/** The history, one row per checkpoint and strategy, with SE(L) = L · (RMS/100) / √M. */
export const historyCsv = (history) => ({
  columns: ['iterations', 'strategy', 'luminance', 'luminance_stderr', 'rms_percent'],
  rows: history.points.flatMap((p) => p.strategies.map((s) => ({
    iterations: p.iterations,
    strategy: s.strategy,
    luminance: s.luminance,
    luminance_stderr: luminanceStderr(s.luminance, s.rms_percent, p.iterations),
    rms_percent: s.rms_percent,
  }))),
});

/** The compare page's table: one row per job (`entries`: { job, result }) and strategy, the job's parameters in front. */
export function compareCsv(entries) {
  const rows = entries.filter((e) => e.job && e.result).flatMap(({ job, result }) => {
    const { spec } = job;
    const ill = spec.scene.illumination;
    const context = {
      job_id: job.id, preset: spec.preset, illumination: ill.kind, spot_a: ill.kind === 'spot' ? ill.a : null, engine: spec.engine || 'brute',
      light_paths: spec.light_paths, camera_paths: spec.camera_paths, merge_radius: spec.merge_radius, iterations: result.iterations, seed: spec.seed,
    };
    return noiseRows(result).map((row) => ({ ...context, ...row }));
  });
  return { columns: [...JOB_COLUMNS, ...NOISE_COLUMNS], rows };
}

/** Every compared job's drawn weights table (`entries`: { id, figure }), one row per job and cell, `job_id` in front. */
export const compareWeightsCsv = (entries) => ({
  columns: ['job_id', 'table', 'strategy', 'lambda', ...WEIGHT_COLUMNS],
  rows: entries.filter((e) => e.figure?.weights).flatMap(({ id, figure }) => figureRows(figure).map((row) => ({ job_id: id, ...row }))),
});
