// Results of a job: fetching its result and history as checkpoints arrive, the noise table, and
// the plots drawn from them (plots.js).

import { TERMINAL, api } from './api.js';
import { fixed, formatCount, formatLuminance, formatParameter, formatRms, h, showMessage, withError } from './format.js';
import { drawHistory, drawWeights } from './plots.js';

/**
 * Fetches the result and history whenever a new checkpoint is written or the job ends, one fetch
 * at a time (a change during a fetch triggers one more).
 */
export class ResultsLoader {
  constructor(id, refs, weightsPlot, historyPlot) {
    Object.assign(this, { id, refs, weightsPlot, historyPlot, shownKey: null, busy: false, again: false, stopped: false });
  }

  /** Leaves the page: answers still on their way are dropped. */
  stop() {
    this.stopped = true;
  }

  update(job) {
    this.job = job;
    const key = `${job.progress.iterations_checkpointed}:${TERMINAL.has(job.state)}`;
    if (key === this.shownKey) return;
    this.shownKey = key;
    if (job.progress.iterations_checkpointed === 0) {
      this.showNothing('No results yet: the job has not written its first checkpoint.');
    } else {
      this.fetch();
    }
  }

  async fetch() {
    if (this.busy) {
      this.again = true;
      return;
    }
    this.busy = true;
    try {
      const [result, history] = await Promise.all([
        api(`/v1/jobs/${this.id}/result`),
        api(`/v1/jobs/${this.id}/history`),
      ]);
      if (!this.stopped) this.show(result, history);
    } catch (error) {
      // 409: no checkpoint yet (or it is unreadable); the detail says which.
      // The next checkpoint tries again (not the next progress event: that would be 4 requests/s).
      if (!this.stopped) {
        this.showNothing(error.status === 409 ? `No results yet: ${error.message}` : `Cannot load the results: ${error.message}`);
      }
    } finally {
      this.busy = false;
      if (this.again && !this.stopped) {
        this.again = false;
        this.fetch();
      }
    }
  }

  showNothing(text) {
    const refs = this.refs;
    showMessage(refs['no-results'], text);
    refs['noise-table'].hidden = true;
    refs['result-status'].replaceChildren();
    showMessage(refs.reference, '');
    showMessage(refs['solve-error'], '');
    refs.gain.textContent = '';
    refs.warnings.hidden = true;
    refs.merges.textContent = '';
    this.weightsPlot.clear('The weights appear after the first checkpoint.');
    this.historyPlot.clear('The RMS history appears after the first checkpoint.');
  }

  show(result, history) {
    const refs = this.refs;
    showMessage(refs['no-results'], '');
    refs['noise-table'].hidden = false;
    refs['result-status'].replaceChildren(result.partial
      ? h('span', { class: 'badge badge-partial', title: 'The numbers change as the job runs' },
        `partial · ${formatCount(result.iterations)} iterations`)
      : h('span', { class: 'badge badge-final' }, `final · ${formatCount(result.iterations)} iterations`));
    showMessage(refs.reference, result.reference_luminance === null ? ''
      : `Reference (quadrature): L·10⁵ = ${formatLuminance(result.reference_luminance)}`);
    const best = this.job.progress.best?.strategy;
    const recommended = result.recommended?.strategy;
    refs['noise-rows'].replaceChildren(...result.noise_table.map((row) => noiseRow(row, this.job.spec, best, recommended, result.folds)));
    showMessage(refs['solve-error'], result.solve_error ? `The weight fit failed: ${result.solve_error}` : '');
    refs.gain.textContent = describeGain(result.gain);
    refs.warnings.replaceChildren(...result.warnings.map((w) => h('li', { 'data-code': w.code },
      h('code', {}, w.code), ` ${w.message}`, w.cells?.length ? ` (cells ${w.cells.join(', ')})` : '')));
    refs.warnings.hidden = result.warnings.length === 0;
    refs.merges.textContent = describeMerges(result.merges_per_iteration);
    drawWeights(this.weightsPlot, refs['weights-note'], result.weights, this.job.spec.cells.phi_bins, result.weights_fit);
    drawHistory(this.historyPlot, refs['history-note'], history.points);
  }
}

function noiseRow(row, spec, best, recommended, folds) {
  const numbers = row.error
    ? [h('td', { class: 'row-error', colspan: 2 }, row.error)]
    : [
      h('td', { class: 'num' }, withError(row.luminance, row.luminance_stderr, formatLuminance)),
      h('td', { class: 'num' }, withError(row.rms_percent, row.rms_percent_stderr, formatRms)),
    ];
  return h('tr', { 'data-strategy': row.strategy, class: row.strategy === best ? 'best' : null },
    h('th', { scope: 'row' }, h('code', {}, row.strategy),
      row.strategy === best ? h('span', { class: 'best-mark', title: "Lowest honest RMS among the rows that keep the solver's fixed weights (in-sample fits are left out)" }, 'best') : null,
      row.strategy === recommended ? h('span', { class: 'recommended-mark', title: 'The weights table and chart show these weights' }, 'recommended') : null,
      row.in_sample ? h('span', { class: 'in-sample-mark', title: 'Fitted and scored on the same iterations: optimistic (L biased, SE and RMS too small)' }, 'in-sample') : null,
      row.respects_fixed === false ? h('span', { class: 'outside-mark', title: "Does not keep the solver's fixed weights: shown for comparison, never best" }, 'outside fixed weights') : null),
    h('td', {}, describeWeights(row, spec, folds)),
    ...numbers);
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

function describeGain(gain) {
  if (!gain) return '';
  const se = gain.stderr === null ? '' : ` ± ${fixed(gain.stderr, 2)}`;
  return `Gain of ${gain.strategy} over the best per-path strategy within the fixed weights (${gain.versus}): variance ratio ${fixed(gain.value, 2)}${se} (jackknife over the folds).`;
}

function describeMerges(merges) {
  if (!merges) return '';
  const planes = ['plane1', 'plane2', 'plane3']
    .filter((p) => merges[p])
    .map((p) => `${p} ${withError(merges[p].mean, merges[p].stderr, (x) => fixed(x, x >= 10 ? 1 : 2))}`);
  return `Merges per iteration: ${planes.join(' · ')}`;
}
