// The harness of the browser test: the server and output directory from the command line, checks
// and their count, the page's problems (page errors, console errors, server errors) with the HTTP
// errors a step provokes on purpose, calls to the API, waiting, screenshots, and reading a uPlot
// chart. Shared by the scenario's modules (jobs.mjs, sweeps.mjs, research.mjs, dashboard.mjs).

import path from 'node:path';

// The rows of a noise table with the paper's fixed weight w0 = 0, in the server's order: the paper's
// cases and fits, the heuristics, the heuristics over planes 2–3, the stacked optimum and each
// stackable heuristic corrected by a table.
export const STRATEGIES = ['plane1', 'plane2', 'plane3', 'switch', 'optimal', 'optimal_holdout', 'optimal_cv', 'balance', 'power',
  'correlation_aware', 'balance_planes23', 'power_planes23', 'correlation_aware_planes23', 'optimal_stacked', 'switch_corrected',
  'balance_planes23_corrected', 'power_planes23_corrected', 'correlation_aware_planes23_corrected'];
// Cells whose weights the server copied from a neighbour: gaps in the weight charts, without a bar.
export const UNFITTED = new Set(['empty', 'uninformative']);
// The y range of the job page's λ = 0 panel (plots.js's WEIGHT_FRAME): a cell beyond it is marked
// at the frame's edge with its value.
export const WEIGHT_FRAME = [-0.5, 1.5];

export const [base, outDir] = process.argv.slice(2);
if (!base || !outDir) {
  console.error('usage: node dashboard.mjs BASE_URL OUT_DIR');
  process.exit(2);
}

export let passed = 0;
export function check(condition, what) {
  if (!condition) throw new Error(`check failed: ${what}`);
  passed += 1;
  console.log(`ok ${passed} - ${what}`);
}

// Page errors, console errors and server errors, reported by the next wait or check.
const problems = [];
// HTTP errors a step provokes on purpose: Chromium logs each failed request as a console error.
export const allowedHttpErrors = [];
// Until the token is entered, the page's API calls are expected to be refused with 401.
let signedOut = Boolean(process.env.OPTIMIS_TOKEN);

/** The token was accepted: from now on a 401 is a failure. */
export function signedIn() {
  signedOut = false;
}

export function watchPage(page) {
  page.on('pageerror', (error) => problems.push(`uncaught exception in the page: ${error.stack || error}`));
  page.on('console', (message) => {
    if (message.type() !== 'error') return;
    const status = /status of (\d{3})/.exec(message.text())?.[1];
    const url = message.location().url;
    if (signedOut && status === '401') return;
    const allowed = allowedHttpErrors.findIndex((a) => String(a.status) === status && url === new URL(a.path, base).href);
    if (allowed >= 0) allowedHttpErrors.splice(allowed, 1);
    else problems.push(`console error: ${message.text()}${url ? ` (${url})` : ''}`);
  });
  page.on('response', (response) => {
    if (response.status() >= 500) problems.push(`server error ${response.status()} for ${response.url()}`);
  });
}

export function assertNoProblems() {
  if (problems.length > 0) throw new Error(`the page reported problems:\n  ${problems.join('\n  ')}`);
}

export const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

const authHeaders = () => (process.env.OPTIMIS_TOKEN ? { Authorization: `Bearer ${process.env.OPTIMIS_TOKEN}` } : {});

/** Calls the server's API directly (not through the page): { status, body } with the body parsed if JSON. */
export async function callApi(urlPath, { method = 'GET', body } = {}) {
  const headers = { ...authHeaders(), ...(body === undefined ? {} : { 'Content-Type': 'application/json' }) };
  const response = await fetch(new URL(urlPath, base), { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const text = await response.text();
  const json = (response.headers.get('content-type') || '').includes('json') ? JSON.parse(text) : null;
  return { status: response.status, text, json };
}

/** Polls `probe` until it returns a truthy value, failing early on page problems. */
export async function waitFor(what, probe, timeoutMs = 30_000) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    assertNoProblems();
    const value = await probe();
    if (value) return value;
    if (Date.now() > deadline) throw new Error(`timed out after ${timeoutMs / 1000} s waiting for ${what}`);
    await sleep(50);
  }
}

