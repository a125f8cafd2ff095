// The job page: one job, streamed live while it runs, its figures and specification, cancel,
// extend and the moments download, its results (results.js) and its ray budget (budget.js).

import { TERMINAL, api, download, streamJob } from './api.js';
import {
  badge, describeBest, formatCount, formatDuration, formatParameter, formatRate, formatTime, h, instantiate, showMessage,
  updateProgress,
} from './format.js';
import { BudgetPanel } from './budget.js';
import { PlotSlot } from './plots.js';
import { ResultsLoader } from './results.js';
import { byField, fieldLabel, flattenSpec, formatField } from './specfields.js';

const RETRY_MS = 3000;

/** Shows job `id` in `app` (the page's #app element); returns what leaving the page does. */
export function showJob(app, id) {
  const { fragment, refs } = instantiate('tpl-job');
  app.replaceChildren(fragment);
  document.title = `Job ${id} · optimis`;

  const plots = {
    weights: new PlotSlot(refs['weights-plot'], `Job ${id}: effective weights of the recommended row against r₃ (Fig. 2)`),
    lambdaZero: new PlotSlot(refs['lambda0-plot'], `Job ${id}: w₁ fitted in-sample at λ = 0 (the paper's procedure)`),
    luminance: new PlotSlot(refs['luminance-plot'], `Job ${id}: luminance against iterations (± 1 SE)`),
    history: new PlotSlot(refs['history-plot'], `Job ${id}: RMS error against iterations`),
  };
  const results = new ResultsLoader(id, refs, plots);
  // After the noise table, before the charts: what to run next follows from the table.
  const budget = new BudgetPanel(id);
  refs.body.querySelector('.plots').before(budget.card);
  let job = null;
  let closeStream = null;
  let retryTimer = null;
  let alive = true;

  function render(next) {
    job = next;
    refs.body.hidden = false;
    refs.id.textContent = job.id;
    refs.state.replaceChildren(badge(job.state));
    renderSweepLink(refs.sweep, job);
    updateProgress(refs.progress, job);
    renderStats(refs, job);
    renderSpec(refs.spec, job);
    renderTasks(refs, job);
    renderActions(refs, job);
    showMessage(refs['job-error'], job.error ? `The job failed: ${job.error}` : '');
    const { iterations_done: done, iterations_total: total } = job.progress;
    document.title = `Job ${job.id} · ${job.state}${TERMINAL.has(job.state) ? '' : ` ${done}/${total}`} · optimis`;
    results.update(job);
    budget.update(job);
    if (TERMINAL.has(job.state)) setLive('');
    else openStream();
  }

  function openStream() {
    if (closeStream) return;
    setLive('live');
    closeStream = streamJob(id, {
      onJob: (next) => {
        if (TERMINAL.has(next.state)) closeStream = null;
        if (alive) render(next);
      },
      onLost: () => {
        closeStream = null;
        setLive('reconnecting');
        retryTimer = setTimeout(reload, RETRY_MS);
      },
    });
  }

  function setLive(status) {
    refs.live.dataset.status = status;
    refs.live.textContent = { live: 'live', reconnecting: 'connection lost — reconnecting…', '': '' }[status];
  }

  async function reload() {
    try {
      const next = await api(`/v1/jobs/${id}`);
      if (!alive) return;
      showMessage(refs['load-error'], '');
      render(next);
    } catch (error) {
      if (!alive) return;
      if (error.status === 404) {
        showMessage(refs['load-error'], `Job ${id} does not exist (it may have been deleted).`);
        refs.body.hidden = true;
        return;
      }
      showMessage(refs['load-error'], `${error.message} Retrying every ${RETRY_MS / 1000} s.`);
      retryTimer = setTimeout(reload, RETRY_MS);
    }
  }

  async function act(button, path, body) {
    showMessage(refs['action-error'], '');
    button.disabled = true;
    try {
      const next = await api(path, { method: 'POST', body });
      if (alive) render(next);
      return true;
    } catch (error) {
      if (alive) showMessage(refs['action-error'], error.message);
      return false;
    } finally {
      button.disabled = false;
      if (job) renderActions(refs, job);
    }
  }

  refs.cancel.addEventListener('click', () => act(refs.cancel, `/v1/jobs/${id}/cancel`));
  refs['extend-form'].addEventListener('submit', async (event) => {
    event.preventDefault();
    const input = refs['extend-form'].elements.iterations;
    const iterations = Number(input.value.trim());
    if (!Number.isSafeInteger(iterations) || iterations < 1) {
      showMessage(refs['action-error'], 'Enter how many iterations to add: a whole number of at least 1.');
      input.focus();
      return;
    }
    if (await act(refs.extend, `/v1/jobs/${id}/extend`, { iterations })) input.value = '';
  });
  // The moments (sums over iterations, to merge or re-fit elsewhere): fetched with the token, named by the server.
  refs.moments.addEventListener('click', () => {
    showMessage(refs['action-error'], '');
    download(`/v1/jobs/${id}/moments`, `optimis-job-${id}-moments.json`)
      .catch((error) => alive && showMessage(refs['action-error'], `Cannot download the moments: ${error.message}`));
  });
  reload();

  return () => {
    alive = false;
    clearTimeout(retryTimer);
    if (closeStream) closeStream();
    results.stop();
    for (const plot of Object.values(plots)) plot.destroy();
  };
}

