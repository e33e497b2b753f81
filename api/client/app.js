// Entry point: wires the preset form, the mesh upload, the scene editor, the job list and
// the result views.
//
// Two ways to submit, matching POST /jobs: {preset, overrides} from the form (errors point
// at /preset or /overrides/..., shown under those inputs), or a whole scene from the editor
// (errors point into the scene, shown on the editor's lines).

import * as api from './api.js';
import { $, el, fmtSeconds } from './util.js';
import { SceneEditor } from './editor.js';
import { JobList, isFinished, rememberLabel } from './jobs.js';
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
    // In the one-column layout the results are below the list: bring them into view, and
    // again once they are drawn (the view grows while it loads, which would leave a smooth
    // scroll started now short of its target).
    if (byUser && narrow.matches) scrollToResults(job.id);
  },
  onUpdate: (job) => {
    if (job.id !== jobs.selected) return;
    if (job.deleted) {
      clearView('The job was deleted.');
      // The address no longer names it (a reload would ask for a deleted job).
      if (location.hash === `#job=${job.id}`) history.replaceState(null, '', location.pathname + location.search);
    } else if (!isFinished(job) || shownId !== job.id) show(job);
  },
});

/** Scrolls the results to the top of the window now and when the job's view is ready. */
function scrollToResults(id) {
  const panel = $('#view-panel');
  panel.scrollIntoView({ block: 'start' });
  const until = Date.now() + 10_000;
  const again = () => {
    if (jobs.selected !== id || Date.now() > until) return;
    if (viewRoot.dataset.job === id && ['ready', 'waiting', 'error'].includes(viewRoot.dataset.state)) {
      requestAnimationFrame(() => panel.scrollIntoView({ block: 'start' }));
    } else setTimeout(again, 100);
  };
  again();
}

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
  const eta = p.eta_s != null ? ` · ETA ${fmtSeconds(p.eta_s)}` : '';
  const lines = {
    queued: 'is waiting for a worker.',
    running: `is running: step ${p.step} of ${p.steps} (${p.percent ?? 0}%${eta}).`,
    cancelled: `was cancelled at step ${p.step}.`,
    failed: 'failed.',
  };
  viewRoot.dataset.state = 'waiting';
  viewRoot.dataset.job = job.id;
  const children = [
    el('h2', {}, job.scene || 'job', ' ', el('small', {}, job.id.slice(0, 8))),
    el('p', { class: 'placeholder' }, `This ${job.kind || 'simulation'} ${lines[job.status] || job.status}`),
  ];
  if (job.status === 'running' || job.status === 'queued') {
    children.push(el('div', { class: 'run-progress' },
      el('progress', { id: 'run-progress', max: '100', value: String(p.percent ?? 0), 'aria-label': `progress of job ${job.id.slice(0, 8)}` }),
      el('span', { id: 'run-eta' }, job.status === 'queued' ? 'queued' : `${p.percent ?? 0}%${eta}`)));
  }
  if (job.error) {
    const smallness = /\/problems\/smallness$/.test(job.error.type || '');
    if (smallness) {
      // The detail already names the condition and both numbers: said once, and the way
      // out ("smallness": "warn") is a button rather than a sentence to act on by hand.
      const detail = String(job.error.detail || job.error.title).replace(/\s*Set "smallness": "warn" to run anyway\.?\s*$/, '');
      children.push(el('p', { class: 'error', id: 'job-error' }, detail));
      children.push(rerunWithWarn(job));
    } else {
      children.push(el('p', { class: 'error', id: 'job-error' }, `${job.error.title}: ${job.error.detail}`));
    }
    for (const e of job.error.errors || []) children.push(el('p', { class: 'error' }, el('code', {}, e.pointer), ': ', e.message));
    markFailedScene(job);
  }
  viewRoot.replaceChildren(...children);
}

/**
 * The offer to rerun a job refused by the smallness condition (2.31) with "smallness":
 * "warn": a button when this tab knows the scene it ran, else how to do it by hand.
 */
