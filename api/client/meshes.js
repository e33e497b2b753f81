// Your own mesh: upload a gmsh .msh file (file input, or dropped anywhere on the page) to
// POST /meshes, show the server's summary of it (or its problem detail), and a form that
// binds each physical group to a boundary condition and writes a scene using the mesh into
// the scene editor, where it can still be edited before it is run.
//
// The summary's figures may come at the top level of the answer or under "summary":
//   {id, bytes, created_at, dimension, nodes, cells, boundary_facets, groups: [{name, facets,
//    measure}], bounding_box: {min, max}, min_cell_size, mean_cell_size, max_cell_size, min_quality,
//    mean_quality}

import * as api from './api.js';
import { el, fmt } from './util.js';

const KINDS = ['free', 'clamped', 'traction', 'contact'];
const KIND_LABELS = { free: 'free', clamped: 'clamped', traction: 'traction', contact: 'contact' };
const MAX_NAME = 60;

/** A first guess of a group's condition from its name (the user changes it in the form). */
export function guessKind(name) {
  const n = name.toLowerCase();
  if (/clamp|fix|dirichlet|encast/.test(n)) return 'clamped';
  if (/contact|support|foundation|base|bottom|floor|ground/.test(n)) return 'contact';
  if (/^top$|^lid$/.test(n)) return 'clamped';
  if (/trac|load|force|press|neumann/.test(n)) return 'traction';
  return 'free';
}

/** The summary figures of a POST /meshes answer (top level or under "summary"). */
export function summaryOf(answer) {
  const s = answer?.summary ?? answer ?? {};
  return { ...s, id: answer?.id ?? s.id, bytes: answer?.bytes ?? s.bytes, created: answer?.created_at ?? answer?.created ?? s.created_at ?? s.created };
}

/**
 * A scene on an uploaded mesh: `base` (a preset's document: material, time, damage, friction,
 * loads, output, ...) with its domain, mesh and boundary replaced. `bindings`: [{group, type,
 * f2}] with type free (left out: traction-free), clamped, traction or contact.
 */
export function buildScene(base, { id, name, refine, bindings, dim = 2 }) {
  const doc = structuredClone(base);
  // The mesh decides the dimension: a 2D preset's vectors on a tetrahedral mesh become
  // 3-vectors (its y, the vertical, becomes z), a 3D preset's on triangles 2-vectors.
  const fit = (v) => {
    if (!Array.isArray(v) || v.length === dim) return v;
    if (v.length === 2 && dim === 3) return [v[0], 0, v[1]];
    if (v.length === 3 && dim === 2) return [v[0], v[2]];
    return v;
  };
  if (doc.loads && typeof doc.loads === 'object') {
    for (const k of Object.keys(doc.loads)) doc.loads[k] = fit(doc.loads[k]);
  }
  if (doc.initial && typeof doc.initial === 'object' && 'u0' in doc.initial) doc.initial.u0 = fit(doc.initial.u0);
  if (name) doc.name = name;
  doc.domain = { mesh: id };
  doc.mesh = { refine };
  doc.boundary = bindings
    .filter((b) => b.type !== 'free')
    .map((b) => (b.type === 'traction' ? { type: b.type, group: b.group, f2: b.f2 } : { type: b.type, group: b.group }));
  return doc;
}

/** A number when the text is one, else the text (a formula such as "-x"). */
function numberOrText(s) {
  const t = s.trim();
  return t !== '' && Number.isFinite(Number(t)) ? Number(t) : t;
}

const point = (p) => `(${(p || []).map((x) => fmt(x)).join(', ')})`;

export class MeshUpload {
  /**
   * `root`: the panel to build in. `baseScene()`: a promise of the document to start from
   * (the selected preset, with the form's k and T) and its name; `onScene(doc)`: put a built
   * scene into the editor (returns false when the user keeps the edited text).
   */
  constructor(root, { baseScene, onScene }) {
    this.root = root;
    this.baseScene = baseScene;
    this.onScene = onScene;
    this.input = el('input', {
      id: 'mesh-file', type: 'file', accept: '.msh', 'aria-describedby': 'mesh-hint',
      onchange: () => this.input.files[0] && this.upload(this.input.files[0]),
    });
    this.status = el('p', { id: 'mesh-status', class: 'status-line', role: 'status' });
    this.result = el('div', { id: 'mesh-result' });
    root.append(
      el('div', { class: 'field' }, el('label', { for: 'mesh-file' }, 'gmsh .msh file (MSH 4.1 or 2.2, ASCII or binary)'), this.input),
      el('p', { class: 'hint', id: 'mesh-hint' }, 'Or drop a .msh file anywhere on the page. Physical groups of lines (2D) or surfaces (3D) become the groups you can bind below.'),
      this.status,
      this.result,
    );
    this.bindDrop();
  }