export async function screenshot(page, name) {
  const file = path.join(outDir, name);
  await page.screenshot({ path: file, fullPage: true });
  console.log(`   screenshot ${file}`);
}

/** "26.26 ± 0.75" → [26.26, 0.75]; "8.29" → [8.29, null]. */
export function parseWithError(text) {
  const numbers = text.replace(/,/g, '').split('±').map((part) => Number.parseFloat(part.trim()));
  return [numbers[0], numbers.length > 1 ? numbers[1] : null];
}

/**
 * What a uPlot chart in `container` shows: its canvas size and drawn pixels, the labels of its
 * legend (the y series; the x series left out), and what the chart kit's plugins report drawing:
 * error bars, SE bands, markers (and how many of them open), guide lines (`x=0.02 y=26.3`).
 */
export async function readPlot(container) {
  return container.evaluate((el) => {
    const canvas = el.querySelector('canvas');
    if (!canvas) return null;
    const { data } = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height);
    let inked = 0;
    for (let i = 3; i < data.length; i += 4) if (data[i] > 0) inked += 1;
    return {
      width: canvas.width, height: canvas.height, inked,
      labels: [...el.querySelectorAll('.u-legend .u-series .u-label')].slice(1).map((l) => l.textContent.trim()),
      errorBars: el.dataset.errorBars === undefined ? null : Number(el.dataset.errorBars),
      markers: el.dataset.markers === undefined ? null : Number(el.dataset.markers),
      openMarkers: el.dataset.openMarkers === undefined ? null : Number(el.dataset.openMarkers),
      bands: el.dataset.bands === undefined ? null : Number(el.dataset.bands),
      guides: el.dataset.guides ?? null,
      offScale: el.dataset.offScale === undefined ? null : Number(el.dataset.offScale),
      offScaleText: el.dataset.offScaleText ?? null,
    };
  });
}

/** The canvas of a uPlot chart has a size, has been drawn on, and its legend names the series. */
export async function checkPlot(page, ref, what, expectedLabels) {
  const plot = await readPlot(page.locator(`[data-ref="${ref}"]`));
  check(plot !== null, `the ${what} plot has a canvas`);
  check(plot.width > 0 && plot.height > 0 && plot.inked > 1000,
    `the ${what} plot is ${plot.width}×${plot.height} px with ${plot.inked} drawn pixels`);
  for (const label of expectedLabels) {
    check(plot.labels.some((l) => l.startsWith(label)), `the ${what} legend names "${label}"`);
  }
}


/**
 * The weights table the compare overlay should draw for a job's `result`: the
 * recommended table, or — a per-path strategy recommended — the table optimum at optimal_cv's λ,
 * fetched as the page does. `prefix` starts the series' legend labels.
 */
export async function expectedFigure(id, result) {
  const rec = result.recommended;
  if (result.weights.length > 0) {
    return { kind: 'recommended', strategy: rec.strategy, weights: result.weights, prefix: rec.heuristics.length ? 'T₁ (table part)' : 'w₁' };
  }
  const { lambda } = result.noise_table.find((r) => r.strategy === 'optimal_cv');
  const optimum = (await callApi(`/v1/jobs/${id}/result?lambda=${lambda}`)).json;
  return { kind: 'table-optimum', lambda, weights: optimum.weights, prefix: 'w₁ (table optimum, not recommended)' };
}

/**
 * The markers the compare overlay draws for `weights` in the r₂ bins `r2s` (lower edges), first φ bin, tail and
 * copied cells left out: `open` those without a data SE (smoothed), `filled` the others, `bars` the
 * filled ones with an SE above 0.
 */
