// The result view of a finished simulation: the deformed mesh (any triangle mesh) coloured
// by a field, the boundary by the kind of its parts and Γ3 by its stick/slip state, zoom
// (wheel, buttons) and pan (drag), the value under the pointer, a time slider with play,
// norms over time, and download links. Data (all from the real endpoints):
//   GET /jobs/{id}/fields?step=N&mesh=1  -> {job, mesh: {nodes, triangles, boundary_edges, parts},
//        n, t, u: [ux0, uy0, ...], w: [...], zeta: [...], von_mises: [per triangle],
//        contact: [{node, slip_velocity, friction_traction, bound, slipping}]}
//   GET /jobs/{id}/summary -> {mesh, time, final, stats, steps: [{n, t, w_V, u_V, zeta_L2, zeta_min, ...}], ...}
//   GET /jobs/{id}/result.pvd -> which steps are stored (see api.storedSteps).
// The mesh is fetched once (with the first step); later steps are fetched without it and
// kept in a small cache, so scrubbing back and forth does not refetch.
//
// A 3D job (its mesh has "dim": 3; fetched as its boundary surface, surface=1) is drawn by viewer3d.js
// (three.js, loaded only then) in place of the canvas; everything around the picture is the
// same, with u, w of three components per node and von Mises per tetrahedron.

import * as api from './api.js';
import { el, fmt, fmtBytes, fmtStep, fmtSeconds, distinctDigits, tickDigits } from './util.js';
import { drawField, probe, partKinds, edgeKind, boundingBox, KINDS, STICK, SLIP } from './render.js';
import { cssGradient, niceRange, niceTicks, LUT } from './colormap.js';
import { linePlot } from './plots.js';

const QUANTITIES = {
  zeta: { label: 'damage ζ', key: 'zeta', perCell: false },
  von_mises: { label: 'von Mises stress (per triangle)', key: 'von_mises', perCell: true },
  w: { label: 'velocity |w|', key: 'w', perCell: false },
  estimate: { label: 'error indicator η (per triangle)', key: 'estimate', perCell: true },
};
const CACHE_STEPS = 400;
const RUN_RANGE_STEPS = 200;
const FRAME_MS = 150;
/** A 3D contact face with more nodes than this is plotted in BINS slices along Γ3. */
const BIN_ABOVE = 60;
const BINS = 40;
const ZOOM_MIN = 0.5;
const ZOOM_MAX = 500;

export class SimulationView {
  constructor(root) {
    this.root = root;
    this.token = 0; // increases with every step request; stale answers are dropped
    this.cache = new Map();
    this.playing = false;
  }

  /** Shows the results of a succeeded simulation job. */
  async open(job) {
    this.close();
    const id = job.id;
    this.job = job;
    this.root.dataset.state = 'loading';
    this.root.dataset.job = id;
    this.root.replaceChildren(el('p', { class: 'hint' }, 'Loading results…'));
    const answers = await Promise.allSettled([api.summary(id), api.storedSteps(id), api.fields(id, 'last', true)]);
    if (this.job !== job) return; // another job was opened meanwhile
    const [summary, steps, first] = answers.map((a) => a.value);
    const refused = answers.find((a) => a.status === 'rejected')?.reason;
    // An uploaded mesh deleted after the run: the summary (and the norms in it) are kept,
    // while everything drawn on the mesh answers 409 until the file is uploaded again.
    if (summary && answers[2].status === 'rejected' && refused?.status === 409) {
      this.openWithoutMesh(job, summary);
      return;
    }
    if (refused) {
      this.root.dataset.state = 'error';
      this.root.replaceChildren(el('p', { class: 'error' }, `Cannot load the results: ${refused.message}`));
      return;
    }
    this.mesh = first.mesh;
    delete first.mesh;
    this.dim = this.mesh.dim === 3 ? 3 : 2;
    if (this.dim === 3) {
      try {
        const { View3D } = await import('./viewer3d.js');
        if (this.job !== job) return;
        this.d3 = new View3D(this.mesh);
      } catch (e) {
        if (this.job !== job) return;
        this.root.dataset.state = 'error';
        this.root.replaceChildren(el('p', { class: 'error' }, `Cannot load the 3D viewer: ${e.message}`));
        return;
      }
    }
    this.kinds = partKinds(this.mesh);
    this.bbox = boundingBox(this.mesh.nodes);
    this.view = { zoom: 1, panX: 0, panY: 0 };
    this.summary = summary;
    this.steps = steps.length ? steps : [{ n: first.n, t: first.t }];
    this.cache = new Map([[first.n, first]]);
    this.current = first;
    this.build();
    const idx = Math.max(0, this.steps.findIndex((s) => s.n === first.n));
    this.slider.value = String(idx);
    this.showLoaded(idx, first);
    this.root.dataset.state = 'ready';
  }

