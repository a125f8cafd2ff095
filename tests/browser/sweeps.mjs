// The sweep steps of the browser test: a 2 × 2 sweep created through the API and followed on its
// page to the end — its summary, points, CSV, charts (their axes and legends; the effective w₁ of
// each point's recommended row as small multiples, one panel per point on shared axes, every one
// with points whatever the kind of recommendation, and their one SVG/PNG) and links — a predicted
// sweep, whose panels draw too, and a long one cancelled.

import { readFile } from 'node:fs/promises';

import { PNG_MIN_WIDTH } from './downloads.mjs';
import { downloadFrom, pngSize } from './files.mjs';
import { base, callApi, check, checkAxes, r2Words, readPlot, waitFor } from './harness.mjs';

// A 2 × 2 grid of the paper's scene at merge radii where the weights tables are informative (about
// 3 s per run on two cores): seeded; its points recommend per-path heuristics and fitted rows, and
// every panel draws its effective weights whatever the kind.
const SWEEP = {
  base: { iterations: 4000, seed: 3 },
  axes: [{ field: 'merge_radius', values: [0.01, 0.02] }, { field: 'scene.l3', values: [1, 3] }],
  mode: 'grid',
};
const ITERATIONS = SWEEP.base.iterations * 4;
// Runs far longer than the test: cancelled from its page.
const LONG_SWEEP = { base: { iterations: 1000000, light_paths: 1000000 }, axes: [{ field: 'seed', values: [1, 2] }] };

/** A sweep's values in the page's words: `merge_radius=0.003, scene.l3=1`. */
const describePoint = (sweep, point) => sweep.fields.map((f) => `${f}=${JSON.stringify(point.values[f])}`).join(', ');

/** The error bars the RMS chart of `field` should draw: rows with a positive RMS and standard error at the points where the other axes take the values `fixed`. */
function expectedRmsBars(sweep, field, fixed) {
  const points = sweep.points.filter((p) => Object.entries(fixed).every(([f, v]) => f === field || p.values[f] === v));
  return points.flatMap((p) => p.figures.noise_table.filter((r) => !(p.figures.unsupported ?? []).includes(r.strategy)))
    .filter((r) => r.rms_percent > 0 && r.rms_percent_stderr > 0).length;
}

/** Figures of predicted points that the chart leaves out: rows with an RMS that their run does not support there. */
const unsupportedFigures = (sweep) => sweep.points
  .flatMap((p) => p.figures.noise_table.filter((r) => r.rms_percent > 0 && (p.figures.unsupported ?? []).includes(r.strategy))).length;

// One run with noise components answers three budgets (its own and two predicted): at 400
// iterations some rows are not supported at the predicted ones (tests/sweeps.rs lists them).
const PREDICTED_SWEEP = {
  base: { iterations: 400, light_paths: 1000000, seed: 5 },
  axes: [{ field: 'light_paths', values: [300000, 1000000, 3000000], by: 'prediction' }],
};

