// The job list: newest first, live progress, cancel and delete.
//
// Progress comes from Server-Sent Events (GET /jobs/{id}/events). Browsers allow only about
// six HTTP/1.1 connections per host, and every open event stream holds one, so at most
// MAX_STREAMS jobs are followed live; the others (and jobs submitted by other clients) are
// picked up by re-reading the list now and then.

import * as api from './api.js';
import { el, fmtSeconds } from './util.js';

const MAX_STREAMS = 3;
const FINISHED = new Set(['succeeded', 'failed', 'cancelled']);

export const isFinished = (job) => FINISHED.has(job.status);

// What a job was run with (h, k, T, edited, the preset), as submitted from this browser: the
// job resource names only the scene, so three runs of "paper-exp3" would look the same.
// Kept in localStorage (the newest LABELS_KEPT), so a reload or another tab shows them too.
const LABELS_STORE = 'contact-sim-job-labels';
const LABELS_KEPT = 500;

function readLabels() {
  try {
    return JSON.parse(localStorage.getItem(LABELS_STORE) || '{}') || {};
  } catch {
    return {};
  }
}

let labels = readLabels();
// Another tab submitted a job: its label is read at once.
window.addEventListener('storage', (ev) => {
  if (ev.key === LABELS_STORE) labels = readLabels();
});

/** Remembers what job `id` was submitted with: {h, k, T, edited, preset, mesh, study}. */
export function rememberLabel(id, label) {
  const all = readLabels();
  all[id] = { ...label, at: Date.now() };
  labels = all;
  const ids = Object.keys(all).sort((a, b) => all[b].at - all[a].at);
  for (const old of ids.slice(LABELS_KEPT)) delete all[old];
  try {
    localStorage.setItem(LABELS_STORE, JSON.stringify(all));
  } catch {
    // Not kept.
  }
}

/** The short text of a job's label: "h 1/8 · k 1/8 · T 1 · edited". */
export function labelText(label) {
  if (!label) return '';
  const parts = [];
  const v = (x) => (Array.isArray(x) ? x.join(', ') : String(x));
  if (label.h !== undefined) parts.push(`h ${v(label.h)}`);
  if (label.k !== undefined) parts.push(`k ${v(label.k)}`);
  if (label.T !== undefined) parts.push(`T ${v(label.T)}`);
  if (label.mesh) parts.push(label.mesh);
  if (label.edited) parts.push('edited');
  return parts.join(' · ');
}

/**
 * The label of a job submitted elsewhere (another browser, curl, Python), from the
 * resolution the job resource carries: h (or the mesh's refinements), k (or N) and T.
 */
export function resourceLabel(job) {
  const r = job.resolution;
  if (!r) return null;
  const label = {};
  if (r.h != null) label.h = r.h;
  if (r.refine != null) label.mesh = `refine ${r.refine}`;
  label.k = r.k != null ? r.k : `T/${r.steps}`;
  if (r.t_end != null) label.T = r.t_end;
  return label;
}

export class JobList {
  /**
   * `root`: an empty <ul>. `onSelect(job)`: the user picked a job. `onUpdate(job)`: a job's
   * resource changed (progress, final status, deletion: job.deleted = true).
   */
  constructor(root, { onSelect, onUpdate }) {
    this.root = root;
    this.onSelect = onSelect;
    this.onUpdate = onUpdate;
    this.jobs = new Map(); // id -> job resource
    this.streams = new Map(); // id -> {close}
    this.pollOnly = new Set(); // ids whose stream broke while unfinished: polled instead
    this.selected = null;
    this.timer = 0;
    this.empty = el('li', { class: 'empty' }, 'No jobs yet: run a preset or a scene.');

  }

  /** Re-reads the list (first page), then schedules the next refresh. */
  async refresh() {
    clearTimeout(this.timer);
    try {
      const page = await api.listJobs(50);
      const seen = new Set();
      for (const j of page.jobs) {
        seen.add(j.id);
        this.upsert(j);
      }
      // Jobs deleted elsewhere disappear; jobs beyond the first page stay as they are.
      for (const id of [...this.jobs.keys()]) {
        if (!seen.has(id) && page.next === null) this.drop(id);
      }
      this.render();
    } catch (e) {
      console.warn('job list:', e.message);
    }
    const busy = [...this.jobs.values()].some((j) => !isFinished(j) && !this.streams.has(j.id));
    this.timer = setTimeout(() => this.refresh(), busy ? 2000 : 10000);
  }

  /** Adds or updates a job resource (e.g. the response of POST /jobs). */
  upsert(job) {
    const old = this.jobs.get(job.id);
    this.jobs.set(job.id, job);
    if (!isFinished(job)) this.followSome();
    // The final event of a stream carries no error: the resource read after it does, and
    // that is news too (the view shows the error at once).
    const changed = old && (old.status !== job.status || old.progress?.step !== job.progress?.step || !!old.error !== !!job.error);
    if (changed) this.onUpdate(job);
    if (!old) this.onUpdate(job);
    this.render();
  }

  drop(id) {
    this.streams.get(id)?.close();
    this.streams.delete(id);
    const job = this.jobs.get(id);
    this.jobs.delete(id);
    if (job) this.onUpdate({ ...job, deleted: true });
    if (this.selected === id) this.selected = null;
  }

  /** Selects a job (`byUser`: clicked in the list, not chosen by the program). */
  select(id, byUser = false) {
    this.selected = id;
    this.render();
    const job = this.jobs.get(id);
    if (job) this.onSelect(job, byUser);
  }

