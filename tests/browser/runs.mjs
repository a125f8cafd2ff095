// The varying parameters in sight (issue 42, item 2), on the 2 × 2 sweep of sweeps.mjs
// (merge_radius × scene.l3): the job list as a runs table — the sweep's runs behind the sweep page's
// link, their R and L₃ as marked, sortable columns, at 1280 px without being cut off — whose filter,
// sort and page survive a reload; the compare page of the sweep's runs with its R and L₃ rows marked
// as varying (screenshot sweep-compare.png); the job page listing L₂, L₃ and the job's name.

import { base, callApi, check, screenshot, waitFor } from './harness.mjs';

/** The list's rows as { job, cells by data-col }, in the order shown. */
const listRows = (page) => page.locator('table.jobs-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
  job: Number(tr.dataset.job),
  cells: Object.fromEntries([...tr.querySelectorAll('td[data-col]')].map((td) => [td.dataset.col, td.textContent.trim()])),
})));

const hashOf = (page) => decodeURIComponent(new URL(page.url()).hash);

export async function checkRunsTable(page, sweep) {
  const jobs = sweep.points.map((p) => p.job_id);
  const byJob = new Map(sweep.points.map((p) => [p.job_id, p.values]));
  await page.setViewportSize({ width: 1280, height: 900 });
  await page.goto(`${base}/#/sweeps/${sweep.id}`);
  const runsLink = page.locator('[data-ref="runs-link"]');
  await waitFor('the link to the runs', () => runsLink.isVisible());
  await runsLink.click();
  await waitFor('the sweep\'s runs in the list', async () => (await listRows(page)).length === jobs.length);
  check(hashOf(page) === `#/?sweep=${sweep.id}`, `the sweep page links to its runs in the list (${hashOf(page)})`);
  const varying = await page.locator('table.jobs-table thead th.varying').evaluateAll((ths) => ths.map((th) => th.dataset.col));
  check(varying.join() === 'merge_radius,scene.l3', `the runs table adds the varying fields as marked columns (${varying.join(', ')})`);
  const note = await page.locator('[data-ref="varying-note"]').textContent();
  check(note === 'Differing on this page: R, L3.', `and names them above the table ("${note}")`);
  const rows = await listRows(page);
  check(rows.every((r) => Number(r.cells.merge_radius) === byJob.get(r.job).merge_radius && Number(r.cells['scene.l3']) === byJob.get(r.job)['scene.l3']),
    `each run's R and L₃ are its sweep point's (${rows.map((r) => `#${r.job}: ${r.cells.merge_radius}, ${r.cells['scene.l3']}`).join('; ')})`);
  await screenshot(page, 'runs-table.png');
  const fit = await page.locator('.jobs-card .table-wrap').evaluate((wrap) => ({
    fits: wrap.scrollWidth <= wrap.clientWidth, scroll: wrap.scrollWidth, client: wrap.clientWidth,
    columns: [...wrap.querySelectorAll('thead th')].map((th) => `${th.textContent.trim() || '·'} ${Math.round(th.getBoundingClientRect().width)}`),
  }));
  check(fit.fits, `at 1280 px the runs table fits its card (${fit.scroll} of ${fit.client} px: ${fit.columns.join(', ')})`);

  // Sorting: by L₃ ascending, then descending; in the URL; kept by a reload.
  const sortL3 = page.locator('table.jobs-table thead button[data-sort="scene.l3"]');
  await sortL3.click();
  await sortL3.click();
  const l3s = (await listRows(page)).map((r) => Number(r.cells['scene.l3']));
  check(l3s.every((v, i) => i === 0 || l3s[i - 1] >= v) && l3s[0] > l3s.at(-1), `two clicks on L₃ sort the runs by it, descending (${l3s.join(', ')})`);
  check(hashOf(page) === `#/?sweep=${sweep.id}&sort=scene.l3&order=desc`, `the filter and the sort are in the URL (${hashOf(page)})`);
  const before = (await listRows(page)).map((r) => r.job);
  await page.reload();
  await waitFor('the list after a reload', async () => (await listRows(page)).length === jobs.length);
  const after = (await listRows(page)).map((r) => r.job);
  check(after.join() === before.join() && await page.locator('[data-ref="sweep-filter"]').isVisible()
    && (await page.locator('thead th[aria-sort="descending"]').getAttribute('data-col')) === 'scene.l3',
  `a reload keeps the sweep filter and the sort (${after.join(', ')})`);
  // A label filter typed in is in the URL too, and a reload keeps it.
  const filter = page.locator('input[data-ref="label-filter"]');
  await filter.fill('batch=none');
  await filter.press('Enter');
  await waitFor('the empty filtered list', () => page.locator('[data-ref="empty"]').isVisible());
  await page.reload();
  await waitFor('the filtered list after a reload', () => page.locator('[data-ref="empty"]').isVisible());
  check(await filter.inputValue() === 'batch=none' && hashOf(page).includes('label=batch=none'),
    `a reload keeps the label filter (${hashOf(page)})`);
  // Back to the whole list: the chip drops the sweep, a third click the sort, the filter emptied.
  await filter.fill('');
  await filter.press('Enter');
  await page.locator('[data-ref="sweep-filter"]').click();
  await sortL3.click();
  await waitFor('the whole list', () => hashOf(page) === '#/');
  check(true, 'removing the filters and the sort returns the list to #/');

  // The compare page of the sweep's runs: R and L₃ marked as varying, the seed not.
  await page.setViewportSize({ width: 1366, height: 900 });
  await page.goto(`${base}/#/sweeps/${sweep.id}`);
  const compareLink = page.locator('[data-ref="compare-link"]');
  await waitFor('the link to compare the runs', () => compareLink.isVisible());
  await compareLink.click();
  await waitFor('the compare page of the runs', () => page.locator('.compare-table tbody.params tr[data-param="scene.l3"] td').first().isVisible());
  check(hashOf(page) === `#/compare?ids=${[...jobs].sort((a, b) => a - b).join(',')}`, `"Compare its runs" opens ${hashOf(page)}`);
  const params = await page.locator('.compare-table tbody.params tr').evaluateAll((trs) => trs.map((tr) => ({
    key: tr.dataset.param, varying: tr.classList.contains('varying'), cells: [...tr.querySelectorAll('td')].map((td) => td.textContent),
  })));
  const row = (key) => params.find((p) => p.key === key);
  const ids = (await page.locator('.compare-table thead th[data-job]').evaluateAll((ths) => ths.map((th) => Number(th.dataset.job))));
  check(row('merge_radius').varying && row('scene.l3').varying && !row('seed').varying && !row('scene.l2').varying
    && ids.every((id, k) => Number(row('merge_radius').cells[k]) === byJob.get(id).merge_radius && Number(row('scene.l3').cells[k]) === byJob.get(id)['scene.l3']),
  `the compare page marks R and L₃ as varying, with each run's values (R ${row('merge_radius').cells.join(', ')}; L₃ ${row('scene.l3').cells.join(', ')})`);
  const onlyRows = await page.locator('.compare-table tbody.params').evaluate((tbody) => [...tbody.childNodes].every((n) => n.nodeName === 'TR'));
  const wide = await page.locator('.compare-table').evaluate((table) => {
    const wrap = table.closest('.table-wrap') ?? table.parentElement;
    return { fits: wrap.scrollWidth <= wrap.clientWidth, scroll: wrap.scrollWidth, client: wrap.clientWidth };
  });
  check(onlyRows && wide.fits, `the parameters are rows only, and the four runs fit the page (${wide.scroll} of ${wide.client} px)`);
  const names = row('name').cells;
  const specs = await Promise.all(ids.map(async (id) => (await callApi(`/v1/jobs/${id}`)).json.spec.name ?? '—'));
  check(names.join('|') === specs.join('|'), `and heads them with the runs' names (${names.join(' | ')})`);
  await screenshot(page, 'sweep-compare.png');

  // The job page lists every field: L₂ and L₃ among them, and the name.
  await page.goto(`${base}/#/jobs/${jobs[0]}`);
  await waitFor('the job\'s specification', () => page.locator('dl.spec div[data-field="scene.l3"]').isVisible());
  const fields = await page.locator('dl.spec > div').evaluateAll((divs) => Object.fromEntries(divs.map((d) => [d.dataset.field, d.querySelector('dd').textContent])));
  const values = byJob.get(jobs[0]);
  check(Number(fields['scene.l3']) === values['scene.l3'] && Number(fields.merge_radius) === values.merge_radius
    && fields['scene.l2'] !== undefined && fields.name === specs[ids.indexOf(jobs[0])],
  `the job page lists L₂ ${fields['scene.l2']}, L₃ ${fields['scene.l3']}, R ${fields.merge_radius} and the name "${fields.name}"`);
}
