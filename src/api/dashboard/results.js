// Results of a job: fetching its result (or a kept solve's, solves.js) and history as checkpoints
// arrive — then Fig. 2's data, the recommended row's effective weights (GET …/effective) and the
// in-sample λ = 0 table (GET …/result?lambda=0), each fetched once per checkpoint — and showing
// them: the noise table (noisetable.js) and, for a job run with radii, its figures at each radius
// (radiitable.js), Fig. 2's two panels (fig2.js) and the history charts
// (plots.js), with the CSV downloads of the noise table, the recommended weights table, the
// effective weights and the history, and the SVG/PNG downloads of the charts (chartfiles.js).

import { TERMINAL, api } from './api.js';
import { chartDownloads } from './chartfiles.js';
import { csvButton } from './csv.js';
import { effectiveCsv, historyCsv, noiseCsv, weightsCsv } from './csvtables.js';
import { fixed, formatCount, h, showMessage, withError } from './format.js';
import { drawEffective, drawLambdaZero, effectiveQuery, figureSource } from './fig2.js';
import { noiseRows, paperNote, recommendedNote, referenceNote } from './noisetable.js';
import { drawHistory, drawLuminance } from './plots.js';
import { radiiSection } from './radiitable.js';
import { SolvesPanel } from './solves.js';

/**
 * Fetches the result and history whenever a new checkpoint is written or the job ends, one fetch
 * at a time (a change during a fetch triggers one more), then Fig. 2's two documents. `plots`: the
 * PlotSlots of Fig. 2's panels (weights: the effective weights, lambdaZero: the λ = 0 table), the
 * luminance and history charts.
 */
export class ResultsLoader {
  constructor(id, refs, plots) {
    Object.assign(this, { id, refs, plots, shownKey: null, busy: false, again: false, stopped: false, result: null, history: null });
    // Fig. 2's documents fetched last, { key, value }: the server computes each afresh (paths drawn,
    // a re-solve), so they are fetched again only when the checkpoint or what is asked changes.
    this.effective = null; // value: { effective } or { error }
    this.lambdaZero = null; // value: { result } or { error }
    this.figure = null; // the recommended weights table, for "Weights (CSV)" (fig2.js's figureSource)
    this.effectiveShown = null; // the effective weights drawn, for "Effective weights (CSV)"
    this.solve = 'default';
    this.addDownloads();
    this.solves = new SolvesPanel(id, refs.solves, (name) => {
      this.solve = name;
      if (this.job) this.fetch();
    });
  }