export function figureMarks(weights, r2s) {
  const phi = Math.min(...weights.map((w) => w.phi[0]));
  const drawn = weights.filter((w) => r2s.includes(w.r2[0]) && w.phi[0] === phi && w.r3[1] !== null && !UNFITTED.has(w.status));
  const open = drawn.filter((w) => w.status === 'smoothed' || w.w1_stderr === null);
  return { open: open.length, filled: drawn.length - open.length, bars: drawn.filter((w) => !open.includes(w) && w.w1_stderr > 0).length };
}

/** An r₂ bin as the page names it: `r₂ ∈ [0, 0.5)`, `r₂ ≥ 0.5` for the open one. */
export const r2Words = (r2) => (r2[1] === null ? `r₂ ≥ ${r2[0]}` : `r₂ ∈ [${r2[0]}, ${r2[1]})`);

/** A value marked at a chart's edge as the page writes it: three significant digits, a real minus. */
export const edgeText = (v, e) => {
  const n = (x) => String(Number(x.toPrecision(3))).replace('-', '−');
  return `${n(v)}${e === null || e === undefined ? '' : ` ± ${n(e)}`}`;
};

/** The r₂ bins of `rows` (effective bins or weight cells), in order. */
const r2Bins = (rows) => [...new Map(rows.map((b) => [b.r2[0], b.r2])).values()].sort((a, b) => a[0] - b[0]);

/**
 * What the job page's effective panel draws from an /effective document `eff`: the r₂ bins with a
 * light-carrying path (`lit`: a w₁ and a w₂ series each) and without (`dark`: a caption note
 * instead), the bins with weights (`drawn`: a filled w₁ and a hollow w₂ marker each) and the error
 * bars (an SE above 0).
 */
export function effectiveMarks(eff) {
  const r2s = r2Bins(eff.bins);
  const lit = r2s.filter((r2) => eff.bins.some((b) => b.r2[0] === r2[0] && b.w));
  const withW = eff.bins.filter((b) => b.w);
  return {
    lit, dark: r2s.filter((r2) => !lit.includes(r2)), drawn: withW.length,
    bars: withW.reduce((n, b) => n + (b.stderr[1] > 0) + (b.stderr[2] > 0), 0),
  };
}

/**
 * What the job page's λ = 0 panel draws from the table `weights` (first φ bin, the tail cell
 * included): per r₂ bin with data a series (`lit`; `dark`: every cell copied), a marker per cell
 * fitted to data within WEIGHT_FRAME (`open` those without a data SE), a bar per such filled cell
 * with an SE above 0, an edge mark per cell beyond the frame (`off`), and `copied` the cells copied
 * from a neighbour in the bins with data (gaps).
 */
export function lambdaZeroMarks(weights) {
  const phi = Math.min(...weights.map((w) => w.phi[0]));
  const cells = weights.filter((w) => w.phi[0] === phi);
  const data = cells.filter((w) => !UNFITTED.has(w.status));
  const inside = data.filter((w) => w.w1 >= WEIGHT_FRAME[0] && w.w1 <= WEIGHT_FRAME[1]);
  const noSe = (w) => w.status === 'smoothed' || w.w1_stderr === null;
  const lit = r2Bins(cells).filter((r2) => data.some((w) => w.r2[0] === r2[0]));
  return {
    lit, dark: r2Bins(cells).filter((r2) => !lit.includes(r2)),
    markers: inside.length, open: inside.filter(noSe).length, bars: inside.filter((w) => !noSe(w) && w.w1_stderr > 0).length,
    off: data.filter((w) => !inside.includes(w)),
    copied: cells.filter((w) => UNFITTED.has(w.status) && lit.some((r2) => r2[0] === w.r2[0])).length,
  };
}