  /**
   * The view of a job whose uploaded mesh was deleted: what the summary holds (run info,
   * warnings, the norms over time) and how to get the picture back. Uploading a mesh (any:
   * the server knows whether it is this job's) opens the job again.
   */
  openWithoutMesh(job, summary) {
    const id = job.id;
    this.summary = summary;
    this.meshUploaded = () => {
      if (this.job === job) this.open(job);
    };
    document.addEventListener('mesh-uploaded', this.meshUploaded);
    const plots = el('div', { class: 'plots', id: 'plots' });
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, job.scene || 'simulation', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' }, this.summaryLink(id))),
      this.runInfo(summary, null),
      ...(summary.warnings || []).map((w) => el('p', { class: 'warning' }, w)),
      el('div', { class: 'mesh-missing', id: 'mesh-missing' },
        el('p', {}, 'The mesh file this job ran on has been deleted, so its picture, the time slider and the VTU and ParaView downloads are not available. '
          + 'The summary and the norms over time below are kept.'),
        el('p', {}, 'To see the picture again, upload the same .msh file again: ',
          el('button', {
            id: 'mesh-upload-again', type: 'button', class: 'small',
            onclick: () => document.dispatchEvent(new CustomEvent('mesh-upload-wanted')),
          }, 'Upload the mesh file again'))),
      el('h3', { class: 'plots-title' }, 'Norms over time'),
      plots,
    );
    this.normPlots(plots, summary, null);
    this.root.dataset.mesh = 'missing';
    this.root.dataset.state = 'ready';
  }

  /**
   * "Continue…": a form asking for the later final time, whose submission (POST /jobs
   * {"continue": {"job", "t_end"}}, sent by the page through a `continue-job` event) goes on
   * from this run's last stored state with its step k.
   */
  continueButton(job, summary) {
    const T = summary.time?.t_end;
    const k = summary.time?.k;
    const input = el('input', {
      id: 'continue-t-end', name: 't_end', size: '6', autocomplete: 'off', 'data-pointer': '/continue/t_end',
      value: T != null ? String(+(2 * T).toPrecision(12)) : '', 'aria-describedby': 'continue-hint',
    });
    const form = el('form', {
      id: 'continue-form', class: 'continue-form', hidden: '', novalidate: '',
      onsubmit: (ev) => {
        ev.preventDefault();
        const v = input.value.trim();
        const t = v !== '' && !Number.isNaN(Number(v)) ? Number(v) : v;
        document.dispatchEvent(new CustomEvent('continue-job', { detail: { job, t_end: t } }));
      },
    },
    el('label', {}, 'to t = ', input),
    el('button', { type: 'submit', id: 'continue-submit', class: 'small primary' }, 'Continue'),
    el('span', { class: 'field-error', 'data-for': '/continue/t_end', role: 'alert' }),
    el('span', { class: 'hint', id: 'continue-hint' },
      ` from t = ${T} with its k = ${fmtStep(k)}: the same steps as one run to that time`));
    const button = el('button', {
      id: 'continue-job', type: 'button', class: 'small', 'aria-expanded': 'false',
      title: 'continue this run to a later final time, from the state after its last step',
      onclick: () => {
        form.hidden = !form.hidden;
        button.setAttribute('aria-expanded', String(!form.hidden));
        if (!form.hidden) input.focus();
      },
    }, 'Continue…');
    this.continueForm = form;
    return button;
  }

  /** The continue form (hidden until asked for) and, for a continuation, its parent. */
  continuation(job, summary) {
    const out = [this.continueForm];
    const c = summary.continued_from;
    if (c) {
      out.push(el('p', { class: 'run-info', id: 'continued-from' },
        `Continued from job ${String(c.job).slice(0, 8)} after its step ${c.step} (t = ${c.t}): steps 1–${c.step} are the parent's.`));
    }
    return out;
  }

  /** The run's figures from its summary (`mesh`: the fields' mesh when it was read). */
  runInfo(summary, mesh) {
    const m = summary.mesh || {};
    const t = summary.time || {};
    const tets = mesh?.tetrahedra?.length ?? m.tetrahedra;
    let cells;
    if (mesh?.dim === 3) {
      const nodes = mesh.surface ? m.nodes ?? '?' : mesh.nodes.length;
      cells = `${nodes} nodes · ${tets ?? '?'} tetrahedra · ${(mesh.surface ? mesh.triangles : mesh.boundary_faces).length} boundary triangles`;
    }
    else if (tets != null) cells = `${m.nodes} nodes · ${tets} tetrahedra`;
    else cells = `${m.nodes} nodes · ${m.triangles} triangles`;
    // A given mesh has no one h: its cells' sizes range from min to max.
    const h = m.h != null ? `h = ${fmtStep(m.h)}`
      : m.cell_size ? `cell size ${fmt(m.cell_size.min)} – ${fmt(m.cell_size.max)} (mean ${fmt(m.cell_size.mean)})` : 'h = ?';
    return el('p', { class: 'run-info' },
      `${cells} · ${h} · k = ${fmtStep(t.k)} · ${t.steps} steps · `,
      `solved in ${fmtSeconds(summary.timing?.solve_s)} · ${summary.stats?.steps_with_slip ?? 0} steps with slip`);
  }

  /** The norms over time from the summary, in `root`; `onPick(t)`: a click shows that time. */
  normPlots(root, summary, onPick) {
    // From t = 0: step 0 (the summary's `initial`) and the solved steps.
    const s = [...(summary.initial ? [summary.initial] : []), ...(summary.steps || [])];
    const ts = s.map((r) => r.t);
    return [
      ['|w|_V', 'w_V', '#1864ab'],
      ['|u|_V', 'u_V', '#5f3dc4'],
      ['|ζ|_Z0', 'zeta_L2', '#2b8a3e'],
      ['min ζ', 'zeta_min', '#c92a2a'],
    ].map(([title, key, colour]) => linePlot(root, { title, xs: ts, ys: s.map((r) => r[key]), colour, ...(onPick ? { onPick } : {}) }));
  }

  /** The summary's download link, with its size once known. */
  summaryLink(id) {
    const path = `/jobs/${id}/summary`;
    const a = api.keyedLink(el('a', { id: 'dl-summary', href: path, download: `summary-${id.slice(0, 8)}.json` }, 'summary JSON'));
    api.sizeInto(a, 'summary JSON', path);
    return a;
  }

  close() {
    this.playing = false; // stopped, not paused: nothing is asked about this job any more
    this.stop();
    this.token++;
    this.job = null;
    if (this.meshUploaded) document.removeEventListener('mesh-uploaded', this.meshUploaded);
    this.meshUploaded = null;
    delete this.root.dataset.mesh;
    this.d3?.dispose();
    this.d3 = null;
    this.resizeObserver?.disconnect();
    cancelAnimationFrame(this.pending);
    this.frame = null;
    this.runRanges = null;
    this.range = null;
    this.root.replaceChildren();
    delete this.root.dataset.state;
    delete this.root.dataset.step;
  }

  build() {
    const { summary, job } = this;
    const id = job.id;
    const f = this.current;
    // Offer only the fields this run stored (a scene's output.fields selects them).
    this.quantity = el('select', { id: 'quantity', onchange: () => this.onRangeInputs(true) },
      Object.entries(QUANTITIES).map(([k, q]) => el('option', { value: k, disabled: !f[q.key] }, this.label(q))));
    this.quantity.value = Object.keys(QUANTITIES).find((k) => f[QUANTITIES[k].key]) || 'zeta';
    // In 3D the body starts deformed visibly (largest displacement 10% of its size).
    const start = this.d3 ? this.suggestedFactor() ?? 1 : 1;
    this.factor = el('input', { id: 'factor', type: 'number', min: '0', step: 'any', value: String(start), inputmode: 'decimal', oninput: () => this.draw() });
    this.edges = el('input', { id: 'show-edges', type: 'checkbox', onchange: () => this.draw() });
    this.rangeMode = el('select', { id: 'range-mode', onchange: () => this.onRangeInputs(false) },
      el('option', { value: 'step' }, 'this step'),
      el('option', { value: 'run' }, 'whole run'),
      el('option', { value: 'manual' }, 'fixed'));
    this.lo = el('input', { id: 'range-lo', type: 'number', step: 'any', 'aria-label': 'colour range minimum', oninput: () => this.draw() });
    this.hi = el('input', { id: 'range-hi', type: 'number', step: 'any', 'aria-label': 'colour range maximum', oninput: () => this.draw() });
    this.canvas = el('canvas', { id: 'mesh-canvas', role: 'img', 'aria-label': 'deformed mesh coloured by the selected field; wheel or the buttons zoom, drag pans' });
    this.probeBox = el('div', { id: 'probe', class: 'probe', 'aria-live': 'off', hidden: true });
    const viewButtons = el('span', { class: 'view-buttons', role: 'group', 'aria-label': 'view' },
      el('button', { id: 'zoom-out', type: 'button', class: 'small', title: 'zoom out', 'aria-label': 'zoom out', onclick: () => this.zoomBy(1 / 1.5) }, '−'),
      el('button', { id: 'zoom-in', type: 'button', class: 'small', title: 'zoom in', 'aria-label': 'zoom in', onclick: () => this.zoomBy(1.5) }, '+'),
      el('button', { id: 'view-reset', type: 'button', class: 'small', title: this.d3 ? 'show the whole body from the initial direction (Home on the picture)' : 'show the whole body', onclick: () => this.resetView() }, 'Reset view'),
      // 3D: the initial view is from above; Γ3 (often the bottom) is one click away.
      this.d3?.hasContact
        ? el('button', { id: 'view-contact', type: 'button', class: 'small', title: 'look at the contact boundary Γ3 (stick and slip) from outside the body', onclick: () => this.d3.viewContact() }, 'View Γ3')
        : null);
    // 3D only: faces coloured by the kind of their boundary part; the slip direction.
    this.partsBox = el('input', { id: 'show-parts', type: 'checkbox', onchange: () => this.draw() });
    this.arrowsBox = el('input', { id: 'show-arrows', type: 'checkbox', checked: true, onchange: () => this.draw() });
    this.cbLo = el('span', { class: 'cb-lo' });
    this.cbHi = el('span', { class: 'cb-hi' });
    this.cbLabel = el('span', { class: 'cb-label' });
    this.cbTicks = el('div', { class: 'cb-ticks', 'aria-hidden': 'true' });
    this.contactInfo = el('span', { class: 'contact-info' });
    this.slider = el('input', {
      id: 'step-slider', type: 'range', min: '0', max: String(this.steps.length - 1), step: '1', value: '0',
      'aria-label': 'stored step', oninput: () => this.show(Number(this.slider.value)),
    });
    this.playBtn = el('button', { id: 'play', type: 'button', class: 'small', onclick: () => (this.playing ? this.stop() : this.play()) }, '▶ Play');
    this.stepLabel = el('span', { id: 'step-label', 'aria-live': 'off' });
    this.vtuLink = api.keyedLink(el('a', { id: 'dl-vtu', download: '' }, 'VTU (this step)'));
    // ParaView needs the collection and its VTU files side by side: the archive has both,
    // with the PVD naming the files by relative paths, so it opens offline.
    this.archiveLink = api.keyedLink(el('a', {
      id: 'dl-paraview', href: `/jobs/${id}/archive.tar`, download: `contact-sim-${id.slice(0, 8)}.tar`,
      title: 'a folder with result.pvd and every stored step as VTU: extract it and open result.pvd in ParaView',
    }, 'ParaView (PVD + VTU, .tar)'));
    this.sizes = new Map(); // step -> bytes of its VTU
    this.estimateArchive();
    const plots = el('div', { class: 'plots', id: 'plots' });
    this.gammaPlots = el('div', { class: 'plots', id: 'gamma3-plots' });
    this.gammaNote = el('p', { class: 'hint', id: 'gamma3-note' });
    const picture = this.d3 ? this.d3.element : el('div', { class: 'canvas-wrap' }, this.canvas, this.probeBox);

    const info = this.runInfo(summary, this.mesh);
    const warnings = (summary.warnings || []).map((w) => el('p', { class: 'warning' }, w));
    // The (2h, 2k) error bar, when the scene asked for one ("error_estimate": true).
    const est = summary.error_estimate?.final;
    const pct = (x) => (x === null || x === undefined ? '–' : `${(100 * x).toPrecision(2)} %`);
    const estimate = est
      ? el('p', { class: est.flagged ? 'warning' : 'run-info', id: 'error-estimate' },
        `Estimated error at T (from a run at 2h, 2k): w ${pct(est.w)}, ζ ${pct(est.zeta)}`,
        est.observed_order_w != null ? ` · observed order ${Number(est.observed_order_w).toFixed(2)}` : '',
        est.flagged ? ' · flagged: the runs disagree more than a first-order model allows' : '')
      : null;

    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, job.scene || 'simulation', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          this.vtuLink,
          this.archiveLink,
          this.summaryLink(id),
          el('button', { id: 'export-png', type: 'button', class: 'small', title: 'the picture with its colour bar, as a PNG file', onclick: () => this.exportPng() }, 'PNG of the view'),
          this.continueButton(job, summary))),
      info,
      ...this.continuation(job, summary),
      ...(estimate ? [estimate] : []),
      ...warnings,
      el('div', { class: 'toolbar' },
        el('label', {}, 'Colour by ', this.quantity),
        el('label', {}, 'Magnify u × ', this.factor),
        el('button', { type: 'button', class: 'small', title: 'largest displacement = 10% of the body', onclick: () => this.autoFactor() }, 'auto'),
        el('label', {}, 'Range ', this.rangeMode),
        el('span', { class: 'range-inputs' }, this.lo, '–', this.hi),
        el('label', {}, this.edges, ' mesh lines'),
        this.d3 ? el('label', {}, this.partsBox, ' faces by boundary part') : null,
        this.d3 ? el('label', {}, this.arrowsBox, ' slip direction') : null,
        viewButtons),
      picture,
      el('div', { class: 'colorbar', id: 'colorbar' },
        this.cbLo, el('div', { class: 'cb-scale' }, el('div', { class: 'bar', style: `background: ${cssGradient()}` }), this.cbTicks), this.cbHi, this.cbLabel),
      this.boundaryLegend(),
      el('div', { class: 'legend' },
        'Γ3 contact: ', el('span', { class: 'swatch', style: `background:${STICK}` }), ' stick ',
        el('span', { class: 'swatch', style: `background:${SLIP}` }), ' slip ', this.contactInfo,
        el('span', { class: 'hint' }, this.d3
          ? ' · lines from slipping nodes: tangential velocity · grey: edges of the reference configuration · "View Γ3" looks at the contact face · drag orbits, right drag pans, wheel zooms; on the focused picture the arrow keys orbit, Shift + arrows pan, + − zoom, Home resets'
          : ' · dashed: reference configuration')),
      el('div', { class: 'time' }, this.playBtn, this.slider, this.stepLabel),
      el('h3', { class: 'plots-title' }, 'Norms over time ', el('span', { class: 'hint' }, '(click to show that time)')),
      plots,
      el('h3', { class: 'plots-title' }, 'Along Γ3 at the shown step'),
      this.gammaNote,
      this.gammaPlots,
    );
    this.onRangeInputs(false);

    // Norms over time, with a marker at the displayed step.
    this.plots = this.normPlots(plots, summary, (t) => this.seek(t));

    // Redraw at the new size when the layout changes (window resize, narrow screens). The
    // wrapper's width is watched, not the canvas, whose height draw() itself sets.
    let width = 0;
    this.resizeObserver = new ResizeObserver(([entry]) => {
      if (entry.contentRect.width === width) return;
      width = entry.contentRect.width;
      this.draw();
    });
    this.resizeObserver.observe(picture);
    if (!this.d3) this.bindPointer();
  }

  /** A quantity's label; in 3D von Mises is per tetrahedron. */
  label(q) {
    return this.d3 ? q.label.replace('(per triangle)', '(per tetrahedron)') : q.label;
  }

  /** The boundary's colours, for the kinds this mesh has. */
  boundaryLegend() {
    const present = this.d3
      ? this.d3.kindsPresent()
      : new Set(this.mesh.boundary_edges.map(([, part]) => edgeKind(this.kinds, part)));
    const order = ['clamped', 'traction', 'contact', 'free', 'other'].filter((k) => present.has(k));
    // In 3D the kinds colour faces (with "faces by boundary part"): square swatches.
    const swatch = (k) => (this.d3
      ? el('span', { class: 'face-swatch', style: `background:${KINDS[k].colour}` })
      : el('span', { class: 'line-swatch', style: `background:${KINDS[k].colour}; height:${KINDS[k].width}px` }));
    // A space between the (unbreakable) entries lets the line wrap there.
    return el('div', { class: 'legend', id: 'boundary-legend' }, 'Boundary: ',
      order.flatMap((k) => [el('span', { class: 'kind', dataset: { kind: k } }, swatch(k), ` ${KINDS[k].label}`), ' ']));
  }

  // ---- zoom, pan and the value under the pointer --------------------------------------

  bindPointer() {
    const c = this.canvas;
    const at = (ev) => {
      // The drawing's origin is the canvas's content box, inside its border.
      const r = c.getBoundingClientRect();
      return [ev.clientX - r.left - c.clientLeft, ev.clientY - r.top - c.clientTop];
    };
    c.addEventListener('wheel', (ev) => {
      ev.preventDefault();
      // Lines (mouse wheels) and pixels (touchpads) alike: ~1.2× per wheel notch.
      const dy = ev.deltaMode === 1 ? ev.deltaY * 33 : ev.deltaMode === 2 ? ev.deltaY * 400 : ev.deltaY;
      this.zoomBy(Math.exp(-dy * 0.0018), ...at(ev));
    }, { passive: false });
    let drag = null;
    c.addEventListener('pointerdown', (ev) => {
      if (ev.button !== 0) return;
      drag = { id: ev.pointerId, x: ev.clientX, y: ev.clientY, moved: false };
      c.setPointerCapture(ev.pointerId);
    });
    c.addEventListener('pointermove', (ev) => {
      if (drag && drag.id === ev.pointerId) {
        const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
        if (!drag.moved && Math.hypot(dx, dy) < 3) return;
        drag.moved = true;
        drag.x = ev.clientX;
        drag.y = ev.clientY;
        const s = this.transform()?.s || 1;
        this.view.panX -= dx / s;
        this.view.panY += dy / s;
        c.classList.add('panning');
        this.showProbe(null);
        this.scheduleDraw();
        return;
      }
      this.pointer = at(ev);
      this.showProbe(this.pointer);
    });
    const end = (ev) => {
      if (drag && drag.id === ev.pointerId) drag = null;
      c.classList.remove('panning');
    };
    c.addEventListener('pointerup', end);
    c.addEventListener('pointercancel', end);
    c.addEventListener('pointerleave', () => {
      this.pointer = null;
      this.showProbe(null);
    });
    c.addEventListener('dblclick', () => this.resetView());
  }

  /** Zooms by `factor` about CSS point (x, y) of the canvas (default: its centre). */
  zoomBy(factor, x, y) {
    if (this.d3) return this.d3.zoomBy(factor);
    const t = this.transform();
    if (!t) return;
    const zoom = Math.min(ZOOM_MAX, Math.max(ZOOM_MIN, this.view.zoom * factor));
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    x ??= w / 2;
    y ??= h / 2;
    // Keep the world point under (x, y) where it is.
    const wx = (x - t.ox) / t.s, wy = (t.oy - y) / t.s;
    const { fit } = this.frame;
    const s = fit.s0 * zoom;
    this.view = { zoom, panX: wx - (x - w / 2) / s - fit.cx, panY: wy + (y - h / 2) / s - fit.cy };
    this.scheduleDraw();
  }

  /**
   * World → CSS pixels for the current view (which may be ahead of the last drawn frame
   * while a redraw is pending): X = ox + s x, Y = oy − s y.
   */
  transform() {
    if (!this.frame) return null;
    const { fit } = this.frame;
    const s = fit.s0 * this.view.zoom;
    return {
      s,
      ox: this.canvas.clientWidth / 2 - s * (fit.cx + this.view.panX),
      oy: this.canvas.clientHeight / 2 + s * (fit.cy + this.view.panY),
    };
  }

  resetView() {
    if (this.d3) return this.d3.resetView();
    this.view = { zoom: 1, panX: 0, panY: 0 };
    this.draw();
  }

  /** Redraws at the next frame (many wheel or drag events make one redraw). */
  scheduleDraw() {
    cancelAnimationFrame(this.pending);
    this.pending = requestAnimationFrame(() => this.draw());
  }

  /** The value of the shown field at CSS point p of the canvas, in the readout. */
  showProbe(p) {
    const box = this.probeBox;
    const hit = p && this.frame ? probe(this.frame, this.mesh.triangles, p[0], p[1]) : null;
    const vals = hit ? this.values() : null;
    if (!hit) {
      box.hidden = true;
      box.textContent = '';
      delete box.dataset.value;
      return;
    }
    const [a, b, c] = this.mesh.triangles[hit.triangle];
    const [wa, wb, wc] = hit.weights;
    const N = this.mesh.nodes;
    const x = wa * N[a][0] + wb * N[b][0] + wc * N[c][0];
    const y = wa * N[a][1] + wb * N[b][1] + wc * N[c][1];
    const q = QUANTITIES[this.quantity.value];
    let value = null;
    if (vals) value = vals.perCell ? vals.v[hit.triangle] : wa * vals.v[a] + wb * vals.v[b] + wc * vals.v[c];
    box.hidden = false;
    box.dataset.value = value === null ? '' : String(value);
    box.dataset.triangle = String(hit.triangle);
    box.replaceChildren(
      el('span', { class: 'probe-value' }, `${q.label.replace(/ \(per triangle\)$/, '')} = ${value === null ? 'not stored' : fmt(value)}`),
      el('span', { class: 'probe-where' }, `at (${fmt(x, 3)}, ${fmt(y, 3)})${vals?.perCell ? ` · triangle ${hit.triangle}` : ''}`),
    );
  }

  /** Shows stored step number `idx` (index into this.steps), fetching it if needed. */
  async show(idx) {
    const entry = this.steps[idx];
    if (!entry) return;
    const token = ++this.token;
    let doc = this.cache.get(entry.n);
    if (!doc) {
      this.stepLabel.textContent = `step ${entry.n} · loading…`;
      try {
        doc = await api.fields(this.job.id, entry.n, false);
      } catch (e) {
        if (token === this.token) this.stepLabel.textContent = `step ${entry.n}: ${e.message}`;
        return;
      }
      this.remember(doc);
    }
    if (token !== this.token) return; // the slider moved on meanwhile
    this.showLoaded(idx, doc);
  }

  remember(doc) {
    if (this.cache.size >= CACHE_STEPS) this.cache.delete(this.cache.keys().next().value);
    this.cache.set(doc.n, doc);
  }

  showLoaded(idx, doc) {
    this.current = doc;
    this.root.dataset.step = String(doc.n);
    this.stepLabel.textContent = `step ${doc.n} of ${this.summary.time?.steps ?? '?'} · t = ${fmt(doc.t)}`;
    this.vtuLink.href = `/jobs/${this.job.id}/fields/${doc.n}.vtu`;
    this.vtuLink.download = `contact-sim-${this.job.id.slice(0, 8)}-step-${doc.n}.vtu`;
    this.vtuSize(doc.n);
    this.slider.setAttribute('aria-valuetext', `step ${doc.n}, t = ${fmt(doc.t)}`);
    for (const p of this.plots) p.setMarker(doc.t);
    this.drawGamma3();
    this.draw();
  }

  /** The size in bytes of step n's VTU (one HEAD request per step), or null. */
  vtuBytes(n) {
    if (!this.sizes.has(n)) this.sizes.set(n, api.contentLength(`/jobs/${this.job.id}/fields/${n}.vtu`));
    return this.sizes.get(n);
  }

  /**
   * Says the size of the shown step's VTU in its link; not while playing (every frame would
   * ask): the link says it when the playback stops.
   */
  async vtuSize(n) {
    const link = this.vtuLink;
    const job = this.job;
    link.textContent = 'VTU (this step)';
    delete link.dataset.bytes;
    if (this.playing && !this.sizes.has(n)) return;
    const bytes = await this.vtuBytes(n);
    if (bytes === null || this.job !== job || this.current?.n !== n) return;
    link.textContent = `VTU (this step, ${fmtBytes(bytes)})`;
    link.dataset.bytes = String(bytes);
  }

  /**
   * Says about how large the ParaView archive is: the server streams it (no length), so it
   * is estimated from the VTU sizes of the first and the last stored step (every step stores
   * the same arrays; the initial state may store fewer) and the tar framing.
   */
  async estimateArchive() {
    const job = this.job;
    const steps = this.steps;
    const first = steps[0].n, last = steps[steps.length - 1].n;
    const [a, b, summary] = await Promise.all([this.vtuBytes(first), this.vtuBytes(last), api.contentLength(`/jobs/${job.id}/summary`)]);
    if (a === null || b === null || this.job !== job) return;
    // A tar member is a 512-byte header and its data padded to 512 bytes.
    const member = (bytes) => 512 + Math.ceil(bytes / 512) * 512;
    const vtus = steps.length > 1 ? member(a) + (steps.length - 1) * member(b) : member(b);
    // scene.json (a few kB), summary.json, result.pvd (one line per step) and the end blocks.
    const total = vtus + member(2048) + member(summary ?? 0) + member(100 + 90 * steps.length) + 1024;
    this.archiveLink.textContent = `ParaView (PVD + VTU, .tar, about ${fmtBytes(total)})`;
    this.archiveLink.dataset.bytes = String(total);
  }

  /** Shows the stored step nearest to time t (a click on a norm plot). */
  seek(t) {
    let best = 0;
    this.steps.forEach((s, i) => {
      if (Math.abs(s.t - t) < Math.abs(this.steps[best].t - t)) best = i;
    });
    this.stop();
    this.slider.value = String(best);
    this.show(best);
  }

  /**
   * Slip velocity and friction traction of the contact nodes at the shown step, against
   * their position along Γ3 (the coordinate in which the contact nodes spread most).
   */
  drawGamma3() {
    const c = this.current.contact;
    this.gammaPlots.replaceChildren();
    if (!c || !c.length) {
      this.gammaNote.textContent = c ? 'No contact nodes.' : 'The contact state is not stored at this step.';
      return;
    }
    const d = this.dim;
    const N = this.mesh.nodes;
    const names = ['x', 'y', 'z'];
    let axis = 0, spread = -1;
    const spreads = [];
    for (let a = 0; a < d; a++) {
      const vs = c.map((e) => N[e.node][a]);
      spreads[a] = Math.max(...vs) - Math.min(...vs);
      if (spreads[a] > spread) [axis, spread] = [a, spreads[a]];
    }
    // In 3D the axis the slices are cut along is the user's choice (the face's longest by
    // default): a stick–slip transition shows along the axis it runs across.
    if (d === 3 && c.length > BIN_ABOVE) {
      if (this.gammaAxis !== undefined && spreads[this.gammaAxis] > 0) axis = this.gammaAxis;
      const pick = el('select', { id: 'gamma3-axis', 'aria-label': 'slices along' },
        ...names.filter((_, a) => spreads[a] > 0).map((n) => el('option', { value: String(names.indexOf(n)) }, `along ${n}`)));
      pick.value = String(axis);
      pick.addEventListener('change', () => {
        this.gammaAxis = Number(pick.value);
        this.drawGamma3();
      });
      this.gammaPlots.append(el('div', { class: 'gamma3-axis' }, pick));
    }
    const sorted = c.slice().sort((p, q) => N[p.node][axis] - N[q.node][axis]);
    const slipping = c.filter((e) => e.slipping).length;
    const plot = (id, title, key, colour, series) => linePlot(this.gammaPlots, {
      xLabel: names[axis], fromZero: false, id, title, colour, ...series(key),
    });
    if (d === 3 && c.length > BIN_ABOVE) {
      // A contact face's nodes spread over a surface: by position along the axis they form a
      // cloud, so each of BINS slices shows its mean (the line) and its range (the band).
      const lo = N[sorted[0].node][axis], hi = N[sorted[sorted.length - 1].node][axis];
      const nb = Math.min(BINS, Math.max(8, Math.round(Math.sqrt(c.length))));
      const bins = Array.from({ length: nb }, () => []);
      for (const e of sorted) bins[Math.min(nb - 1, Math.floor(((N[e.node][axis] - lo) / (hi - lo || 1)) * nb))].push(e);
      const full = bins.filter((b) => b.length);
      const mean = (xs) => xs.reduce((a, b) => a + b, 0) / xs.length;
      const series = (key) => ({
        xs: full.map((b) => mean(b.map((e) => N[e.node][axis]))),
        ys: full.map((b) => mean(b.map((e) => e[key]))),
        band: { lo: full.map((b) => Math.min(...b.map((e) => e[key]))), hi: full.map((b) => Math.max(...b.map((e) => e[key]))) },
      });
      this.gammaNote.textContent = `${c.length} contact nodes in ${full.length} slices along ${names[axis]}: the line is each slice's mean, the band its range; ${slipping} slip.`;
      plot('plot-slip', 'slip velocity w_τ', 'slip_velocity', SLIP, series);
      plot('plot-friction', 'friction traction', 'friction_traction', '#5f3dc4', series);
      for (const s of this.gammaPlots.querySelectorAll('svg.plot')) s.dataset.nodes = String(c.length);
      return;
    }
    const xs = sorted.map((e) => N[e.node][axis]);
    this.gammaNote.textContent = `${c.length} contact nodes by ${names[axis]}${d === 3 ? ' (each node a dot)' : ''}; ${slipping} slip.`;
    const series = (key) => ({ xs, ys: sorted.map((e) => e[key]), dots: d === 3 });
    plot('plot-slip', 'slip velocity w_τ', 'slip_velocity', SLIP, series);
    plot('plot-friction', 'friction traction', 'friction_traction', '#5f3dc4', series);
    for (const s of this.gammaPlots.querySelectorAll('svg.plot')) s.dataset.nodes = String(c.length);
  }

  /** Values of the selected quantity for the current step, and whether per triangle. */
  values() {
    const q = QUANTITIES[this.quantity.value];
    const d = this.current;
    if (q.key === 'w') {
      if (!d.w) return null;
      if (this.dim === 3) {
        const n = d.w.length / 3;
        const v = new Float64Array(n);
        for (let i = 0; i < n; i++) v[i] = Math.hypot(d.w[3 * i], d.w[3 * i + 1], d.w[3 * i + 2]);
        return { v, perCell: false };
      }
      const n = d.w.length / 2;
      const v = new Float64Array(n);
      for (let i = 0; i < n; i++) v[i] = Math.hypot(d.w[2 * i], d.w[2 * i + 1]);
      return { v, perCell: false };
    }
    return d[q.key] ? { v: d[q.key], perCell: q.perCell } : null;
  }

  /**
   * The extremes of the selected quantity over every stored step ("whole run"): null until
   * they are known; the first call fetches the steps (that quantity only) in the background
   * and redraws when done.
   */
  runRange() {
    const key = this.quantity.value;
    this.runRanges ??= new Map();
    const known = this.runRanges.get(key);
    if (known && !known.loading) return known;
    if (known) return null;
    // A long run is sampled (evenly, first and last included): RUN_RANGE_STEPS requests at
    // most, and the colour bar says so.
    const all = this.steps;
    const every = Math.max(1, Math.ceil((all.length - 1) / (RUN_RANGE_STEPS - 1)));
    const picked = all.filter((_, i) => i % every === 0 || i === all.length - 1);
    const entry = { loading: true, min: Infinity, max: -Infinity, sampled: picked.length < all.length ? `${picked.length} of ${all.length} steps` : null };
    this.runRanges.set(key, entry);
    const job = this.job;
    const q = QUANTITIES[key];
    const field = q.key;
    (async () => {
      for (const s of picked) {
        if (this.job !== job) return;
        const cached = this.cache.get(s.n);
        const doc = cached || (await api.fields(job.id, s.n, false, [field]));
        let v = doc[field];
        if (!v) continue;
        if (field === 'w') {
          const d = this.dim, n = v.length / d, m = new Float64Array(n);
          for (let i = 0; i < n; i++) m[i] = Math.hypot(v[d * i], v[d * i + 1], d === 3 ? v[d * i + 2] : 0);
          v = m;
        }
        for (const x of v) if (Number.isFinite(x)) { if (x < entry.min) entry.min = x; if (x > entry.max) entry.max = x; }
      }
      entry.loading = false;
      if (this.job === job) this.draw();
    })().catch(() => {
      this.runRanges.delete(key);
    });
    return null;
  }

  /** The range inputs are editable only in "fixed" mode; switching fills them with the current range. */
  onRangeInputs(quantityChanged) {
    // A fixed range of one quantity means nothing for another: back to automatic (the
    // whole run stays the whole run).
    if (quantityChanged && this.rangeMode.value === 'manual') this.rangeMode.value = 'step';
    this.lo.disabled = this.hi.disabled = this.rangeMode.value !== 'manual';
    this.draw();
  }

  draw() {
    if ((!this.canvas && !this.d3) || !this.current || !this.mesh) return;
    const vals = this.values();
    let min = Infinity, max = -Infinity;
    if (vals) for (const x of vals.v) if (Number.isFinite(x)) { if (x < min) min = x; if (x > max) max = x; }
    let range;
    let source = 'step';
    const mode = this.rangeMode.value;
    if (mode === 'manual' && Number(this.hi.value) > Number(this.lo.value)) {
      range = [Number(this.lo.value), Number(this.hi.value)];
      source = 'manual';
    } else {
      let [lo, hi] = [min, max];
      const run = mode === 'run' && vals ? this.runRange() : null;
      if (run) {
        [lo, hi] = [Math.min(run.min, min), Math.max(run.max, max)];
        source = 'run';
      } else if (mode === 'run') source = 'run-loading';
      range = niceRange(lo, hi);
      if (mode !== 'manual') {
        this.lo.value = String(Number(lo.toPrecision(4)));
        this.hi.value = String(Number(hi.toPrecision(4)));
      }
    }
    this.root.querySelector('#colorbar')?.setAttribute('data-range', source);
    if (this.d3) this.draw3d(vals, range);
    else this.draw2d(vals, range);
    const q = QUANTITIES[this.quantity.value];
    const ends = distinctDigits(range[0], range[1], 4);
    this.cbLo.textContent = fmt(range[0], ends);
    this.cbHi.textContent = fmt(range[1], ends);
    this.range = range;
    const ticks = niceTicks(range[0], range[1], 5);
    const digits = tickDigits(ticks);
    this.cbTicks.replaceChildren(...ticks.map((v) => el('span', {
      class: 'cb-tick', style: `left: ${(100 * (v - range[0])) / (range[1] - range[0])}%`, dataset: { value: String(v) },
    }, fmt(v, digits))));
    this.cbLabel.textContent = vals
      ? `${this.label(q)}: min ${fmt(min)}, max ${fmt(max)}${max - min <= 1e-12 * Math.max(1, Math.abs(max)) ? ' (uniform)' : ''}`
      : `${this.label(q)}: not stored`;
    if (q.key === 'zeta') this.cbLabel.textContent += ' · ζ = 1 is intact material, 0 fully damaged';
    if (source === 'run') {
      const sampled = this.runRanges?.get(this.quantity.value)?.sampled;
      this.cbLabel.textContent += ` · colours span the whole run${sampled ? ` (sampled: ${sampled})` : ''}`;
    }
    else if (source === 'run-loading') this.cbLabel.textContent += ' · reading the whole run…';
    if (this.d3 && this.partsBox.checked) this.cbLabel.textContent += ' · the faces show their boundary part now';
    const c = this.current.contact;
    this.contactInfo.textContent = c ? `(${c.filter((x) => x.slipping).length} of ${c.length} nodes slip)` : '(contact state not stored)';
  }

  /** The 3D picture of the current step (viewer3d.js). */
  draw3d(vals, range) {
    const wrapW = this.d3.element.clientWidth || 600;
    const factor = Number(this.factor.value);
    const q = QUANTITIES[this.quantity.value];
    this.d3.update({
      width: wrapW,
      height: Math.round(Math.min(Math.max(wrapW * 0.62, 240), window.innerHeight * 0.65)),
      disp: this.current.u || null,
      factor: Number.isFinite(factor) && factor >= 0 ? factor : 1,
      values: vals ? vals.v : null,
      perCell: vals ? vals.perCell : false,
      range,
      label: q.label.replace(/ \(per triangle\)$/, ''),
      mode: this.partsBox.checked ? 'parts' : 'field',
      contact: this.current.contact || null,
      showEdges: this.edges.checked,
      showArrows: this.arrowsBox.checked,
    });
  }

  /** The 2D picture of the current step (render.js). */
  draw2d(vals, range) {
    // Height follows the body's aspect ratio (its bounding box, with room for the
    // deformation), within the window.
    const wrapW = this.canvas.parentElement.clientWidth || 600;
    const nodes = this.mesh.nodes;
    const [bx0, by0, bx1, by1] = this.bbox;
    const aspect = (by1 - by0) / (bx1 - bx0 || 1);
    const cssH = Math.round(Math.min(Math.max(wrapW * aspect * 1.25 + 32, 180), window.innerHeight * 0.6));
    if (this.canvas.style.height !== `${cssH}px`) this.canvas.style.height = `${cssH}px`;
    const factor = Number(this.factor.value);
    this.frame = drawField(this.canvas, {
      nodes,
      triangles: this.mesh.triangles,
      boundaryEdges: this.mesh.boundary_edges,
      kinds: this.kinds,
      view: this.view,
      disp: this.current.u || null,
      factor: Number.isFinite(factor) && factor >= 0 ? factor : 1,
      values: vals ? vals.v : new Float64Array(nodes.length),
      perCell: vals ? vals.perCell : false,
      range,
      contact: this.current.contact || null,
      showEdges: this.edges.checked,
    });
    const fr = this.frame;
    // For tests and tools: world → CSS pixels from the canvas's bounding client rectangle
    // (X = ox + s x, Y = oy − s y, in the reference configuration).
    const cv = this.canvas;
    cv.dataset.view = JSON.stringify({ s: fr.s, ox: fr.ox + cv.clientLeft, oy: fr.oy + cv.clientTop, zoom: this.view.zoom });
    this.canvas.style.touchAction = this.view.zoom > 1 ? 'none' : '';
    if (this.pointer) this.showProbe(this.pointer);
  }

  /** A factor that makes the largest displacement 10% of the body's size (1 significant digit). */
  autoFactor() {
    const f = this.suggestedFactor();
    if (f === null) return;
    this.factor.value = String(f);
    this.draw();
  }

  /** autoFactor's factor for the current step; null without a displacement. */
  suggestedFactor() {
    const u = this.current?.u;
    if (!u) return null;
    const d = this.dim;
    let umax = 0;
    for (let i = 0; i < u.length; i += d) umax = Math.max(umax, Math.hypot(u[i], u[i + 1], d === 3 ? u[i + 2] : 0));
    let size;
    if (d === 3) {
      size = this.d3.size;
    } else {
      const [x0, y0, x1, y1] = this.bbox;
      size = Math.max(x1 - x0, y1 - y0);
    }
    if (!(umax > 0)) return null;
    const f = (0.1 * size) / umax;
    const p = 10 ** Math.floor(Math.log10(f));
    return Number((Math.round(f / p) * p).toPrecision(1));
  }

  /**
   * Saves the picture as shown with its colour bar (ticks, the field's name and range) and
   * the step as a PNG file.
   */
  exportPng() {
    const src = this.d3 ? this.d3.canvas : this.canvas;
    if (!src || !src.width) return;
    const dpr = window.devicePixelRatio || 1;
    const W = src.width;
    const barH = Math.round(14 * dpr), pad = Math.round(10 * dpr), font = Math.round(13 * dpr);
    const H = src.height + pad + barH + pad + font + pad + font + pad;
    const out = document.createElement('canvas');
    out.width = W;
    out.height = H;
    const ctx = out.getContext('2d');
    ctx.fillStyle = '#ffffff';
    ctx.fillRect(0, 0, W, H);
    ctx.drawImage(src, 0, 0);
    // The colour bar: one column per map entry, so its colours are the map's own.
    const y0 = src.height + pad;
    const x0 = pad * 4, bw = W - 8 * pad;
    for (let x = 0; x < bw; x++) {
      const i = Math.min(255, Math.floor((256 * x) / bw));
      ctx.fillStyle = `rgb(${LUT[3 * i]},${LUT[3 * i + 1]},${LUT[3 * i + 2]})`;
      ctx.fillRect(x0 + x, y0, 1, barH);
    }
    ctx.fillStyle = '#1d2329';
    ctx.font = `${font}px system-ui, sans-serif`;
    ctx.textBaseline = 'top';
    const [lo, hi] = this.range || [0, 1];
    ctx.textAlign = 'center';
    const ticks = niceTicks(lo, hi, 5);
    const digits = tickDigits(ticks);
    for (const v of ticks) {
      const x = x0 + ((v - lo) / (hi - lo)) * bw;
      ctx.fillRect(Math.round(x), y0 + barH, 1, Math.round(4 * dpr));
      ctx.fillText(fmt(v, digits), x, y0 + barH + pad / 2);
    }
    ctx.textAlign = 'left';
    ctx.fillText(`${this.cbLabel.textContent} · ${this.stepLabel.textContent} · ${this.job.scene || ''} ${this.job.id.slice(0, 8)}`,
      pad, y0 + barH + pad + font + pad / 2, W - 2 * pad);
    out.toBlob((blob) => {
      const url = URL.createObjectURL(blob);
      const a = el('a', { href: url, download: `contact-sim-${this.job.id.slice(0, 8)}-step-${this.current.n}.png` });
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(url), 60_000);
    }, 'image/png');
  }

  async play() {
    if (this.steps.length < 2) return;
    this.playing = true;
    this.playBtn.textContent = '❚❚ Pause';
    // While playing, colours keep their meaning from step to step: the whole run's range.
    if (this.rangeMode.value === 'step') {
      this.rangeMode.value = 'run';
      this.onRangeInputs(false);
    }
    let idx = Number(this.slider.value);
    if (idx >= this.steps.length - 1) idx = -1; // at the end: start over
    while (this.playing && idx < this.steps.length - 1) {
      const t0 = performance.now();
      idx++;
      this.slider.value = String(idx);
      await this.show(idx);
      if (!this.playing) break; // paused, or another job opened, while the step loaded
      // Fetch the next step while this one is on screen.
      const next = this.steps[idx + 1];
      if (next && !this.cache.has(next.n)) api.fields(this.job.id, next.n, false).then((d) => this.remember(d), () => {});
      await new Promise((r) => setTimeout(r, Math.max(0, FRAME_MS - (performance.now() - t0))));
    }
    this.stop();
  }

  stop() {
    const was = this.playing;
    this.playing = false;
    if (this.playBtn) this.playBtn.textContent = '▶ Play';
    if (was && this.current && this.sizes) this.vtuSize(this.current.n);
  }
}
