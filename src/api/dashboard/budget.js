// The job page's ray-budget panel: for a job run with noise components, a form for the target RMS
// and the renderer's costs that asks POST /v1/jobs/{id}/budget for the (N_F, N_B) reaching the
// target soonest, and shows the plan (budgetplan.js) with a download of it as JSON. With a target
// RMSE (the noise and the merge radius's bias together) and a cost per merge, the server also plans
// over the radii the job tallied (`error_plan`, shown by errorplan.js). A job without noise
// components gets one line saying how to run one. Nothing runs until asked: the server re-fits the
// weights at every budget of its grid (a fraction of a second to seconds).

import { api, saveBlob } from './api.js';
import { formatCount, formatScientific, h, showMessage } from './format.js';
import { headlineOf, planTable, searchNote } from './budgetplan.js';
import { errorPlanSection } from './errorplan.js';

// The target and P filled in at first; the costs left blank take the server's reference costs
// (the brute force on the paper's scene, 2 cores: docs/results.md §7), as `optimis budget` and the
// API do — one document and one set of costs give one plan in every front end. The placeholders
// show the reference's values once a plan has said them. The target RMSE is optional (blank: no
// error plan); with it, the target RMS may be left blank (the server then takes the RMSE's value).
const FIELDS = [
  { name: 'target_rms', label: 'Target RMS (%)', value: '1', blankWith: 'target_rmse', title: 'The RMS noise of the pixel to reach, in percent (blank with a target RMSE: that value)' },
  { name: 'target_rmse', label: 'Target RMSE (%)', value: '', optional: true, placeholder: 'optional', title: "Optional: the relative RMSE about the true pixel value to reach, in percent — the noise and the merge radius's bias together — planned over the job's own R and every radius it tallied (radii)" },
  { name: 'light_cost', label: ['t', h('sub', {}, 'F'), ' (s per light path)'], value: '', cost: 'light_path', title: "Your renderer's seconds per light path (blank: the reference's)" },
  { name: 'camera_cost', label: ['t', h('sub', {}, 'B'), ' (s per camera path and pixel)'], value: '', cost: 'camera_path', title: "Your renderer's seconds per camera path, per pixel (blank: the reference's)" },
  { name: 'iteration_cost', label: ['t', h('sub', {}, '0'), ' (s per iteration)'], value: '', cost: 'iteration', title: "Seconds per iteration besides the paths (blank: the reference's)" },
  { name: 'merge_cost', label: ['t', h('sub', {}, 'M'), ' (s per merge and pixel)'], value: '', cost: 'merge', title: "Your renderer's seconds per merge event and pixel, for the target RMSE: what makes a larger radius cost time (blank: the reference's)" },
  { name: 'pixels', label: 'Pixels P', value: '1e6', title: 'Pixels of the image the light paths serve' },
];

/** The budget card of job `id`; `card` is its element, `update(job)` follows the job. */
export class BudgetPanel {
  constructor(id) {
    Object.assign(this, { id, job: null, plan: null, busy: false });
    this.inputs = Object.fromEntries(FIELDS.map((f) => [f.name, h('input', { name: f.name, value: f.value, inputmode: 'decimal', autocomplete: 'off', size: 9, title: f.title, placeholder: f.cost ? 'reference' : f.placeholder ?? null })]));
    this.submit = h('button', { type: 'submit', class: 'primary' }, 'Plan the budget');
    this.error = h('p', { class: 'notice notice-error', id: `budget-error-${id}`, role: 'alert', 'data-ref': 'budget-error', hidden: true });
    this.form = h('form', { class: 'budget-form', novalidate: true, 'data-ref': 'budget-form' },
      h('div', { class: 'field-grid' }, FIELDS.map((f) => h('label', { class: 'field' }, h('span', {}, f.label), this.inputs[f.name]))),
      this.submit);
    this.form.addEventListener('input', (event) => event.target.removeAttribute('aria-invalid'));
    this.form.addEventListener('submit', (event) => {
      event.preventDefault();
      this.request();
    });
    this.intro = h('p', { class: 'hint' }, 'The (N', h('sub', {}, 'F'), ', N', h('sub', {}, 'B'), ') that reaches a target RMS soonest, predicted for every strategy from this run\'s noise components, with a renderer whose iteration costs t = t',
      h('sub', {}, 'F'), '·N', h('sub', {}, 'F'), ' + t', h('sub', {}, 'B'), '·N', h('sub', {}, 'B'), '·P + t', h('sub', {}, '0'),
      ' seconds. Costs left blank are the reference\'s (this crate\'s brute force on the paper\'s scene, 2 cores), as in optimis budget and the API; enter your renderer\'s.',
      ' With a target RMSE — the error about the true pixel value, noise and bias together — it also plans over the merge radius: the job\'s own R and the smaller radii R′ it tallied (its radii), each iteration\'s merges costing t', h('sub', {}, 'M'), ' per merge and pixel.');
    this.unavailable = h('p', { class: 'hint', 'data-ref': 'budget-unavailable', hidden: true },
      'Needs a job run with noise components: submit it with {"noise_components": true} in the extra overrides (N', h('sub', {}, 'F'), ' and N', h('sub', {}, 'B'), ' even).');
    this.result = h('div', { class: 'budget-result', 'data-ref': 'budget-result' });
    this.download = h('button', { type: 'button', class: 'download', 'data-download': 'json', hidden: true }, 'Plan (JSON)');
    this.download.addEventListener('click', () => this.plan && saveBlob(new Blob([`${JSON.stringify(this.plan, null, 2)}\n`], { type: 'application/json' }), `optimis-job-${id}-budget.json`));
    this.card = h('section', { class: 'card budget-card', 'aria-labelledby': `budget-heading-${id}`, 'data-ref': 'budget' },
      h('h2', { id: `budget-heading-${id}` }, 'Ray budget ', h('span', { class: 'hint' }, '(the fastest (N', h('sub', {}, 'F'), ', N', h('sub', {}, 'B'), ') to a target noise)')),
      this.unavailable, this.intro, this.form, this.error, this.result,
      h('div', { class: 'downloads', role: 'group', 'aria-label': 'Download the plan' }, this.download));
  }