  addDownloads() {
    const { refs, plots, id } = this;
    // "Weights (CSV)" is the recommended table, offered only when there is one (a per-path
    // heuristic has none); "Effective weights (CSV)" is what Fig. 2's first panel draws, for any kind.
    this.weightsButton = csvButton('Weights (CSV)', `optimis-job-${id}-weights.csv`, () => weightsCsv(this.figure));
    this.effectiveButton = csvButton('Effective weights (CSV)', `optimis-job-${id}-effective-weights.csv`, () => effectiveCsv(this.effectiveShown));
    this.effectiveButton.hidden = true; // until the effective weights are drawn
    refs['noise-downloads'].append(
      csvButton('Noise table (CSV)', `optimis-job-${id}-noise.csv`, () => noiseCsv(this.result)),
      this.weightsButton, this.effectiveButton,
      csvButton('History (CSV)', `optimis-job-${id}-history.csv`, () => historyCsv(this.history)));
    refs['weights-downloads'].append(chartDownloads(plots.weights, `optimis-job-${id}-fig2-w1`));
    refs['lambda0-downloads'].append(chartDownloads(plots.lambdaZero, `optimis-job-${id}-fig2-lambda0`));
    refs['luminance-downloads'].append(chartDownloads(plots.luminance, `optimis-job-${id}-luminance`));
    refs['history-downloads'].append(chartDownloads(plots.history, `optimis-job-${id}-rms-history`));
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
        api(this.solve === 'default' ? `/v1/jobs/${this.id}/result` : `/v1/jobs/${this.id}/solves/${encodeURIComponent(this.solve)}`),
        api(`/v1/jobs/${this.id}/history`),
      ]);
      if (this.stopped) return;
      this.show(result, history);
      // Fig. 2 after the table: the noise table need not wait for the paths and the re-solve.
      const own = this.solve === 'default';
      const [effective, lambdaZero] = await Promise.all([this.effectiveOf(result, own), this.lambdaZeroOf(result)]);
      if (!this.stopped && this.result === result) this.showFigure(result, effective, lambdaZero, own);
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

  /**
   * Panel (a)'s source for `result` (`own`: the job's own solver options): { effective,
   * recommended, kept }, or { message } / { error } (fig2.js's drawEffective). Fetched again only
   * when the checkpoint or the query changes.
   */
  async effectiveOf(result, own) {
    const query = effectiveQuery(this.id, result, own);
    if (!query.path) return { message: query.message, recommended: result.recommended };
    const key = `${result.iterations}:${result.partial}:${query.path}`;
    if (this.effective?.key !== key) {
      const value = await api(query.path).then((effective) => ({ effective }), (error) => ({ error: error.message }));
      this.effective = { key, value };
    }
    return { ...this.effective.value, recommended: result.recommended, kept: !own };
  }

  /**
   * Panel (b)'s source: the result at λ = 0 under the job's own solver options (whatever solve the
   * table shows), { result } or { error }; fetched again only when the checkpoint changes.
   */
  async lambdaZeroOf(result) {
    const key = `${result.iterations}:${result.partial}`;
    if (this.lambdaZero?.key !== key) {
      const value = await api(`/v1/jobs/${this.id}/result?lambda=0`).then((r) => ({ result: r }), (error) => ({ error: error.message }));
      this.lambdaZero = { key, value };
    }
    return this.lambdaZero.value;
  }

  showNothing(text) {
    const refs = this.refs;
    showMessage(refs['no-results'], text);
    refs['noise-table'].hidden = true;
    refs['noise-downloads'].hidden = true;
    refs['result-status'].replaceChildren();
    showMessage(refs.reference, '');
    showMessage(refs['paper-note'], '');
    refs['recommended-note'].replaceChildren();
    refs['recommended-note'].hidden = true;
    showMessage(refs['solve-error'], '');
    refs.gain.textContent = '';
    refs.warnings.hidden = true;
    refs.merges.textContent = '';
    refs.radii.replaceChildren();
    this.plots.weights.clear('The weights appear after the first checkpoint.');
    this.plots.lambdaZero.clear('The λ = 0 table appears after the first checkpoint.');
    showMessage(refs['weights-note'], '');
    showMessage(refs['lambda0-note'], '');
    refs['weights-kind'].textContent = '';
    this.figure = null;
    this.effectiveShown = null;
    this.weightsButton.hidden = true;
    this.effectiveButton.hidden = true;
    this.plots.luminance.clear('The luminance appears after the first checkpoint.');
    this.plots.history.clear('The RMS history appears after the first checkpoint.');
  }

  show(result, history) {
    this.result = result;
    this.history = history;
    const refs = this.refs;
    showMessage(refs['no-results'], '');
    refs['noise-table'].hidden = false;
    refs['noise-downloads'].hidden = false;
    refs['result-status'].replaceChildren(result.partial
      ? h('span', { class: 'badge badge-partial', title: 'The numbers change as the job runs' },
        `partial · ${formatCount(result.iterations)} iterations`)
      : h('span', { class: 'badge badge-final' }, `final · ${formatCount(result.iterations)} iterations`));
    showMessage(refs.reference, referenceNote(result, this.job.spec));
    const { rows, paper } = noiseRows(result, this.job);
    for (const th of refs['noise-table'].querySelectorAll('thead .paper-col')) th.hidden = !paper;
    refs['noise-rows'].replaceChildren(...rows);
    refs['recommended-note'].replaceChildren(...recommendedNote(result));
    refs['recommended-note'].hidden = !result.recommended;
    showMessage(refs['paper-note'], paperNote(this.job.spec, result));
    showMessage(refs['solve-error'], result.solve_error ? `The weight fit failed: ${result.solve_error}` : '');
    refs.gain.textContent = describeGain(result.gain);
    refs.warnings.replaceChildren(...result.warnings.map((w) => h('li', { 'data-code': w.code },
      h('code', {}, w.code), ` ${w.message}`, w.cells?.length ? ` (cells ${w.cells.join(', ')})` : '')));
    refs.warnings.hidden = result.warnings.length === 0;
    refs.merges.textContent = describeMerges(result.merges_per_iteration);
    // The details the reader opened stay open when the next checkpoint redraws them.
    const shown = refs.radii.querySelector('[data-ref="radii-table"]');
    const open = shown ? new Set([...shown.querySelectorAll('details[open]')].map((d) => d.dataset.radius)) : null;
    refs.radii.replaceChildren(...[radiiSection(result, open)].filter(Boolean));
    this.figure = figureSource(result, null, this.solve === 'default');
    this.weightsButton.hidden = this.figure.kind !== 'recommended';
    // Until the first figure arrives, say that it is coming; later ones replace the last in place.
    if (!this.plots.weights.plot) this.plots.weights.clear('Computing the effective weights…');
    if (!this.plots.lambdaZero.plot) this.plots.lambdaZero.clear('Fitting the λ = 0 table…');
    drawLuminance(this.plots.luminance, refs['luminance-note'], history.points, result.reference_luminance, result.recommended?.strategy);
    drawHistory(this.plots.history, refs['history-note'], history.points);
  }

  /** Fig. 2's two panels, once their documents for `result` are in. */
  showFigure(result, effective, lambdaZero, own) {
    const refs = this.refs;
    this.effectiveShown = effective.effective ?? null;
    this.effectiveButton.hidden = !this.effectiveShown;
    drawEffective(this.plots.weights, { note: refs['weights-note'], kind: refs['weights-kind'] }, effective, this.job.spec, `Job ${this.id}`);
    drawLambdaZero(this.plots.lambdaZero, refs['lambda0-note'], lambdaZero, this.job.spec, `Job ${this.id}`, !own);
  }
}

function describeGain(gain) {
  if (!gain) return '';
  const se = gain.stderr === null ? '' : ` ± ${fixed(gain.stderr, 3)}`;
  return `Gain of the recommended ${gain.strategy} over the best other per-path strategy within the fixed weights (${gain.versus}): variance ratio ${fixed(gain.value, 3)}${se} (paired jackknife over the folds).`;
}

function describeMerges(merges) {
  if (!merges) return '';
  const planes = ['plane1', 'plane2', 'plane3']
    .filter((p) => merges[p])
    .map((p) => `${p} ${withError(merges[p].mean, merges[p].stderr, (x) => fixed(x, x >= 10 ? 1 : 2))}`);
  return `Merges per iteration: ${planes.join(' · ')}`;
}
