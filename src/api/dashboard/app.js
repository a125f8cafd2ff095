// The optimis dashboard: a hash-routed client of the public API (/v1/jobs…, /v1/sweeps…).
//
// No framework and no build step: pages are <template>s from index.html filled in by plain ES
// modules, served as they are. The page is served under a Content-Security-Policy that forbids
// inline script, so every event handler is attached from these modules.
//
// This entry module owns the routing and the sign-in banner, and wires the others together:
//   api.js        calls to the server, downloads, the bearer token    (imports nothing of ours)
//   format.js     DOM and formatting helpers                          (imports nothing of ours)
//   form.js       the submit form                                     (api, format)
//   csv.js        CSV text (RFC 4180) and its download buttons        (api, format)
//   paper.js      the paper's configuration, SE(L)                  (imports nothing of ours)
//   chartkit.js   uPlot plugins: error bars, SE bands, guide lines    (imports nothing of ours)
//   chartfiles.js a chart's SVG (a serialiser) and PNG downloads      (api, chartkit, format)
//   plots.js      the job's history charts: luminance, RMS; shared    (chartkit, format, paper)
//   fig2.js       Fig. 2: effective weights, the λ = 0 table; tables  (axes, chartkit, format, plots)
//   noisetable.js the noise table: paper column, case numbers, z, CSV (format, paper)
//   solves.js     a job's kept solves: selector and keep form         (api, format)
//   results.js    a job's results: loading, table, charts, downloads  (api, chartfiles, csv, fig2, format, noisetable, paper, plots, solves)
//   specfields.js a spec's fields, which differ between jobs           (format)
//   list.js       the job list page (a runs table), selection to compare (api, format, form, specfields)
//   job.js        the job page                                        (api, format, plots, results, specfields)
//   compare.js    the compare page of 2 to 8 jobs                     (api, chartkit, chartfiles, csv, fig2, format, list, plots, specfields)
//   sweepdata.js  a sweep's chart data (no DOM)                       (plots)
//   sweepplots.js a sweep's charts, with error bars                   (chartkit, format, plots, sweepdata)
//   sweepw1.js    a sweep's effective w₁ per point, small multiples   (api, axes, chartkit, chartfiles, format, plots, sweepdata)
//   sweeps.js     the sweep list page                                 (api, format)
//   sweep.js      the sweep page                                      (api, format, list, sweepdata, sweepplots, sweepw1)

import { saveToken, whenUnauthorized } from './api.js';
import { showCompare } from './compare.js';
import { h } from './format.js';
import { showJob } from './job.js';
import { showList } from './list.js';
import { showSweep } from './sweep.js';
import { showSweeps } from './sweeps.js';

const app = document.getElementById('app');
let leavePage = () => {};

// Hash routes: #/jobs/ID, #/compare?ids=1,2,…, #/sweeps, #/sweeps/ID; anything else is the job list
// (#/?state=…&label=…: its filters, sort and page, list.js).
function route() {
  leavePage();
  const hash = location.hash;
  const job = /^#\/jobs\/(\d+)$/.exec(hash);
  const compare = /^#\/compare(\?.*)?$/.exec(hash);
  const sweep = /^#\/sweeps\/(\d+)$/.exec(hash);
  const list = /^#\/(\?.*)?$/.exec(hash);
  if (job) leavePage = showJob(app, Number(job[1]));
  else if (compare) leavePage = showCompare(app, compare[1] ?? '');
  else if (sweep) leavePage = showSweep(app, Number(sweep[1]));
  else if (hash === '#/sweeps') leavePage = showSweeps(app);
  else leavePage = showList(app, list?.[1] ?? '');
  const section = job || compare || list || hash === '' ? 'jobs' : sweep || hash === '#/sweeps' ? 'sweeps' : '';
  for (const link of document.querySelectorAll('.topnav a[data-nav]')) {
    if (link.dataset.nav === section) link.setAttribute('aria-current', 'page');
    else link.removeAttribute('aria-current');
  }
  window.scrollTo(0, 0);
}

/** Shows the sign-in banner (once): the server wants a token this tab does not have, or a better one. */
function askForToken(reason) {
  if (document.getElementById('sign-in')) return;
  const input = h('input', { id: 'token-input', type: 'password', autocomplete: 'current-password', placeholder: 'token' });
  const form = h('form', { id: 'sign-in', class: 'sign-in', role: 'alert' },
    h('label', { for: 'token-input' }, 'This server needs its access token',
      reason ? h('span', { class: 'hint' }, ` (${reason})`) : null),
    input,
    h('button', { type: 'submit' }, 'Sign in'));
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    saveToken(input.value.trim());
    form.remove();
    route();
  });
  document.body.prepend(form);
  input.focus();
}

// ---------------------------------------------------------------------------------------------
// Start

whenUnauthorized(askForToken);
window.addEventListener('hashchange', route);
route();