  /** Shows the form for a job with noise components, else how to get one. */
  update(job) {
    this.job = job;
    const able = Boolean(job.spec.noise_components);
    this.unavailable.hidden = able;
    this.intro.hidden = !able;
    this.form.hidden = !able;
    this.submit.disabled = this.busy || job.progress.iterations_checkpointed === 0;
    this.submit.title = job.progress.iterations_checkpointed === 0 ? 'The plan needs the job\'s first checkpoint' : '';
  }

  /** The request body from the form, or throws naming the field that is not a number. */
  body() {
    const body = {};
    for (const f of FIELDS) {
      const text = this.inputs[f.name].value.trim();
      if (text === '' && (f.cost || f.optional)) continue; // the reference's, or none
      if (text === '' && f.blankWith && this.inputs[f.blankWith].value.trim() !== '') continue; // the server takes that one's
      const value = Number(text);
      if (text === '' || !Number.isFinite(value)) {
        const error = new Error(`${f.name}: “${text}” is not a number.`);
        error.field = f.name;
        throw error;
      }
      body[f.name] = value;
    }
    return body;
  }

  async request() {
    this.clearError();
    let body;
    try {
      body = this.body();
    } catch (error) {
      this.showError(error.message, error.field);
      return;
    }
    this.busy = true;
    this.submit.disabled = true;
    this.submit.textContent = 'Planning…';
    const iterations = this.job.progress.iterations_checkpointed;
    try {
      const plan = await api(`/v1/jobs/${this.id}/budget`, { method: 'POST', body });
      this.show(plan, iterations);
    } catch (error) {
      // 422: a field out of range (`field` names it); 409: no checkpoint yet, or no noise components.
      this.result.replaceChildren(); // an earlier plan no longer answers the form
      this.plan = null;
      this.download.hidden = true;
      const named = error.field && !error.message.startsWith(error.field);
      this.showError(named ? `${error.field}: ${error.message}` : error.message, error.field);
    } finally {
      this.busy = false;
      this.submit.textContent = 'Plan the budget';
      if (this.job) this.update(this.job);
    }
  }

  show(plan, iterations) {
    this.plan = plan;
    // A blank cost was the reference's: its placeholder now says which value that is.
    for (const f of FIELDS.filter((x) => x.cost && this.inputs[x.name].value.trim() === '')) {
      const value = plan.error_plan?.costs[f.cost] ?? plan.costs[f.cost];
      if (value !== undefined) this.inputs[f.name].placeholder = `reference ${formatScientific(value)}`;
    }
    const measured = { light_paths: this.job.spec.light_paths, camera_paths: this.job.spec.camera_paths };
    this.result.replaceChildren(...headlineOf(plan, { iterations: formatCount(iterations) }), planTable(plan),
      h('p', { class: 'hint', 'data-ref': 'budget-search' }, searchNote(plan, measured)),
      plan.error_plan ? errorPlanSection(plan.error_plan) : null);
    this.download.hidden = false;
  }

  clearError() {
    showMessage(this.error, '');
    for (const input of Object.values(this.inputs)) input.removeAttribute('aria-invalid');
  }

  /** Shows `text` and marks the input the problem's `field` names, as the submit form does. */
  showError(text, field) {
    showMessage(this.error, text);
    const input = field ? this.inputs[field] : null;
    if (input) {
      input.setAttribute('aria-invalid', 'true');
      input.setAttribute('aria-describedby', this.error.id);
      input.focus();
    }
  }
}