/** A predicted sweep's RMS chart leaves out the figures its run does not support, and says how many. */
export async function checkPredictedSweep(page) {
  const created = await callApi('/v1/sweeps', { method: 'POST', body: PREDICTED_SWEEP });
  check(created.status === 201, `POST /v1/sweeps creates a predicted sweep (${created.status})`);
  const id = created.json.id;
  await page.goto(`${base}/#/sweeps/${id}`);
  await sweepSucceeds(page, 'the predicted sweep', 120_000);
  const sweep = (await callApi(`/v1/sweeps/${id}`)).json;
  const hidden = unsupportedFigures(sweep);
  check(sweep.points.every((p) => p.figures.source === 'predicted') && hidden > 0,
    `the API lists ${hidden} figures its run does not support (${sweep.points.map((p) => (p.figures.unsupported ?? []).join('+') || '—').join(', ')})`);
  const card = page.locator('[data-field="light_paths"]');
  const bars = expectedRmsBars(sweep, 'light_paths', {});
  const plot = await waitFor('the predicted RMS chart', async () => {
    const p = await readPlot(card.locator('.plot'));
    return p && p.errorBars === bars && p;
  }, 10_000);
  check(plot.inked > 1000, `its RMS chart draws ${plot.errorBars} error bars, none for an unsupported figure`);
  const note = await card.locator('p.hint').last().textContent();
  check(note.includes(`${hidden} predicted ${hidden === 1 ? 'figure is' : 'figures are'} not drawn: the run does not support them`),
    `its note says so ("${note.slice(note.indexOf('predicted figure') - 3, note.indexOf('predicted figure') + 60)}…")`);
  // Its points share one run: their weight panels draw that run's effective weights of each point's row.
  const panels = page.locator('[data-ref="w1-grid"] figure.w1-panel .plot');
  const markers = await waitFor('the predicted sweep\'s weight panels', async () => {
    const got = await panels.evaluateAll((plots) => plots.map((p) => Number(p.dataset.markers ?? 0)));
    return got.length === sweep.points.length && got.every((m) => m > 0) && got;
  }, 30_000);
  const w1Note = await page.locator('[data-ref="w1-note"]').textContent();
  check(w1Note.includes('A predicted point draws its recommended row as its run weights it'),
    `every predicted point's weight panel has points (${markers.join(', ')} markers), and the caption says whose weights they are`);
}

/**
 * What each point's panel should draw: its recommended row's effective weights (as the page asks
 * for them: 10,000 paths per side), in the first r₂ bin where some point's paths carry light — the
 * bins with a w₁ (a marker each) and those with an SE above 0 (a bar each) — and the point's
 * strategy and kind.
 */
async function expectedW1Panels(sweep) {
  const docs = [];
  for (const p of sweep.points) {
    docs.push((await callApi(`/v1/jobs/${p.job_id}/effective?paths=10000&strategy=${p.figures.recommended.strategy}`)).json);
  }
  const r2s = [...new Map(docs.flatMap((d) => d.bins.map((b) => [b.r2[0], b.r2]))).values()].sort((a, b) => a[0] - b[0]);
  const r2 = r2s.find((bin) => docs.some((d) => d.bins.some((b) => b.r2[0] === bin[0] && b.w)));
  return {
    r2,
    dark: r2s.filter((bin) => !docs.some((d) => d.bins.some((b) => b.r2[0] === bin[0] && b.w))),
    panels: docs.map((d) => {
      const lit = d.bins.filter((b) => b.r2[0] === r2[0] && b.w);
      return { strategy: d.strategy, kind: d.kind, markers: lit.length, bars: lit.filter((b) => b.stderr[1] > 0).length };
    }),
  };
}

/** Waits until the open sweep page's state badge reads succeeded (throws if it ends otherwise). */
async function sweepSucceeds(page, what, timeout) {
  await waitFor(`${what} to succeed`, async () => {
    const badge = await page.locator('[data-ref="state"] .badge').textContent().catch(() => '');
    if (badge === 'failed' || badge === 'cancelled') throw new Error(`${what} ended ${badge}`);
    return badge === 'succeeded';
  }, timeout);
}

/** The sweep list (from the header) leads to a sweep created through the API; its page follows it to the end. */
export async function openSweep(page) {
  const created = await callApi('/v1/sweeps', { method: 'POST', body: SWEEP });
  check(created.status === 201, `POST /v1/sweeps creates a 2 × 2 sweep (${created.status})`);
  const id = created.json.id;
  await page.locator('.topnav').getByRole('link', { name: 'Sweeps' }).click();
  const row = page.locator(`tr[data-sweep="${id}"]`);
  await waitFor(`sweep ${id} in the sweep list`, async () => (await row.count()) > 0);
  const axes = (await row.locator('td').nth(2).textContent()).replace(/\s+/g, ' ').trim();
  check(axes === 'merge_radius (2) × scene.l3 (2)', `the sweep list shows sweep ${id} with its axes "${axes}"`);
  await row.getByRole('link', { name: `#${id}` }).click();
  await waitFor('the sweep page', () => page.locator('h1', { hasText: `Sweep ${id}` }).isVisible());
  check(new URL(page.url()).hash === `#/sweeps/${id}`, `the list links to the sweep page #/sweeps/${id}`);
  await sweepSucceeds(page, 'the sweep', 180_000);
  const sweep = (await callApi(`/v1/sweeps/${id}`)).json;
  check(sweep.state === 'succeeded' && sweep.points.every((p) => p.figures && !p.figures.partial),
    'the API agrees: the sweep succeeded and every point has final figures');
  return sweep;
}