/**
 * How the chart in `container` lays out its axes and legend, read from its uPlot instance (through
 * plots.js's plotOf: the page's own module) and measured here with the axes' own fonts: per axis its
 * label's width against the plot side it runs along, its widest tick label against the room the
 * axis gives tick labels, its ticks and whether they are evenly spaced (a linear axis's steps all
 * equal, its labels all with as many decimals); and the legend's names and values as shown.
 */
export async function readAxes(container) {
  return container.evaluate(async (el) => {
    const { plotOf } = await import('/assets/plots.js');
    const u = plotOf(el);
    if (!u) return null;
    const ratio = window.uPlot.pxRatio;
    const width = (font, text) => {
      u.ctx.font = font;
      return u.ctx.measureText(String(text)).width / ratio;
    };
    const axes = u.axes.map((a, i) => {
      const vertical = a.side % 2 === 1;
      const values = (a._values ?? []).map(String);
      const splits = a._splits ?? [];
      const steps = splits.slice(1).map((v, k) => v - splits[k]);
      const log = u.scales[a.scale ?? (i === 0 ? 'x' : 'y')].distr === 3;
      const decimals = values.map((v) => (/\.(\d+)$/.exec(v.replace(/,/g, ''))?.[1].length ?? 0));
      return {
        side: a.side,
        label: a.label ?? null,
        labelWidth: a.label ? width(a.labelFont[0], a.label) : 0,
        labelRoom: (vertical ? u.bbox.height : u.bbox.width) / ratio,
        tickWidth: vertical ? Math.max(0, ...values.map((v) => width(a.font[0], v))) : a.font[2] * 1.2,
        tickRoom: a._size - (a.ticks.show ? a.ticks.size : 0) - a.gap,
        values,
        log,
        even: log || steps.every((d) => Math.abs(d - steps[0]) <= 1e-9 * Math.abs(steps[0])),
        sameDecimals: log || decimals.every((d) => d === decimals[0]),
      };
    });
    const legend = [...el.querySelectorAll('.u-legend .u-series')].map((row) => ({
      label: row.querySelector('.u-label')?.textContent ?? '',
      value: row.querySelector('.u-value')?.textContent ?? '',
      shown: row.getBoundingClientRect().width > 0,
    }));
    return { axes, legend };
  });
}

/**
 * The chart in `container` (`what` in the messages): every axis label fits the side it runs along,
 * every axis is wide enough for its tick labels, linear ticks are evenly spaced and printed alike,
 * and with no cursor on the chart its legend reads as a key: names, no "—" (the x entry hidden).
 */
export async function checkAxes(page, container, what) {
  await page.mouse.move(0, 0); // no cursor on any chart: the legend as a screenshot shows it
  const read = await waitFor(`${what}'s axes`, () => readAxes(container), 10_000);
  for (const a of read.axes) {
    const name = a.side % 2 ? 'y' : 'x';
    check(a.label === null || a.labelWidth <= a.labelRoom,
      `${what}: the ${name} axis label "${a.label}" (${Math.round(a.labelWidth)} px) fits along its ${Math.round(a.labelRoom)} px`);
    check(a.tickWidth <= a.tickRoom + 0.5,
      `${what}: the ${name} axis gives its tick labels room (${Math.round(a.tickWidth)} ≤ ${Math.round(a.tickRoom)} px: ${a.values.join(' ')})`);
    check(a.even && a.sameDecimals, `${what}: the ${name} axis ticks are ${a.log ? 'decades and their 2 and 5 ×' : 'evenly spaced and printed alike'} (${a.values.join(' ')})`);
  }
  if (read.legend.length) {
    const [x, ...ys] = read.legend;
    check(!x.shown && ys.every((s) => s.value === '' && s.label.length > 0 && s.value !== '—'),
      `${what}: with no cursor the legend is a key of ${ys.length} names, no "—" (${ys.slice(0, 3).map((s) => s.label).join(', ')}…)`);
  }
  return read;
}