function rerunWithWarn(job) {
  const text = submittedText.get(job.id);
  let doc = null;
  try {
    doc = text === undefined ? null : JSON.parse(text);
  } catch {
    doc = null;
  }
  if (!doc || typeof doc !== 'object' || doc.preset || doc.study) {
    return el('p', { class: 'hint', id: 'rerun-warn-hint' },
      'To run it anyway, add "smallness": "warn" to its scene (Edit as scene) and run it again: the run then records the violation as a warning.');
  }
  return el('p', {},
    el('button', {
      id: 'rerun-warn', type: 'button',
      onclick: () => {
        const warned = { ...doc, smallness: 'warn' };
        const t = JSON.stringify(warned, null, 2);
        submit(t, { label: { ...sceneFacts(warned), edited: true }, text: t });
      },
    }, 'Rerun with "smallness": "warn"'),
    el('span', { class: 'hint' }, ' runs it anyway and records the violation as a warning.'));
}

/**
 * The scene text each job was submitted with from this tab (the editor's text, or the preset
 * document the form expanded to), so that a job failing with a pointer into its scene (e.g.
 * /loads/f0/0 for a load infinite at a quadrature point) can be marked on its editor line.
 */
const submittedText = new Map();

function markFailedScene(job) {
  const errs = (job.error?.errors || []).filter((e) => typeof e.pointer === 'string' && e.pointer.startsWith('/'));
  const text = submittedText.get(job.id);
  if (!errs.length || text === undefined) return;
  // Never replace a scene the user is editing with another one.
  if (editor.text !== text) {
    if (editor.edited) return;
    editor.text = text;
    editorFromForm = false;
  }
  editor.showErrors(errs);
  $('#scene-panel').open = true;
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

/** Maps pointers into an expanded preset back to the form's inputs. */
const FORM_POINTERS = { '/mesh/h': '/overrides/h', '/time/k': '/overrides/k', '/time/t_end': '/overrides/t_end', '/name': '/name', '/study/name': '/name' };

/**
 * Submits `body` (a document or the editor's text). `fromEditor`: pointers are into the
 * editor's text; else into the form (`mapped`: the body is the preset expanded by the form,
 * whose pointers FORM_POINTERS maps back). `label`: what the job list shows for it;
 * `text`: the scene text to mark if the job fails at a pointer.
 */
async function submit(body, { fromEditor = false, mapped = false, label = null, text = null } = {}) {
  clearFieldErrors();
  // A new submission: the marks of an earlier one (from the editor or a failed job) go.
  editor.clearErrors();
  setStatus('Submitting…');
  try {
    const job = await api.submit(body);
    setStatus(
      job.status === 'succeeded'
        ? `Already computed: job ${job.id.slice(0, 8)} (identical scene).`
        : `Submitted: job ${job.id.slice(0, 8)}.`,
    );
    if (label) rememberLabel(job.id, label);
    if (text !== null) submittedText.set(job.id, text);
    jobs.upsert(job);
    jobs.select(job.id);
  } catch (e) {
    if (e.status === 422 && e.errors.length) {
      // From the editor every pointer is into the scene text; from the form they name inputs.
      let rest = [];
      if (fromEditor) editor.showErrors(e.errors);
      else rest = showFieldErrors(mapped ? e.errors.map((x) => ({ ...x, pointer: FORM_POINTERS[x.pointer] ?? x.pointer })) : e.errors);
      const extra = rest.map((r) => `${r.pointer}: ${r.message}`).join('; ');
      setStatus(`${e.title || 'invalid scene'}: ${e.errors.length} error${e.errors.length > 1 ? 's' : ''}${extra ? ` (${extra})` : ''}`, true);
    } else {
      setStatus(`${e.title || 'error'}: ${e.message}`, true);
    }
  }
}

// "Continue…" in a simulation's view: the continuation of that job to the asked final time.
document.addEventListener('continue-job', (ev) => {
  const { job, t_end } = ev.detail;
  submit({ continue: { job: job.id, t_end } });
});

/** h, k and T of a scene document (as written: "1/32" stays a fraction), for the job list. */
function sceneFacts(doc) {
  if (doc?.study) {
    const st = doc.study;
    return { study: true, h: st.h, k: st.k };
  }
  const t = doc?.time || {};
  const T = t.t_end ?? t.T;
  let k = t.k;
  if (k === undefined && t.N !== undefined && T !== undefined) k = `${T}/${t.N}`;
  const facts = { h: doc?.mesh?.h, k, T };
  if (doc?.domain?.mesh) facts.mesh = doc.mesh?.refine !== undefined ? `own mesh, refine ${doc.mesh.refine}` : 'own mesh';
  return facts;
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

const nameInput = $('#job-name');

/** Whether the selected entry of the menu is a study preset (paper-table-1, ...). */
const isStudy = () => presetList.find((x) => x.name === presetSelect.value)?.kind === 'study';

$('#preset-form').addEventListener('submit', async (ev) => {
  ev.preventDefault();
  const o = overrides();
  const name = nameInput.value.trim();
  const study = isStudy();
  let doc;
  try {
    doc = await presetDoc();
  } catch (e) {
    setStatus(`Cannot load preset: ${e.message}`, true);
    return;
  }
  const label = { ...sceneFacts(doc), preset: presetSelect.value, edited: false };
  const text = study ? null : JSON.stringify(doc, null, 2);
  if (name) {
    // A named run is the preset's document with the name (POST {preset} has no name).
    if (study) doc.study.name = name;
    else doc.name = name;
    submit(doc, { mapped: true, label, text: JSON.stringify(doc, null, 2) });
  } else if (study) {
    submit({ study: { preset: presetSelect.value } }, { label });
  } else {
    submit({ preset: presetSelect.value, ...(Object.keys(o).length ? { overrides: o } : {}) }, { label, text });
  }
});

let editorFromForm = true; // see editorFollowsForm
const presetDocs = new Map(); // name -> the server's document (fetched once)

async function fetchPreset(name) {
  if (!presetDocs.has(name)) presetDocs.set(name, api.preset(name).catch((e) => {
    presetDocs.delete(name);
    throw e;
  }));
  return structuredClone(await presetDocs.get(name));
}

/**
 * The selected preset's document with the form's h (unless `withH` is false), k and T; a
 * study preset's document ({"study": {...}}) as it is.
 */
async function presetDoc(withH = true) {
  const doc = await fetchPreset(presetSelect.value);
  if (doc.study) return doc;
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

/**
 * Loads the selected preset into the editor, with the form's h, k, T written into it.
 * `following`: only while the editor still follows the form once the preset is read (the
 * user may have typed into it meanwhile).
 */
async function loadPresetIntoEditor(open, following = false) {
  try {
    const doc = await presetDoc();
    if (following && (editor.edited || !editorFromForm)) return;
    editor.text = JSON.stringify(doc, null, 2);
    editorFromForm = true;
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
  // Syntax errors are shown locally (with their line) instead of a bare 400 from the server;
  // the previous answer's errors no longer describe this text.
  const doc = editor.parse();
  if (doc === null) {
    editor.clearErrors();
    editor.revealSyntax();
    setStatus('The scene is not valid JSON; see the marked line.', true);
    return;
  }
  const label = { ...sceneFacts(doc), edited: editor.edited };
  submit(editor.text, { fromEditor: true, label, text: editor.text });
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
const meshUpload = new MeshUpload($('#mesh-upload'), {
  baseScene: async () => {
    // A study preset starts from the scene it studies.
    if (isStudy()) {
      const study = (await fetchPreset(presetSelect.value)).study;
      const scene = typeof study.scene === 'string' ? await fetchPreset(study.scene) : study.scene;
      return { doc: scene, name: typeof study.scene === 'string' ? study.scene : presetSelect.value };
    }
    return { doc: await presetDoc(false), name: presetSelect.value };
  },
  onScene: (doc) => {
    if (editor.edited && !confirm('Replace the edited scene with the scene on the uploaded mesh?')) return false;
    editor.text = JSON.stringify(doc, null, 2);
    editorFromForm = false;
    $('#scene-panel').open = true;
    $('#scene-panel').scrollIntoView({ block: 'nearest' });
    return true;
  },
});

// "Upload the mesh file again" in the view of a job whose mesh was deleted: the mesh panel,
// open, with its file chooser.
document.addEventListener('mesh-upload-wanted', () => {
  const panel = $('#mesh-panel');
  panel.open = true;
  panel.scrollIntoView({ block: 'nearest' });
  const input = $('#mesh-file');
  input.focus();
  input.click();
});

/**
 * The description of the selected preset, and, when h, k or T are typed, the values the run
 * will use (the description quotes the preset's own).
 */
async function describePreset() {
  const p = presetList.find((x) => x.name === presetSelect.value);
  const study = p?.kind === 'study';
  for (const k of ['h', 'k', 't_end']) $(`#ov-${k}`).disabled = study;
  // A study's levels are its own: the hint about h and k would not apply.
  $('#ov-hint').hidden = study;
  const parts = [el('span', {}, p?.description || '')];
  if (study) {
    parts.push(el('span', { class: 'preset-note' },
      ' A study runs every level and a reference, then shows the error table. Its document ({"study": {...}}) can be edited or pasted in the scene editor like a scene.'));
  } else {
    const o = overrides();
    if (Object.keys(o).length) {
      try {
        const base = await fetchPreset(presetSelect.value);
        const f = sceneFacts(base);
        const said = (key, label, was) => (o[key] !== undefined ? `${label} = ${o[key]}${was !== undefined ? ` (preset: ${was})` : ''}` : null);
        const run = [said('h', 'h', f.h), said('k', 'k', f.k), said('t_end', 'T', f.T)].filter(Boolean).join(', ');
        parts.push(el('strong', { class: 'preset-note', id: 'preset-run' }, ` This run: ${run}.`));
      } catch {
        // The description alone.
      }
    }
  }
  presetDesc.replaceChildren(...parts);
}

/**
 * The editor follows the form (preset, h, k, T) while its text is the form's: not once the
 * user edited it, nor after a scene on an uploaded mesh or a failed job's scene was put in.
 */
let follow = 0;
function editorFollowsForm() {
  clearTimeout(follow);
  follow = setTimeout(() => {
    if (!editor.edited && editorFromForm) loadPresetIntoEditor(false, true);
  }, 150);
}

presetSelect.addEventListener('change', () => {
  describePreset();
  editorFollowsForm();
  saveForm();
  // The mesh form's note names the preset its scene starts from: the one now selected.
  meshUpload.updateBaseHint();
});
for (const k of ['h', 'k', 't_end']) {
  $(`#ov-${k}`).addEventListener('input', () => {
    describePreset();
    editorFollowsForm();
    saveForm();
  });
}
nameInput.addEventListener('input', saveForm);

// ---- what a reload keeps -------------------------------------------------------------------
// The form and an edited scene text live in this tab's sessionStorage, so a reload (or a
// crash of the tab) does not lose them.

const FORM_STORE = 'contact-sim-form';
let saving = 0;
function saveForm() {
  clearTimeout(saving);
  saving = setTimeout(() => {
    const state = {
      preset: presetSelect.value,
      h: $('#ov-h').value, k: $('#ov-k').value, t_end: $('#ov-t_end').value, name: nameInput.value,
      scene: editor.edited ? { text: editor.text, loaded: editor.loaded ?? '' } : null,
    };
    try {
      sessionStorage.setItem(FORM_STORE, JSON.stringify(state));
    } catch {
      // Not kept (storage refused).
    }
  }, 100);
}
editor.textarea.addEventListener('input', saveForm);

/** Restores the form and the edited text; true when an edited text was restored. */
function restoreForm() {
  let state;
  try {
    state = JSON.parse(sessionStorage.getItem(FORM_STORE) || 'null');
  } catch {
    state = null;
  }
  if (!state) return false;
  if (presetList.some((p) => p.name === state.preset)) presetSelect.value = state.preset;
  $('#ov-h').value = state.h || '';
  $('#ov-k').value = state.k || '';
  $('#ov-t_end').value = state.t_end || '';
  nameInput.value = state.name || '';
  if (state.scene) {
    editor.restore(state.scene.text, state.scene.loaded);
    editorFromForm = false;
    return true;
  }
  return false;
}

// Without a key (the dialog was cancelled) the page asks no more by itself: a button in the
// header asks again and reloads.
document.addEventListener('api-key-declined', () => {
  if ($('#auth-button')) return;
  $('.top').append(el('button', {
    id: 'auth-button', type: 'button', class: 'small',
    onclick: async () => {
      if (await api.askApiKey()) location.reload();
    },
  }, 'Enter API key'));
  setStatus('This server needs an API key: use "Enter API key" at the top.', true);
});

// ---- start -------------------------------------------------------------------------------

async function start() {
  try {
    const list = await api.presets();
    const scenes = list.presets.map((p) => ({ ...p, kind: 'scene' }));
    const studies = (list.studies || []).map((p) => ({ ...p, kind: 'study' }));
    presetList = [...scenes, ...studies];
    const option = (p) => el('option', { value: p.name }, p.name);
    presetSelect.replaceChildren(
      el('optgroup', { label: 'Simulations' }, scenes.map(option)),
      ...(studies.length ? [el('optgroup', { label: 'Convergence studies (error tables)' }, studies.map(option))] : []),
    );
    const restored = restoreForm();
    describePreset();
    if (!restored) await loadPresetIntoEditor(false);
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
