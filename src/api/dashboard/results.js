// Results of a job: fetching its result (or a kept solve's, solves.js) and history as checkpoints
// arrive — and, when a per-path strategy is recommended, the table optimum for Fig. 2 — and showing
// them: the noise table (noisetable.js), Fig. 2 (fig2.js) and the history charts (plots.js), with
// the CSV downloads of the noise table, the weights and the history, and the SVG/PNG downloads of
// the charts (chartfiles.js).

import { TERMINAL, api } from './api.js';
import { chartDownloads } from './chartfiles.js';
import { csvButton } from './csv.js';
import { historyCsv, noiseCsv, weightsCsv } from './csvtables.js';
import { fixed, formatCount, h, showMessage, withError } from './format.js';
import { drawWeights, figureSource, tableOptimumLambda } from './fig2.js';
import { noiseRows, paperNote, recommendedNote, referenceNote } from './noisetable.js';
import { drawHistory, drawLuminance } from './plots.js';
import { SolvesPanel } from './solves.js';

/**
 * Fetches the result and history whenever a new checkpoint is written or the job ends, one fetch
 * at a time (a change during a fetch triggers one more). `plots`: the PlotSlots of the weights,
 * luminance and history charts.
 */
export class ResultsLoader {
  constructor(id, refs, plots) {
    Object.assign(this, { id, refs, plots, shownKey: null, busy: false, again: false, stopped: false, result: null, history: null });
    this.optimum = null; // the table optimum fetched last: { key, value }
    this.figure = null; // what Fig. 2 shows (fig2.js's figureSource)
    this.solve = 'default';
    this.addDownloads();
    this.solves = new SolvesPanel(id, refs.solves, (name) => {
      this.solve = name;
      if (this.job) this.fetch();
    });
  }

  addDownloads() {
    const { refs, plots, id } = this;
    refs['noise-downloads'].append(
      csvButton('Noise table (CSV)', `optimis-job-${id}-noise.csv`, () => noiseCsv(this.result)),
      csvButton('Weights (CSV)', `optimis-job-${id}-weights.csv`, () => weightsCsv(this.figure)),
      csvButton('History (CSV)', `optimis-job-${id}-history.csv`, () => historyCsv(this.history)));
    refs['weights-downloads'].append(chartDownloads(plots.weights, `optimis-job-${id}-fig2-w1`));
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
      const optimum = this.solve === 'default' ? await this.tableOptimum(result) : null;
      if (!this.stopped) this.show(result, history, optimum);
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
   * The table optimum at optimal_cv's λ when `result` recommends a per-path strategy (Fig. 2 draws
   * it for reference): { result } or { error }; null when not wanted. Fetched again only when the
   * iterations or λ change (the server re-solves for every request).
   */
  async tableOptimum(result) {
    const lambda = tableOptimumLambda(result);
    if (lambda === null) return null;
    const key = `${result.iterations}:${result.partial}:${lambda}`;
    if (this.optimum?.key !== key) {
      const value = await api(`/v1/jobs/${this.id}/result?lambda=${lambda}`)
        .then((optimum) => ({ result: optimum }), (error) => ({ error: error.message }));
      this.optimum = { key, value };
    }
    return this.optimum.value;
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
    this.plots.weights.clear('The weights appear after the first checkpoint.');
    refs['weights-kind'].textContent = '';
    this.figure = null;
    this.plots.luminance.clear('The luminance appears after the first checkpoint.');
    this.plots.history.clear('The RMS history appears after the first checkpoint.');
  }

  show(result, history, optimum) {
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
    this.figure = figureSource(result, optimum, this.solve === 'default');
    drawWeights(this.plots.weights, { note: refs['weights-note'], kind: refs['weights-kind'] }, this.figure, this.job.spec, `Job ${this.id}`);
    drawLuminance(this.plots.luminance, refs['luminance-note'], history.points, result.reference_luminance, result.recommended?.strategy);
    drawHistory(this.plots.history, refs['history-note'], history.points);
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
