// Named re-solves of a job (/v1/jobs/{id}/solves): a selector of the kept solves (`default`, the
// job's own options, marked) whose choice the results show, and a form that keeps new options —
// a gradient penalty λ and, optionally, w₀ freed — under a name.

import { api } from './api.js';
import { h, showMessage } from './format.js';

/** The solves panel in `root`; `onChoose(name)` shows the results of the chosen solve. */
export class SolvesPanel {
  constructor(id, root, onChoose) {
    Object.assign(this, { id, root, onChoose, chosen: 'default' });
    this.select = h('select', { 'data-ref': 'solve-select', 'aria-label': 'Solve shown' });
    this.select.addEventListener('change', () => this.choose(this.select.value));
    this.name = h('input', { name: 'name', placeholder: 'name, e.g. lambda-0.1', autocomplete: 'off', size: 16 });
    this.lambda = h('input', { name: 'lambda', inputmode: 'decimal', placeholder: 'λ, e.g. 0.1', size: 8 });
    this.freeW0 = h('input', { type: 'checkbox', name: 'free-w0' });
    this.error = h('p', { class: 'notice notice-error', hidden: true });
    const keep = h('button', { type: 'submit' }, 'Keep');
    const form = h('form', { class: 'solve-form', novalidate: true },
      this.name, ' ', this.lambda, ' ', h('label', {}, this.freeW0, ' free w₀'), ' ', keep);
    form.addEventListener('submit', (event) => {
      event.preventDefault();
      this.keep();
    });
    root.replaceChildren(
      h('span', { class: 'hint' }, 'Solve shown: '), this.select,
      h('span', { class: 'hint' }, ' · keep other options: '), form, this.error);
    this.load();
  }

  async load() {
    try {
      const list = await api(`/v1/jobs/${this.id}/solves`);
      this.select.replaceChildren(...list.solves.map((s) => h('option', { value: s.name },
        s.default ? `${s.name} (the job's own, λ = ${s.solver.lambda})` : `${s.name} (λ = ${s.solver.lambda}${s.solver.fixed.w0 === undefined || s.solver.fixed.w0 === null ? ', w₀ free' : ''})`)));
      this.select.value = this.chosen;
    } catch (error) {
      showMessage(this.error, `Cannot list the solves: ${error.message}`);
    }
  }

  choose(name) {
    this.chosen = name;
    this.onChoose(name);
  }

  async keep() {
    const name = this.name.value.trim();
    const patch = {};
    if (this.lambda.value.trim() !== '') patch.lambda = Number(this.lambda.value);
    if (this.freeW0.checked) patch.fixed = { w0: null };
    try {
      await api(`/v1/jobs/${this.id}/solves/${encodeURIComponent(name)}`, { method: 'PUT', body: patch });
      showMessage(this.error, '');
      this.chosen = name;
      await this.load();
      this.onChoose(name);
    } catch (error) {
      showMessage(this.error, error.field ? `${error.field}: ${error.message}` : error.message);
    }
  }
}