export async function checkSweepSummary(page, sweep) {
  const progress = await page.locator('[data-ref="progress"] .progress-text').textContent();
  const total = ITERATIONS.toLocaleString('en-US');
  check(progress === `${total} / ${total}`, `the sweep's progress bar reads ${progress} (4 runs × ${SWEEP.base.iterations} iterations)`);
  const runs = (await page.locator('[data-ref="runs-by-state"]').textContent()).replace(/\s+/g, ' ').trim();
  check(runs === 'succeeded 4', `the runs by state read "${runs}"`);
  check(await page.locator('[data-ref="cancel"]').isHidden(), 'a finished sweep has no Cancel button');
  const rows = await page.locator('.points-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    cells: [...tr.cells].map((td) => td.textContent.trim()),
    job: tr.querySelector('a')?.getAttribute('href'),
  })));
  check(rows.length === 4, `the points table has the ${rows.length} points`);
  sweep.points.forEach((p, i) => {
    const [index, radius, l3, job, state, , rms] = rows[i].cells;
    const chosen = p.figures.noise_table.find((r) => r.strategy === p.figures.recommended.strategy);
    const shown = Number.parseFloat(rms.replace(/,/g, ''));
    check(index === String(p.index) && radius === String(p.values.merge_radius) && l3 === String(p.values['scene.l3'])
      && job === `#${p.job_id}` && rows[i].job === `#/jobs/${p.job_id}` && state === 'succeeded'
      && Math.abs(shown - chosen.rms_percent) < 0.06 && rms.includes(chosen.strategy)
      && rms.includes(p.figures.recommended.lambda === null ? ', per path)' : ', λ = '),
      `point ${p.index}: ${radius}, ${l3}, job ${job}, recommended RMS ${rms}`);
  });
}

/** The CSV link points at the table, and clicking it downloads the same bytes as the API serves. */
export async function checkCsv(page, sweep) {
  const href = `/v1/sweeps/${sweep.id}/table?format=csv`;
  const link = page.getByRole('link', { name: 'Download the table (CSV)' });
  check(await link.getAttribute('href') === href, `the CSV link is ${href}`);
  const [download] = await Promise.all([page.waitForEvent('download'), link.click()]);
  const text = await readFile(await download.path(), 'utf8');
  const expected = await callApi(href);
  const lines = text.trimEnd().split('\r\n');
  const rows = sweep.points.reduce((n, p) => n + p.figures.noise_table.length, 0);
  check(download.suggestedFilename() === `sweep-${sweep.id}.csv` && lines[0].startsWith('point,merge_radius,scene.l3,source,')
    && lines.length === 1 + rows, `clicking it downloads ${download.suggestedFilename()}: a header and ${lines.length - 1} rows`);
  check(text === expected.text, 'the download is the table the API serves');
}