  setStatus(text, bad = false) {
    this.status.textContent = text;
    this.status.classList.toggle('bad', bad);
  }

  /** Drag and drop of a file onto the whole page. */
  bindDrop() {
    const body = document.body;
    const hasFiles = (ev) => [...(ev.dataTransfer?.types || [])].includes('Files');
    let depth = 0; // dragenter/leave fire for every child element crossed
    body.addEventListener('dragenter', (ev) => {
      if (!hasFiles(ev)) return;
      depth++;
      body.classList.add('dropping');
    });
    body.addEventListener('dragleave', () => {
      depth = Math.max(0, depth - 1);
      if (!depth) body.classList.remove('dropping');
    });
    body.addEventListener('dragover', (ev) => {
      if (!hasFiles(ev)) return;
      ev.preventDefault();
      ev.dataTransfer.dropEffect = 'copy';
    });
    body.addEventListener('drop', (ev) => {
      if (!hasFiles(ev)) return;
      ev.preventDefault();
      depth = 0;
      body.classList.remove('dropping');
      const file = ev.dataTransfer.files[0];
      if (!file) return;
      this.root.closest('details')?.setAttribute('open', '');
      if (!/\.msh$/i.test(file.name)) {
        this.setStatus(`${file.name} is not a .msh file: only gmsh meshes can be dropped here.`, true);
        return;
      }
      this.upload(file);
    });
  }

  async upload(file) {
    this.result.replaceChildren();
    delete this.root.dataset.state;
    this.setStatus(`Uploading ${file.name} (${fmt(file.size / 1024, 3)} KiB)…`);
    let res;
    try {
      res = await api.uploadMesh(await file.arrayBuffer());
    } catch (e) {
      this.root.dataset.state = 'error';
      this.setStatus(`${file.name} was not accepted.`, true);
      this.result.replaceChildren(el('p', { class: 'error', id: 'mesh-error' },
        e.title ? `${e.title}: ` : '', e.message || String(e),
        e.status === 404 || e.status === 405 ? ' (this server does not take mesh uploads)' : ''));
      return;
    }
    const s = summaryOf(res.body);
    this.mesh = { ...s, file: file.name };
    this.setStatus(res.status === 200
      ? `${file.name} was uploaded before (same content): mesh ${String(s.id).slice(0, 12)}.`
      : `Uploaded ${file.name}: mesh ${String(s.id).slice(0, 12)}.`);
    this.show();
    this.root.dataset.state = 'ready';
    // A job shown without its (deleted) mesh may be drawable again.
    document.dispatchEvent(new CustomEvent('mesh-uploaded', { detail: { id: s.id } }));
  }

