// A job run with `radii`: its figures at each merge radius it tallied (the result's `radii`, the
// smaller radii R′ and its own R, ascending) — per radius a <details> with its merges per
// iteration and its recommended row, and per strategy the measured RMS % ± SE of one iteration and
// the bias ± its error against the R → 0 reference (by quadrature for the per-path rows, from L̂
// for the fitted ones: Monte Carlo, and as noisy as L̂). The own radius's details start open; a
// redraw (the next checkpoint) keeps those the reader opened or closed.

import { formatLuminance, formatParameter, formatRms, formatScientific, formatScientificWithError, h, withError } from './format.js';

const SOURCES = {
  quadrature: ['quad.', "The bias by quadrature of the strategy's expected luminance at R′ (± the quadrature's tolerance)"],
  monte_carlo: ['MC', "The bias of this run's L̂ at R′ against the reference (± L̂'s standard error): fitted weights have no quadrature"],
};

/**
 * The per-radius section of `result`, or null when the job tallied no radii. `open`: the radii
 * (as data-radius strings) whose details are open, when the section was shown before.
 */
export function radiiSection(result, open = null) {
  const radii = result.radii ?? [];
  if (radii.length === 0) return null;
  return h('section', { class: 'radii', 'data-ref': 'radii-table' },
    h('h3', {}, 'At each merge radius the run tallied'),
    h('p', { class: 'hint' }, "Measured on this run's iterations at every radius (the same paths, nested discs): L ± SE and the RMS % of one iteration ± SE; the bias is 100·(E[C] at R′ − L)/L against the R → 0 reference, the error no number of iterations removes, ± its error (quad.: quadrature; MC: from this run's L̂). Fitted rows are cross-fitted; the in-sample row is left out."),
    radii.map((report) => radiusDetails(report, open ? open.has(String(report.merge_radius)) : report.own)));
}

function radiusDetails(report, open) {
  const merges = report.merges_per_iteration.map((m) => formatScientific(m)).join(' · ');
  const summary = [`R′ = ${formatParameter(report.merge_radius)}`, report.own ? " (the job's own R)" : '', ` — merges per iteration (planes 1 · 2 · 3): ${merges}`,
    ...(report.recommended ? [' — recommended there: ', h('code', {}, report.recommended)] : [])];
  return h('details', { class: 'radius', 'data-radius': String(report.merge_radius), 'data-own': String(report.own), open },
    h('summary', {}, summary),
    h('div', { class: 'table-wrap' }, h('table', { class: 'radius-table' },
      h('thead', {}, h('tr', {},
        h('th', { scope: 'col' }, 'Strategy'),
        h('th', { scope: 'col', class: 'num' }, h('var', {}, 'L'), '·10', h('sup', {}, '5'), ' ± SE'),
        h('th', { scope: 'col', class: 'num' }, 'RMS % ± SE'),
        h('th', { scope: 'col', class: 'num' }, 'Bias % ± err'),
        h('th', { scope: 'col' }, 'Bias from'))),
      h('tbody', {}, report.rows.map((row) => radiusRow(row, report))))));
}

function radiusRow(row, report) {
  const [source, title] = SOURCES[row.bias_source] ?? [row.bias_source, ''];
  const value = (x, se, format) => (x === null || x === undefined ? '—' : withError(x, se ?? null, format));
  return h('tr', { 'data-strategy': row.strategy, class: row.strategy === report.recommended ? 'recommended' : null },
    h('th', { scope: 'row' }, h('code', {}, row.strategy),
      row.respects_fixed ? null : h('span', { class: 'outside-mark', title: "Does not keep the solver's fixed weights" }, 'outside fixed weights')),
    h('td', { class: 'num', 'data-col': 'luminance' }, value(row.luminance, row.luminance_stderr, formatLuminance)),
    h('td', { class: 'num', 'data-col': 'rms' }, value(row.rms_percent, row.rms_percent_stderr, formatRms)),
    h('td', { class: 'num', 'data-col': 'bias' }, row.bias_percent === null || row.bias_percent === undefined ? '—' : formatScientificWithError(row.bias_percent, row.bias_percent_stderr)),
    h('td', { 'data-col': 'bias_source', title }, source));
}