export async function checkSweepCharts(page, sweep) {
  const strategies = [...new Set(sweep.points.flatMap((p) => p.figures.noise_table.map((r) => r.strategy)))];
  const outside = new Set(sweep.points.flatMap((p) => p.figures.noise_table.filter((r) => !r.respects_fixed).map((r) => r.strategy)));
  const first = Object.fromEntries(sweep.spec.axes.map((a) => [a.field, a.values[0]]));
  for (const axis of sweep.spec.axes) {
    const card = page.locator(`[data-field="${axis.field}"]`);
    const other = sweep.spec.axes.find((a) => a !== axis);
    const plot = await readPlot(card.locator('.plot'));
    check(plot !== null && plot.inked > 1000, `the RMS chart of ${axis.field} is drawn (${plot?.inked} pixels)`);
    check(plot.labels.length === strategies.length && strategies.every((s) => plot.labels.some((l) => l.startsWith(s))),
      `it has one series per strategy of the noise tables (${plot.labels.length})`);
    check(plot.labels.every((l) => l.includes('outside fixed weights') === outside.has(l.split(' ')[0])),
      `the strategies outside the fixed weights are marked (${[...outside].join(', ')})`);
    const bars = expectedRmsBars(sweep, axis.field, first);
    check(plot.errorBars === bars && bars > 0, `it draws ${plot.errorBars} error bars, one per row with a standard error`);
    const select = card.locator(`select[data-axis="${other.field}"]`);
    const options = await select.locator('option').allTextContents();
    check(options.join() === other.values.map(String).join(), `a selector fixes ${other.field} (${options.join(', ')})`);
    await select.selectOption({ index: 1 });
    const moved = expectedRmsBars(sweep, axis.field, { ...first, [other.field]: other.values[1] });
    const after = await waitFor('the redrawn chart', async () => {
      const p = await readPlot(card.locator('.plot'));
      return p.errorBars === moved && p;
    }, 5_000);
    check(after.labels.length === strategies.length, `with ${other.field} = ${other.values[1]} it redraws ${moved} bars, same series`);
    await checkAxes(page, card.locator('.plot'), `the RMS chart of ${axis.field}`);
  }
  await checkW1Grid(page, sweep);
}

/**
 * The effective w₁(r₃) as small multiples: a panel per point in the sweep's grid (a column per
 * value of its last axis), each named by its point and its recommended row; a chart with points
 * and bars in every one — a per-path heuristic's as much as a table's —, all on the same x and y
 * ranges; one SVG of the grid with a panel per chart, and its PNG at print resolution.
 */
async function checkW1Grid(page, sweep) {
  const expected = await expectedW1Panels(sweep);
  const kinds = [...new Set(expected.panels.map((p) => p.kind))];
  const grid = page.locator('[data-ref="w1-grid"]');
  const read = () => grid.locator('figure.w1-panel').evaluateAll((figs) => figs.map((f) => ({
    point: Number(f.dataset.point), caption: f.querySelector('figcaption').textContent,
    canvas: Boolean(f.querySelector('canvas')), markers: Number(f.querySelector('.plot').dataset.markers ?? 0),
    bars: Number(f.querySelector('.plot').dataset.errorBars ?? 0), text: f.textContent,
  })));
  const panels = await waitFor('every panel drawn', async () => {
    const got = await read();
    return got.length === sweep.points.length && got.every((p, k) => p.canvas && p.markers === expected.panels[k].markers) && got;
  }, 30_000);
  const columns = Number(await grid.getAttribute('data-columns'));
  check(panels.every((p, k) => p.point === sweep.points[k].index && p.caption.startsWith(describePoint(sweep, sweep.points[k]))
    && p.caption.includes(`${expected.panels[k].strategy} (${expected.panels[k].kind})`)) && columns === sweep.spec.axes.at(-1).values.length,
  `the w₁(r₃) card has a panel per point, in the sweep's grid of ${columns} columns (${panels.map((p) => p.caption).join(' | ')})`);
  check(panels.every((p) => p.markers > 0),
    `every panel draws its point's effective w₁ with points (${panels.map((p) => p.markers).join(', ')} markers), recommendations of kind ${kinds.join(', ')}`);
  const bars = panels.reduce((n, p) => n + p.bars, 0);
  check(bars === expected.panels.reduce((n, p) => n + p.bars, 0), `they draw ${bars} error bars (± 1 SE of the effective w₁)`);
  const note = await page.locator('[data-ref="w1-note"]').textContent();
  check(note.includes(`effective w₁ of its recommended row`) && note.includes(r2Words(expected.r2))
    && expected.dark.every((b) => note.includes(`${r2Words(b)}: no light path reaches it at any point`)),
  `the card's caption says what is drawn, in ${r2Words(expected.r2)}${expected.dark.length ? `, and that no light reaches ${expected.dark.map(r2Words).join(', ')}` : ''}`);
  const scales = await grid.locator('figure.w1-panel .plot').evaluateAll(async (plots) => {
    const { plotOf } = await import('/assets/plots.js');
    return plots.map(plotOf).filter(Boolean).map((u) => JSON.stringify([u.scales.x.min, u.scales.x.max, u.scales.y.min, u.scales.y.max]));
  });
  check(scales.length === panels.length && new Set(scales).size === 1, `every panel has the same x and y ranges (${scales[0]})`);
  await checkAxes(page, grid.locator('figure.w1-panel .plot').first(), 'a w₁(r₃) panel');
  const card = page.locator('[data-chart="w1"]');
  const svg = (await downloadFrom(page, card.locator('button[data-download="svg"]'))).bytes.toString('utf8');
  check(svg.split('class="panel"').length - 1 === panels.length && svg.includes('effective w₁ of the panel'),
    `its SVG holds the ${panels.length} panels and one legend`);
  const png = await downloadFrom(page, card.locator('button[data-download="png"]'));
  check(pngSize(png.bytes).width >= PNG_MIN_WIDTH, `its PNG is ${pngSize(png.bytes).width} × ${pngSize(png.bytes).height} px`);
}

