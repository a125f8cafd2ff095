// The paper's configuration — to say in which fields a job differs when the server attached no
// published table to its result (the figures themselves come from the server: the result's
// `references`, from the repository's references/*.json) — and the standard error of a luminance
// from its RMS. No DOM here. (A row's z is the server's, against the row's own expectation at R:
// noisetable.js.)

// The paper's configuration (the preset paper-table1): what the paper's values depend on.
// Iterations, seed, engine, cells and λ are left free: the luminance and the per-iteration RMS do
// not depend on them (the cells and λ only move the optimal row, and the paper's grid is the preset's).
const PAPER = [
  ['preset', (s) => s.preset, 'paper-table1'],
  ['light_paths', (s) => s.light_paths, 1e7],
  ['camera_paths', (s) => s.camera_paths, 100],
  ['merge_radius', (s) => s.merge_radius, 0.003],
  ['scene.l2', (s) => s.scene.l2, 1],
  ['scene.l3', (s) => s.scene.l3, 3],
  ['scene.beta_deg', (s) => s.scene.beta_deg, 3],
  ['scene.illumination.kind', (s) => s.scene.illumination.kind, 'spot'],
  ['scene.illumination.a', (s) => s.scene.illumination.a, 0.02],
  ['scene.illumination.r_ls', (s) => s.scene.illumination.r_ls, 20],
  ['scene.illumination.contrast', (s) => s.scene.illumination.contrast, (20 / 0.02) ** 2 / 300],
  ['solver.fixed.w0', (s) => s.solver.fixed?.w0, 0],
];

const same = (a, b) => (typeof b === 'number' ? typeof a === 'number' && Math.abs(a - b) <= 1e-9 * Math.max(1, Math.abs(b)) : a === b);

/** The fields in which `spec` differs from the paper's configuration (none: the paper's values apply). */
export function paperMismatches(spec) {
  return PAPER.filter(([, get, want]) => !same(get(spec), want)).map(([name]) => name);
}

/** SE(L) after `iterations` iterations from L and the per-iteration RMS %: L · (RMS/100) / √M. */
export const luminanceStderr = (luminance, rmsPercent, iterations) =>
  (luminance === null || rmsPercent === null || !(iterations > 0) ? null : Math.abs(luminance) * (rmsPercent / 100) / Math.sqrt(iterations));
