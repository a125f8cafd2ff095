// A job's specification as named fields, and the fields in which a set of jobs differ: what the job
// list's runs table shows as sortable columns, what the compare page marks as varying and what the
// job page lists (issue 42, item 2). A field is a JSON path of the job document (`scene.l3`,
// `solver.lambda`), the path the API's errors, sweeps and `optimis compare` name. Imports format.js.

import { formatCount, formatParameter, h } from './format.js';

// Shown elsewhere (the name and notes in their own rows, labels as chips), so never a column.
const NOT_PARAMETERS = new Set(['name', 'notes', 'labels']);

// The paper's symbols for the fields it names, in the order a reader of the paper expects them;
// any other field comes after these, by path.
const KNOWN = [
  ['preset', 'Preset'],
  ['engine', 'Engine'],
  ['light_paths', ['', ['N', 'F']]],
  ['camera_paths', ['', ['N', 'B']]],
  ['merge_radius', ['', ['R']]],
  ['radii', ['radii ', ['R′']]],
  ['scene.l2', ['', ['L', '2']]],
  ['scene.l3', ['', ['L', '3']]],
  ['scene.beta_deg', ['', ['β']]],
  ['scene.illumination.kind', 'Illumination'],
  ['scene.illumination.a', ['spot ', ['a']]],
  ['scene.illumination.r_ls', ['', ['r', 'ls']]],
  ['scene.illumination.contrast', 'Spot contrast'],
  ['scene.illumination.rings', 'Rings'],
  ['iterations', ['', ['M']]],
  ['seed', 'Seed'],
  ['solver.lambda', ['', ['λ']]],
  ['solver.cv_lambdas', 'λ grid'],
  ['folds', 'Folds'],
  ['cells', 'Cells'],
];
const ORDER = new Map(KNOWN.map(([path], i) => [path, i]));
const LABELS = new Map(KNOWN);

// Kept whole rather than split into their elements: a grid or a list is one setting.
const WHOLE = new Set(['cells', 'scene.illumination.rings', 'solver.cv_lambdas']);

/** The spec's parameters as a Map path → value (numbers, strings, booleans; grids and lists whole). */
export function flattenSpec(spec) {
  const fields = new Map();
  const walk = (value, path) => {
    if (NOT_PARAMETERS.has(path)) return;
    if (value !== null && typeof value === 'object' && !Array.isArray(value) && !WHOLE.has(path)) {
      for (const [key, inner] of Object.entries(value)) walk(inner, path ? `${path}.${key}` : key);
    } else if (value !== undefined) {
      fields.set(path, value);
    }
  };
  walk(spec ?? {}, '');
  if (!fields.has('engine')) fields.set('engine', 'brute'); // the default the server applies
  return fields;
}

/** Orders field paths: the paper's first, in its order, then the rest alphabetically. */
export function byField(a, b) {
  const [ia, ib] = [ORDER.get(a) ?? Infinity, ORDER.get(b) ?? Infinity];
  return ia !== ib ? ia - ib : a.localeCompare(b);
}

const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);

/** The paths whose values are not the same in every spec of `specs` (a missing field counts as a value). */
export function varyingFields(specs) {
  const flat = specs.map(flattenSpec);
  const paths = new Set(flat.flatMap((f) => [...f.keys()]));
  return [...paths].filter((p) => flat.some((f) => !same(f.get(p), flat[0].get(p)))).sort(byField);
}

/** The field's name as the paper writes it (e.g. L₃ in italics), with its path as a tooltip. */
export function fieldLabel(path) {
  const label = LABELS.get(path);
  if (label === undefined) return h('span', { title: path }, h('code', {}, path));
  if (typeof label === 'string') return h('span', { title: path }, label);
  const [prefix, [symbol, sub]] = label;
  return h('span', { title: path }, prefix, h('var', {}, symbol), sub ? h('sub', {}, sub) : null);
}

/** The field's name in plain text (L3, β, seed): for tooltips and messages. */
export function fieldText(path) {
  const label = LABELS.get(path);
  if (label === undefined) return path;
  if (typeof label === 'string') return label;
  const [prefix, [symbol, sub]] = label;
  return `${prefix}${symbol}${sub ?? ''}`;
}

/** A field's value in words: counts grouped, parameters as 10ⁿ when they are decades, grids by size. */
export function formatField(path, value) {
  if (value === undefined || value === null) return '—';
  if (path === 'cells') return `${value.r2_edges.length} × ${value.r3_edges.length} × ${value.phi_bins}`;
  if (path === 'scene.beta_deg') return `${formatParameter(value)}°`;
  if (path === 'seed' || path === 'first_iteration') return String(value); // an identifier, not a size
  if (typeof value === 'number') {
    return Number.isInteger(value) && Math.abs(value) >= 1000 && !Number.isInteger(Math.log10(value))
      ? formatCount(value) : formatParameter(value);
  }
  if (typeof value === 'boolean') return value ? 'yes' : 'no';
  if (typeof value === 'string') return value;
  if (Array.isArray(value) && value.length <= 8 && value.every((x) => typeof x === 'number')) {
    return value.map(formatParameter).join(', ');
  }
  return Array.isArray(value) ? `${value.length} items` : JSON.stringify(value);
}

/** Compares two values of one field for sorting: numbers by size, the rest as text; missing last. */
export function compareValues(a, b) {
  if (a === undefined || a === null) return b === undefined || b === null ? 0 : 1;
  if (b === undefined || b === null) return -1;
  if (typeof a === 'number' && typeof b === 'number') return a - b;
  return String(typeof a === 'object' ? JSON.stringify(a) : a).localeCompare(String(typeof b === 'object' ? JSON.stringify(b) : b));
}