/** A run's job page links back to its sweep, and so does the job list. */
export async function checkSweepLinks(page, sweep) {
  const point = sweep.points[1];
  await page.locator(`.points-table tr[data-point="${point.index}"] a`).click();
  await waitFor('the job page', () => page.locator('h1', { hasText: `Job ${point.job_id}` }).isVisible());
  const link = page.locator('[data-ref="sweep"]');
  check(await link.isVisible() && await link.textContent() === `sweep ${sweep.id}` && await link.getAttribute('href') === `#/sweeps/${sweep.id}`,
    `job ${point.job_id}'s page shows "sweep ${sweep.id}" linked to the sweep`);
  await link.click();
  await waitFor('the sweep page again', () => page.locator('h1', { hasText: `Sweep ${sweep.id}` }).isVisible());
  check(true, 'the link leads back to the sweep page');
  await page.locator('.topnav').getByRole('link', { name: 'Jobs' }).click();
  const inList = page.locator(`tr[data-job="${point.job_id}"] a.sweep-link`);
  await waitFor(`job ${point.job_id} in the list`, async () => (await inList.count()) > 0);
  check(await inList.getAttribute('href') === `#/sweeps/${sweep.id}`, `the job list shows job ${point.job_id} as part of sweep ${sweep.id}`);
}

/** A running sweep is cancelled from its page: every run ends cancelled. */
export async function checkSweepCancel(page) {
  const created = await callApi('/v1/sweeps', { method: 'POST', body: LONG_SWEEP });
  check(created.status === 201, 'a long sweep is created');
  const { id } = created.json;
  await page.goto(`${base}/#/sweeps/${id}`);
  const cancel = page.locator('[data-ref="cancel"]');
  await waitFor('the Cancel button', () => cancel.isVisible());
  await cancel.click();
  await waitFor('the sweep to be cancelled', async () => (await page.locator('[data-ref="state"] .badge').textContent()) === 'cancelled');
  const sweep = (await callApi(`/v1/sweeps/${id}`)).json;
  check(sweep.points.every((p) => p.state === 'cancelled') && (await cancel.isHidden()),
    `Cancel stops every run of sweep ${id} (${JSON.stringify(sweep.progress.runs_by_state)}) and goes away`);
}
