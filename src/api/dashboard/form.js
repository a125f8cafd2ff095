// The submit form on the list page: reading its fields and extra overrides into a job document,
// posting it, and showing what is wrong with it.

import { api } from './api.js';
import { formatCount, showMessage } from './format.js';

class FormError extends Error {
  constructor(message, field) {
    super(message);
    this.field = field;
  }
}

export function setupSubmitForm(refs) {
  const form = refs.form;
  form.addEventListener('input', (event) => event.target.removeAttribute('aria-invalid'));
  form.addEventListener('submit', async (event) => {
    event.preventDefault();
    clearFormError(form, refs['form-error']);
    let submission;
    try {
      submission = buildSubmission(form);
    } catch (error) {
      showFormError(form, refs['form-error'], error.message, error.field);
      return;
    }
    refs.submit.disabled = true;
    refs.submit.textContent = 'Submitting…';
    try {
      const job = await api('/v1/jobs', { method: 'POST', body: submission });
      location.hash = `#/jobs/${job.id}`;
    } catch (error) {
      const prefix = error.status === 0 ? '' : 'The server rejected the job: ';
      showFormError(form, refs['form-error'], prefix + error.message, error.field);
    } finally {
      refs.submit.disabled = false;
      refs.submit.textContent = 'Submit job';
    }
  });
}

/** The submitted document: the preset, the filled-in fields, and the extra overrides. */
function buildSubmission(form) {
  const extra = parseExtra(form.elements.extra.value);
  const fields = { preset: form.elements.preset.value, engine: form.elements.engine.value };
  for (const input of form.querySelectorAll('input[data-kind]')) {
    const text = input.value.trim();
    if (text) setPath(fields, input.name.split('.'), parseField(input.name, text, input.dataset.kind));
  }
  for (const path of leafPaths(fields)) {
    if (getPath(extra, path) !== undefined) {
      const name = path.join('.');
      throw new FormError(`${name} is set both in its own field and in the extra overrides; keep only one.`, name);
    }
  }
  return deepMerge(extra, fields);
}

function parseExtra(text) {
  if (!text.trim()) return {};
  let value;
  try {
    value = JSON.parse(text);
  } catch (error) {
    throw new FormError(`The extra overrides are not valid JSON: ${error.message}`, 'extra');
  }
  if (typeof value !== 'object' || value === null || Array.isArray(value)) {
    throw new FormError('The extra overrides must be a JSON object, such as {"seed": 7}.', 'extra');
  }
  return value;
}

function parseField(name, text, kind) {
  // A list of numbers (radii): comma-separated, sent as a JSON array.
  if (kind === 'numbers') {
    return text.split(',').map((part) => {
      const item = part.trim();
      const value = Number(item);
      if (item === '' || !Number.isFinite(value)) throw new FormError(`${name}: “${item}” is not a number (give numbers separated by commas, such as 0.001, 0.002).`, name);
      return value;
    });
  }
  const value = Number(text);
  if (!Number.isFinite(value)) throw new FormError(`${name}: “${text}” is not a number.`, name);
  // Counts are sent as JSON numbers, exact only up to 2⁵³.
  if (kind === 'integer' && !Number.isSafeInteger(value)) {
    throw new FormError(`${name}: must be a whole number up to ${formatCount(Number.MAX_SAFE_INTEGER)}, got “${text}”.`, name);
  }
  return value;
}

const isObject = (v) => typeof v === 'object' && v !== null && !Array.isArray(v);

function getPath(object, path) {
  return path.reduce((node, key) => (isObject(node) ? node[key] : undefined), object);
}

function setPath(object, path, value) {
  const last = path.at(-1);
  const parent = path.slice(0, -1).reduce((node, key) => (node[key] ??= {}), object);
  parent[last] = value;
}

function leafPaths(object, prefix = []) {
  return Object.entries(object).flatMap(([key, value]) =>
    isObject(value) ? leafPaths(value, [...prefix, key]) : [[...prefix, key]]);
}

function deepMerge(target, source) {
  for (const [key, value] of Object.entries(source)) {
    target[key] = isObject(value) && isObject(target[key]) ? deepMerge(target[key], value) : value;
  }
  return target;
}

function clearFormError(form, message) {
  showMessage(message, '');
  for (const el of form.querySelectorAll('[aria-invalid]')) el.removeAttribute('aria-invalid');
}

/** Shows `text` and marks the input named by the problem's `field` (or the JSON box for others). */
function showFormError(form, message, text, field) {
  showMessage(message, text);
  if (!field) return;
  const input = form.elements.namedItem(field) ?? (form.elements.extra.value.trim() ? form.elements.extra : null);
  if (input) {
    input.setAttribute('aria-invalid', 'true');
    input.setAttribute('aria-describedby', message.id);
    input.focus();
  }
}
