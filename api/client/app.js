// Entry point: wires the preset form, the mesh upload, the scene editor, the job list and
// the result views.
//
// Two ways to submit, matching POST /jobs: {preset, overrides} from the form (errors point
// at /preset or /overrides/..., shown under those inputs), or a whole scene from the editor
// (errors point into the scene, shown on the editor's lines).

import * as api from './api.js';
import { $, el } from './util.js';
import { SceneEditor } from './editor.js';
import { JobList, isFinished } from './jobs.js';
import { SimulationView } from './viewer.js';
import { StudyView } from './study.js';
import { MeshUpload } from './meshes.js';

const presetSelect = $('#preset-select');
const presetDesc = $('#preset-desc');
const status = $('#submit-status');
const editor = new SceneEditor($('#editor'));
const viewRoot = $('#viewer');
const simView = new SimulationView(viewRoot);
const studyView = new StudyView(viewRoot);
let presetList = [];
let shownId = null; // the job whose results are on screen

const narrow = window.matchMedia('(max-width: 900px)');
const jobs = new JobList($('#job-list'), {
  onSelect: (job, byUser) => {
    show(job);
    // In the one-column layout the results are below the list: bring them into view.
    if (byUser && narrow.matches) $('#view-panel').scrollIntoView({ behavior: 'smooth', block: 'start' });
  },
  onUpdate: (job) => {
    if (job.id !== jobs.selected) return;
    if (job.deleted) clearView('The job was deleted.');
    else if (!isFinished(job) || shownId !== job.id) show(job);
  },
});

function setStatus(text, bad = false) {
  status.textContent = text;
  status.classList.toggle('bad', bad);
}

// ---- result view -------------------------------------------------------------------------

function clearView(message) {
  simView.close();
  studyView.close();
  shownId = null;
  viewRoot.replaceChildren(el('p', { class: 'hint' }, message));
}

/** Results of a succeeded job; otherwise its state (progress, error). */
function show(job) {
  if (location.hash !== `#job=${job.id}`) history.replaceState(null, '', `#job=${job.id}`);
  if (job.status === 'succeeded') {
    if (shownId === job.id) return;
    shownId = job.id;
    simView.close();
    studyView.close();
    (job.kind === 'study' ? studyView : simView).open(job);
    return;
  }
  simView.close();
  studyView.close();
  shownId = null;
  const p = job.progress || {};
  const lines = {
    queued: 'is waiting for a worker.',
    running: `is running: step ${p.step} of ${p.steps} (${p.percent ?? 0}%).`,
    cancelled: `was cancelled at step ${p.step}.`,
    failed: 'failed.',
  };
  viewRoot.dataset.state = 'waiting';
  viewRoot.dataset.job = job.id;
  viewRoot.replaceChildren(
    el('h2', {}, job.scene || 'job', ' ', el('small', {}, job.id.slice(0, 8))),
    el('p', { class: 'placeholder' }, `This ${job.kind || 'simulation'} ${lines[job.status] || job.status}`),
    job.error ? el('p', { class: 'error' }, `${job.error.title}: ${job.error.detail}`) : null,
    ...(job.error?.errors || []).map((e) => el('p', { class: 'error' }, el('code', {}, e.pointer), ': ', e.message)),
  );
}

// ---- submitting --------------------------------------------------------------------------

/** Clears the messages under the preset form's fields. */
function clearFieldErrors() {
  for (const span of document.querySelectorAll('.field-error')) span.textContent = '';
  for (const input of document.querySelectorAll('[data-pointer]')) input.removeAttribute('aria-invalid');
}

/** Puts each error under the form field with its pointer; returns the ones without a field. */
function showFieldErrors(errors) {
  const rest = [];
  for (const e of errors) {
    const span = document.querySelector(`.field-error[data-for="${CSS.escape(e.pointer)}"]`);
    if (!span) {
      rest.push(e);
      continue;
    }
    span.textContent = span.textContent ? `${span.textContent}; ${e.message}` : e.message;
    document.querySelector(`[data-pointer="${CSS.escape(e.pointer)}"]`)?.setAttribute('aria-invalid', 'true');
  }
  return rest;
}

async function submit(body, fromEditor) {
  clearFieldErrors();
  if (fromEditor) editor.clearErrors();
  setStatus('Submitting…');
  try {
    const job = await api.submit(body);
    setStatus(
      job.status === 'succeeded'
        ? `Already computed: job ${job.id.slice(0, 8)} (identical scene).`
        : `Submitted: job ${job.id.slice(0, 8)}.`,
    );
    jobs.upsert(job);
    jobs.select(job.id);
  } catch (e) {
    if (e.status === 422 && e.errors.length) {
      // From the editor every pointer is into the scene text; from the form they name inputs.
      let rest = [];
      if (fromEditor) editor.showErrors(e.errors);
      else rest = showFieldErrors(e.errors);
      const extra = rest.map((r) => `${r.pointer}: ${r.message}`).join('; ');
      setStatus(`${e.title || 'invalid scene'}: ${e.errors.length} error${e.errors.length > 1 ? 's' : ''}${extra ? ` (${extra})` : ''}`, true);
    } else {
      setStatus(`${e.title || 'error'}: ${e.message}`, true);
    }
  }
}