/** "sweep N", linked to the sweep's page, when the job is a run of a sweep. */
function renderSweepLink(link, job) {
  link.hidden = job.sweep_id === null || job.sweep_id === undefined;
  if (link.hidden) return;
  link.href = `#/sweeps/${job.sweep_id}`;
  link.textContent = `sweep ${job.sweep_id}`;
  link.title = 'This job is a run of a sweep';
}

function renderStats(refs, job) {
  const p = job.progress;
  const running = job.state === 'running';
  refs.rate.textContent = running ? formatRate(p.light_paths_per_second) : '—';
  refs.eta.textContent = running ? formatDuration(p.eta_seconds) : '—';
  refs.checkpointed.textContent = `${formatCount(p.iterations_checkpointed)} iterations`;
  refs.best.textContent = describeBest(p.best);
  refs.created.textContent = formatTime(job.created_at);
  refs.updated.textContent = formatTime(job.updated_at);
}

// Every field of the spec (specfields.js), the paper's first — L₂ and L₃ too — under the job's
// name, notes and labels: what a reader comparing runs of a sweep needs to tell them apart.
function renderSpec(dl, job) {
  const spec = job.spec;
  const rows = [];
  if (spec.name) rows.push(['Name', spec.name, 'name']);
  if (spec.notes) rows.push(['Notes', spec.notes, 'notes']);
  const labels = Object.entries(spec.labels ?? {});
  if (labels.length) rows.push(['Labels', labels.map(([k, v]) => `${k}=${v}`).join(', '), 'labels']);
  const flat = flattenSpec(spec);
  let illumination = false;
  for (const path of [...flat.keys()].sort(byField)) {
    if (path.startsWith('scene.illumination.')) {
      // One row in words (`spot: a = 0.02, r_ls = 0.1, contrast 10`), where the first of its fields sorts.
      if (!illumination) rows.push(['Illumination', describeIllumination(spec.scene.illumination), 'scene.illumination']);
      illumination = true;
    } else if (path.startsWith('shard.')) {
      if (path === 'shard.index') rows.push(['Shard', `${spec.shard.index + 1} of ${spec.shard.count}`, 'shard']);
    } else {
      rows.push([fieldLabel(path), path === 'cells' ? `${formatField(path, flat.get(path))} (r₂ × r₃ × φ)` : formatField(path, flat.get(path)), path]);
    }
  }
  if (job.merged) rows.push(['Merged', 'yes: the moments of several jobs added together', 'merged']);
  dl.replaceChildren(...rows.map(([term, value, path]) => h('div', { 'data-field': path }, h('dt', {}, term), h('dd', {}, value))));
}

/** The job's cluster tasks (`execution`, on a server with --executor slurm), while it runs; each
 * task's id is the batch system's (`batch_job_id`: Slurm's job id). */
function renderTasks(refs, job) {
  const tasks = job.execution ? job.execution.tasks : [];
  refs.tasks.hidden = tasks.length === 0;
  refs['tasks-body'].replaceChildren(...tasks.map((t) => h('tr', {},
    h('td', {}, String(t.index)),
    h('td', {}, `${formatCount(t.first_iteration)} – ${formatCount(t.first_iteration + t.iterations)}`),
    h('td', {}, `${formatCount(t.iterations_done)} of ${formatCount(t.iterations)}`),
    h('td', {}, badge(t.state)),
    h('td', {}, t.batch_job_id || '—'),
    h('td', {}, String(t.attempts)),
    h('td', {}, h('code', {}, t.log)))));
}

function describeIllumination(ill) {
  switch (ill.kind) {
    case 'spot':
      return `spot: a = ${formatParameter(ill.a)}, r_ls = ${formatParameter(ill.r_ls)}, contrast ${formatParameter(ill.contrast)}`;
    case 'uniform':
      return `uniform: r_ls = ${formatParameter(ill.r_ls)}`;
    default:
      return `${ill.rings.length} rings`;
  }
}

/** Cancel while the job can still stop; Extend unless the server is known to refuse it. */
function renderActions(refs, job) {
  refs.cancel.hidden = TERMINAL.has(job.state);
  const refusal = job.state === 'failed' ? 'A failed job cannot be extended; submit a new one.'
    : job.merged ? 'A merged job cannot be extended; extend its parts and merge again.'
      : job.spec.shard ? 'A shard cannot be extended; extend the study instead.' : '';
  refs['extend-form'].hidden = Boolean(refusal);
  showMessage(refs['extend-note'], refusal);
}