  /** Opens event streams for unfinished jobs, newest first, up to MAX_STREAMS. */
  followSome() {
    const waiting = [...this.jobs.values()]
      .filter((j) => !isFinished(j) && !this.streams.has(j.id) && !this.pollOnly.has(j.id))
      .sort((a, b) => (a.created_at < b.created_at ? 1 : -1));
    for (const j of waiting) {
      if (this.streams.size >= MAX_STREAMS) break;
      const id = j.id;
      const stream = api.follow(
        id,
        (ev) => {
          const cur = this.jobs.get(id);
          if (!cur) return;
          const percent = ev.steps > 0 ? Math.round((1000 * ev.step) / ev.steps) / 10 : 0;
          this.upsert({
            ...cur,
            status: ev.status,
            progress: { ...cur.progress, step: ev.step, steps: ev.steps, percent, eta_s: ev.eta_s, last_residual: ev.last_residual },
          });
        },
        async () => {
          this.streams.delete(id);
          // The final event carries no links and no error: read the whole resource.
          try {
            if (this.jobs.has(id)) {
              const job = await api.job(id);
              // A stream that ended before the job did broke (e.g. a proxy or a restart):
              // reconnecting at once could loop, so this job is left to the list's polling.
              if (!isFinished(job)) this.pollOnly.add(id);
              this.upsert(job);
            }
          } catch (e) {
            if (e.status === 404) this.drop(id);
          }
          this.render();
          this.followSome();
        },
      );
      this.streams.set(id, stream);
    }
  }

  async cancel(id) {
    try {
      this.upsert(await api.cancel(id));
    } catch (e) {
      alert(`Cancel failed: ${e.message}`);
      this.refresh();
    }
  }

  async remove(id) {
    const job = this.jobs.get(id);
    if (!confirm(`Delete job ${job?.scene ?? ''} (${id.slice(0, 8)}) and its results?`)) return;
    try {
      await api.remove(id);
      this.drop(id);
    } catch (e) {
      if (e.status === 404) this.drop(id);
      else alert(`Delete failed: ${e.message}`);
    }
    this.render();
  }

  render() {
    const jobs = [...this.jobs.values()].sort((a, b) => (a.created_at < b.created_at ? 1 : -1));
    if (!jobs.length) {
      this.root.replaceChildren(this.empty);
      return;
    }
    // Items are kept and updated in place (not rebuilt): progress events arrive many times a
    // second, and a rebuilt button under the pointer would swallow the user's click.
    this.items ??= new Map();
    for (const id of [...this.items.keys()]) if (!this.jobs.has(id)) this.items.delete(id);
    const lis = jobs.map((j) => {
      let item = this.items.get(j.id);
      if (!item) {
        item = this.item(j.id);
        this.items.set(j.id, item);
      }
      this.update(item, j);
      return item.li;
    });
    // Only touch the DOM order when it changed.
    const current = [...this.root.children];
    if (current.length !== lis.length || current.some((c, i) => c !== lis[i])) this.root.replaceChildren(...lis);
  }

  /** The skeleton of one job's entry; update() fills it. */
  item(id) {
    const r = {};
    r.name = el('span', { class: 'job-name' });
    r.badge = el('span', { class: 'badge' });
    r.status = el('span', { class: 'status' });
    r.progress = el('progress', { max: '100', value: '0', 'aria-label': `progress of job ${id.slice(0, 8)}` });
    r.label = el('div', { class: 'job-label' });
    r.detail = el('span', { class: 'job-detail' });
    r.cancel = el('button', { type: 'button', class: 'small', onclick: () => this.cancel(id) }, 'Cancel');
    r.delete = el('button', { type: 'button', class: 'small danger', onclick: () => this.remove(id) }, 'Delete');
    r.actions = el('span', { class: 'job-actions' });
    r.id = el('div', { class: 'job-id' });
    r.li = el(
      'li',
      { class: 'job', dataset: { id } },
      el('button', { class: 'job-open', type: 'button', title: 'show this job', onclick: () => this.select(id, true) }, r.name, r.badge, r.status),
      r.label,
      r.progress,
      el('div', { class: 'job-meta' }, r.detail, r.actions),
      r.id,
    );
    return r;
  }

  update(r, j) {
    const p = j.progress || {};
    const done = isFinished(j);
    const kind = j.kind || 'simulation';
    let detail;
    if (j.status === 'running') {
      detail = `${p.step}/${p.steps} steps · ${p.percent ?? 0}%${p.eta_s != null ? ` · ETA ${fmtSeconds(p.eta_s)}` : ''}`;
    } else if (j.status === 'queued') detail = 'waiting for a worker';
    else if (j.status === 'failed') detail = j.error?.detail || j.error?.title || 'failed';
    else if (j.status === 'succeeded') detail = kind === 'study' ? 'study finished' : `${p.steps} steps`;
    else detail = `cancelled at step ${p.step}`;
    r.li.className = `job${this.selected === j.id ? ' selected' : ''}`;
    r.li.dataset.status = j.status;
    r.li.dataset.kind = kind;
    r.name.textContent = j.scene || '(unnamed)';
    r.badge.textContent = kind;
    r.badge.hidden = kind === 'simulation';
    r.status.textContent = j.status;
    r.status.className = `status s-${j.status}`;
    r.progress.value = j.status === 'succeeded' ? 100 : p.percent ?? 0;
    const label = labelText(labels[j.id] || resourceLabel(j));
    r.label.textContent = label;
    r.label.hidden = !label;
    r.detail.textContent = detail;
    r.detail.title = detail;
    const want = done ? r.delete : r.cancel;
    if (r.actions.firstChild !== want) r.actions.replaceChildren(want);
    r.id.textContent = `${j.id.slice(0, 8)} · ${new Date(j.created_at).toLocaleString()}`;
  }
}