/** A number when the text is one, else the text (fractions such as "1/16" stay strings). */
function numberOrText(s) {
  const t = s.trim();
  return t !== '' && Number.isFinite(Number(t)) ? Number(t) : t;
}

function overrides() {
  const o = {};
  for (const k of ['h', 'k', 't_end']) {
    const v = $(`#ov-${k}`).value;
    if (v.trim() !== '') o[k] = numberOrText(v);
  }
  return o;
}

$('#preset-form').addEventListener('submit', (ev) => {
  ev.preventDefault();
  const o = overrides();
  submit({ preset: presetSelect.value, ...(Object.keys(o).length ? { overrides: o } : {}) }, false);
});

/** The selected preset's document with the form's h (unless `withH` is false), k and T. */
async function presetDoc(withH = true) {
  const doc = await api.preset(presetSelect.value);
  const o = overrides();
  if (o.h !== undefined && withH) (doc.mesh ??= {}).h = o.h;
  if (o.k !== undefined) {
    doc.time ??= {};
    delete doc.time.N;
    doc.time.k = o.k;
  }
  if (o.t_end !== undefined) {
    doc.time ??= {};
    delete doc.time.T;
    doc.time.t_end = o.t_end;
  }
  return doc;
}

/** Loads the selected preset into the editor, with the form's h, k, T written into it. */
async function loadPresetIntoEditor(open) {
  try {
    const doc = await presetDoc();
    editor.text = JSON.stringify(doc, null, 2);
    if (open) {
      $('#scene-panel').open = true;
      editor.textarea.focus();
    }
  } catch (e) {
    setStatus(`Cannot load preset: ${e.message}`, true);
  }
}

$('#edit-preset').addEventListener('click', () => {
  // Do not throw away a scene the user has been editing without asking.
  if (editor.edited && !confirm('Replace the edited scene with the preset?')) return;
  loadPresetIntoEditor(true);
});

function submitScene() {
  // Syntax errors are shown locally (with their line) instead of a bare 400 from the server.
  if (editor.parse() === null) {
    setStatus('The scene is not valid JSON; see the marked line.', true);
    return;
  }
  submit(editor.text, true);
}
$('#submit-scene').addEventListener('click', submitScene);
editor.textarea.addEventListener('keydown', (ev) => {
  if (ev.key === 'Enter' && (ev.ctrlKey || ev.metaKey)) {
    ev.preventDefault();
    submitScene();
  }
});
$('#format-scene').addEventListener('click', () => {
  const doc = editor.parse();
  if (doc !== null) {
    const errors = editor.errors;
    editor.text = JSON.stringify(doc, null, 2);
    editor.showErrors(errors); // the notes follow their keys to the new lines
  }
});

// A scene on an uploaded mesh starts from the selected preset (an imported mesh has no h).
new MeshUpload($('#mesh-upload'), {
  baseScene: async () => ({ doc: await presetDoc(false), name: presetSelect.value }),
  onScene: (doc) => {
    if (editor.edited && !confirm('Replace the edited scene with the scene on the uploaded mesh?')) return false;
    editor.text = JSON.stringify(doc, null, 2);
    $('#scene-panel').open = true;
    $('#scene-panel').scrollIntoView({ block: 'nearest' });
    return true;
  },
});

presetSelect.addEventListener('change', () => {
  const p = presetList.find((x) => x.name === presetSelect.value);
  presetDesc.textContent = p?.description || '';
});

// ---- start -------------------------------------------------------------------------------

async function start() {
  try {
    presetList = (await api.presets()).presets;
    presetSelect.replaceChildren(...presetList.map((p) => el('option', { value: p.name }, p.name)));
    presetSelect.dispatchEvent(new Event('change'));
    await loadPresetIntoEditor(false);
  } catch (e) {
    setStatus(`Cannot load the presets: ${e.message}`, true);
  }
  await jobs.refresh();
  // #job=<id> (kept in the address while a job is shown) reopens that job after a reload.
  const m = /^#job=([0-9a-f-]{36})$/.exec(location.hash);
  if (m) {
    try {
      jobs.upsert(await api.job(m[1]));
      jobs.select(m[1]);
    } catch {
      history.replaceState(null, '', location.pathname);
    }
  }
  document.body.dataset.ready = 'true';
}

start();