  /** The summary table and the group form. */
  show() {
    const m = this.mesh;
    const bb = m.bounding_box || {};
    const size = bb.min && bb.max ? bb.max.map((x, i) => fmt(x - bb.min[i])).join(' × ') : '–';
    const row = (key, label, ...value) => el('tr', { dataset: { key } }, el('th', { scope: 'row' }, label), el('td', {}, ...value));
    const summary = el('table', { id: 'mesh-summary', class: 'mesh-summary' },
      el('caption', {}, m.file),
      el('tbody', {},
        row('id', 'mesh id', el('code', { title: m.id }, String(m.id).slice(0, 16), '…')),
        row('dimension', 'dimension', String(m.dimension)),
        row('nodes', 'nodes', String(m.nodes)),
        row('cells', m.dimension === 3 ? 'cells (tetrahedra)' : 'cells (triangles)', String(m.cells)),
        row('boundary_facets', 'boundary facets', String(m.boundary_facets ?? '–')),
        row('bounding_box', 'bounding box', `${point(bb.min)} – ${point(bb.max)}`, el('br'), el('small', {}, size)),
        row('cell_size', 'cell size', `${fmt(m.min_cell_size)} – ${fmt(m.max_cell_size)}${m.mean_cell_size != null ? ` (mean ${fmt(m.mean_cell_size)})` : ''}`),
        row('quality', 'quality (1 = equilateral)', `min ${fmt(m.min_quality, 3)}, mean ${fmt(m.mean_quality, 3)}`)));

    const groups = m.groups || [];
    const dim = m.dimension || 2;
    const measure = dim === 3 ? 'area' : 'length';
    this.rows = groups.map((g) => {
      const kind = el('select', { class: 'kind', 'aria-label': `condition on group ${g.name}`, onchange: () => sync() },
        KINDS.map((k) => el('option', { value: k }, KIND_LABELS[k])));
      kind.value = guessKind(g.name);
      // In 3D a traction starts as a unit push down (z is the vertical), to edit.
      const f2 = Array.from({ length: dim }, (_, i) => el('input', {
        class: `f2 f2-${'xyz'[i]}`, value: dim === 3 && i === 2 ? '-1' : '0', size: '5', inputmode: 'decimal', autocomplete: 'off',
        'aria-label': `f2 ${'xyz'[i]} on group ${g.name}`,
      }));
      const sync = () => {
        for (const input of f2) input.disabled = kind.value !== 'traction';
      };
      sync();
      const tr = el('tr', { dataset: { group: g.name, facets: String(g.facets) } },
        el('th', { scope: 'row' }, el('span', { class: 'group-name' }, g.name),
          el('small', { class: 'group-facets' }, `${g.facets} facet${g.facets === 1 ? '' : 's'} · ${measure} ${fmt(g.measure)}`)),
        el('td', {}, kind),
        el('td', { class: 'f2-cell' }, ...f2));
      return { group: g.name, kind, f2, tr };
    });
    this.refine = el('input', { id: 'mesh-refine', type: 'number', min: '0', max: '6', step: '1', value: '0', inputmode: 'numeric' });
    this.name = el('input', { id: 'mesh-scene-name', value: m.file.replace(/\.msh$/i, '').slice(0, MAX_NAME), autocomplete: 'off' });
    const form = el('form', { id: 'mesh-form', novalidate: true, onsubmit: (ev) => { ev.preventDefault(); this.build(); } },
      groups.length
        ? el('div', { class: 'table-wrap' }, el('table', { id: 'mesh-groups', class: 'mesh-groups' },
          el('caption', {}, 'Boundary conditions on the physical groups (free: traction-free, left out of the scene)'),
          el('thead', {}, el('tr', {}, el('th', {}, 'group'), el('th', {}, 'condition'), el('th', {}, `f2 (${dim === 3 ? 'x, y, z' : 'x, y'})`))),
          el('tbody', {}, this.rows.map((r) => r.tr))))
        : el('p', { class: 'warning' }, 'The mesh has no physical groups of facets: bind the boundary in the scene editor with "from"/"to" segments or "on" formulas.'),
      el('div', { class: 'overrides' },
        el('div', { class: 'field' }, el('label', { for: 'mesh-refine' }, 'refine (uniform)'), this.refine),
        el('div', { class: 'field mesh-name' }, el('label', { for: 'mesh-scene-name' }, 'scene name'), this.name)),
      el('p', { class: 'hint', id: 'mesh-base' }),
      el('div', { class: 'buttons' }, el('button', { type: 'submit', id: 'mesh-build', class: 'primary' }, 'Put into the scene editor')));
    this.result.replaceChildren(summary, form);
    this.updateBaseHint();
  }

  /** Says which preset the rest of the scene comes from. */
  async updateBaseHint() {
    const hint = this.result.querySelector('#mesh-base');
    if (!hint) return;
    try {
      const { name } = await this.baseScene();
      hint.textContent = `Material, time, loads, damage, friction and output are taken from the preset ${name} (chosen above). A group set to free is not written into the scene: the scene format has no "free" part, and every boundary no part names is traction-free.`;
    } catch {
      hint.textContent = '';
    }
  }

  /** The form's bindings. */
  bindings() {
    return this.rows.map((r) => ({ group: r.group, type: r.kind.value, f2: r.f2.map((i) => numberOrText(i.value || '0')) }));
  }

  async build() {
    let base;
    try {
      base = await this.baseScene();
    } catch (e) {
      this.setStatus(`Cannot load the preset to start from: ${e.message}`, true);
      return;
    }
    const refine = Math.max(0, Math.round(Number(this.refine.value) || 0));
    const doc = buildScene(base.doc, {
      id: this.mesh.id,
      name: this.name.value.trim().slice(0, MAX_NAME) || undefined,
      refine,
      bindings: this.bindings(),
      dim: this.mesh.dimension || 2,
    });
    if (!doc.boundary.some((b) => b.type === 'clamped')) {
      this.setStatus('Clamp at least one group: a scene needs a clamped part (Γ1).', true);
      return;
    }
    if (this.onScene(doc) !== false) this.setStatus('The scene is in the editor: check it and press "Run scene".');
  }
}
