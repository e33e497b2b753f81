// The picture of a 3D result (a tetrahedral body): its boundary surface deformed by u × a
// factor, coloured by a nodal field (ζ, |w|: interpolated across each triangle), by the
// tetrahedron's value (von Mises: each boundary face shows the cell it belongs to) or by the
// kind of each face's boundary part (the 2D legend's colours); the contact nodes of Γ3 as
// points by stick/slip state, optionally with lines along the tangential velocity of the
// slipping ones; the reference configuration's edges (grey) and, on request, the mesh lines.
// three.js (WebGL, vendored under vendor/three/, named by the page's import map) draws it;
// the mouse orbits (drag), zooms about the pointer (wheel) and pans (right drag, or
// Shift/Ctrl + drag); on the focused picture the arrow keys orbit, Shift + arrows pan,
// + and − zoom and Home (or 0) resets the view. The value under the pointer is shown as in 2D.
//
// viewer.js owns everything around the picture (toolbar, colour bar and range, time slider,
// plots) and calls update() with the step's data; this module only draws. Data (from
// GET /jobs/{id}/fields?mesh=1&surface=1 of a 3D job: the boundary surface only):
//   mesh: {dim: 3, surface: true, nodes: [[x,y,z]] (surface nodes), node_ids: [...],
//          triangles: [[a,b,c]], triangle_parts: [part | null], cells: [tetrahedron],
//          parts: [{type, group?}]}
//   u: [ux0,uy0,uz0, ...] at the surface nodes, von_mises: one per triangle,
//   contact: [{node (surface numbering), slipping, tangential_velocity: [x,y,z], ...}]
// The whole mesh (without surface=1: tetrahedra, boundary_faces: [[[a,b,c], part, cell]],
// element fields per tetrahedron) is drawn the same way.
// Frames are drawn on demand (a change of view or data), not continuously: with software
// WebGL (no GPU) a frame of ~20k boundary triangles takes about 0.1 s.
//
// Without WebGL the picture is replaced by a message; the rest of the view keeps working.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { LUT } from './colormap.js';
import { KINDS, STICK, SLIP, partKinds, edgeKind } from './render.js';
import { el, fmt } from './util.js';

/**
 * Direction from the body's centre to the camera in the initial view (z is up): from the
 * front right and 30° above, so the top, front and right faces show the body's shape.
 */
const VIEW_DIR = new THREE.Vector3(1, -1.6, 1.1).normalize();
const FOV = 30;
/** Orbit step of the arrow keys (radians) and pan step (fraction of the view's height). */
const KEY_ANGLE = Math.PI / 18;
const KEY_PAN = 0.05;
/** Longest velocity line, as a fraction of the body's size. */
const ARROW_LENGTH = 0.12;

const rgb = (hex) => {
  const n = parseInt(hex.slice(1), 16);
  return [(n >> 16) / 255, ((n >> 8) & 255) / 255, (n & 255) / 255];
};

// The surface: colour-map lookup per fragment (values interpolated like the 2D renderer's,
// then quantised to the same 256 entries) or the part's colour, shaded by a head light
// (face-on: the exact map colour) with flat normals from screen-space derivatives, so the
// deformed positions are the only geometry to update. No colour management: the map's sRGB
// bytes are written as they are.
const SURFACE_VERTEX = `
attribute float value;
attribute vec3 partColour;
varying float vValue;
varying vec3 vPart;
varying vec3 vViewPos;
void main() {
  vValue = value;
  vPart = partColour;
  vec4 mv = modelViewMatrix * vec4(position, 1.0);
  vViewPos = mv.xyz;
  gl_Position = projectionMatrix * mv;
}`;
const SURFACE_FRAGMENT = `
uniform sampler2D lut;
uniform float lo;
uniform float hi;
uniform int mode;
varying float vValue;
varying vec3 vPart;
varying vec3 vViewPos;
void main() {
  vec3 n = normalize(cross(dFdx(vViewPos), dFdy(vViewPos)));
  float shade = 0.55 + 0.45 * abs(dot(n, normalize(-vViewPos)));
  vec3 base;
  if (mode == 1) {
    base = vPart;
  } else {
    float k = clamp(floor((vValue - lo) / (hi - lo) * 255.0 + 0.5), 0.0, 255.0);
    base = texture2D(lut, vec2((k + 0.5) / 256.0, 0.5)).rgb;
  }
  gl_FragColor = vec4(base * shade, 1.0);
}`;
// Round points with a dark rim, a fixed size in pixels.
const POINT_VERTEX = `
attribute vec3 rgb;
uniform float size;
varying vec3 vRgb;
void main() {
  vRgb = rgb;
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
  gl_PointSize = size;
}`;
const POINT_FRAGMENT = `
varying vec3 vRgb;
void main() {
  vec2 p = gl_PointCoord * 2.0 - 1.0;
  float r = dot(p, p);
  if (r > 1.0) discard;
  gl_FragColor = vec4(r > 0.5 ? vRgb * 0.5 : vRgb, 1.0);
}`;
// Plain lines in one colour (no colour management either).
const LINE_VERTEX = `
void main() { gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }`;
const LINE_FRAGMENT = `
uniform vec4 colour;
void main() { gl_FragColor = colour; }`;

function lineMaterial(hex, alpha) {
  return new THREE.ShaderMaterial({
    vertexShader: LINE_VERTEX,
    fragmentShader: LINE_FRAGMENT,
    uniforms: { colour: { value: new THREE.Vector4(...rgb(hex), alpha) } },
    transparent: alpha < 1,
    depthWrite: alpha >= 1,
  });
}

/** The colour map as a 256 × 1 texture. */
function lutTexture() {
  const data = new Uint8Array(256 * 4);
  for (let i = 0; i < 256; i++) {
    data.set([LUT[3 * i], LUT[3 * i + 1], LUT[3 * i + 2], 255], 4 * i);
  }
  const t = new THREE.DataTexture(data, 256, 1, THREE.RGBAFormat, THREE.UnsignedByteType);
  t.magFilter = t.minFilter = THREE.NearestFilter;
  t.needsUpdate = true;
  return t;
}

/** Every edge of the faces once, as a flat [a0, b0, a1, b1, ...]. */
function uniqueEdges(faces) {
  const seen = new Set();
  const out = [];
  for (const [t] of faces) {
    for (let j = 0; j < 3; j++) {
      const a = t[j], b = t[(j + 1) % 3];
      const lo = a < b ? a : b, hi = a < b ? b : a;
      const key = lo * 4294967296 + hi;
      if (seen.has(key)) continue;
      seen.add(key);
      out.push(lo, hi);
    }
  }
  return Int32Array.from(out);
}

export class View3D {
  /**
   * Builds the picture of `mesh` (the fields document's mesh, dim 3). `element` is what the
   * viewer puts on the page: the canvas with its readout, or the message that WebGL is
   * missing (then `ok` is false and update() only remembers its data).
   */
  constructor(mesh) {
    this.mesh = mesh;
    // [triangle, part, index of its value among the element fields]: on the surface form
    // the element fields have one value per triangle, on the whole mesh one per tetrahedron.
    this.faces = mesh.surface
      ? mesh.triangles.map((t, f) => [t, mesh.triangle_parts[f], f])
      : mesh.boundary_faces || [];
    this.kinds = partKinds(mesh);
    this.frames = 0;
    // The reference configuration's extent; `size` is its largest side.
    this.box = new THREE.Box3();
    const v = new THREE.Vector3();
    for (const p of mesh.nodes) this.box.expandByPoint(v.set(p[0], p[1], p[2]));
    this.size = Math.max(...this.box.getSize(v).toArray()) || 1;
    this.canvas = el('canvas', {
      id: 'mesh-canvas-3d', tabindex: '0', role: 'img',
      'aria-label': 'deformed body (3D) coloured by the selected field; drag or the arrow keys orbit, '
        + 'wheel or + and − zoom, right drag or Shift + arrows pan, Home resets the view',
    });
    this.probeBox = el('div', { id: 'probe', class: 'probe', 'aria-live': 'off', hidden: true });
    this.message = el('p', { class: 'webgl-lost', hidden: true, role: 'alert' }, 'The graphics context was lost; the picture comes back when the browser restores it.');
    this.element = el('div', { class: 'canvas-wrap canvas-3d' }, this.canvas, this.probeBox, this.message);
    try {
      // Throws when the browser gives no WebGL 2 context.
      this.renderer = new THREE.WebGLRenderer({
        canvas: this.canvas, antialias: true, alpha: true,
        // The last frame stays readable: "save image" and the tests read its pixels.
        preserveDrawingBuffer: true,
      });
    } catch (e) {
      this.ok = false;
      this.element = el('div', { class: 'canvas-wrap canvas-3d' },
        el('p', { class: 'error webgl-missing', id: 'webgl-missing', role: 'alert' },
          'This browser cannot draw the 3D view: WebGL is not available (it may be turned off, or the graphics driver blocked). ',
          'The time slider, the plots and the downloads still work; the VTU and PVD files open in ParaView.'),
        el('span', { class: 'hint' }, `(${e.message})`));
      return;
    }
    this.ok = true;
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0x000000, 0);
    this.canvas.addEventListener('webglcontextlost', (ev) => {
      ev.preventDefault();
      this.message.hidden = false;
    });
    this.canvas.addEventListener('webglcontextrestored', () => {
      this.message.hidden = true;
      this.requestRender();
    });
    this.buildScene();
    this.bindInput();
  }

  buildScene() {
    const { nodes } = this.mesh;
    const faces = this.faces;
    const F = faces.length;

    // The surface: three vertices per face (a face's value may be its cell's).
    this.faceNodes = new Int32Array(3 * F);
    const partColour = new Float32Array(9 * F);
    const present = new Set();
    faces.forEach(([tri, part], f) => {
      const kind = edgeKind(this.kinds, part);
      present.add(kind);
      const c = rgb(KINDS[kind].colour);
      for (let j = 0; j < 3; j++) {
        this.faceNodes[3 * f + j] = tri[j];
        partColour.set(c, 9 * f + 3 * j);
      }
    });
    this.presentKinds = present;
    const g = new THREE.BufferGeometry();
    this.positions = new THREE.BufferAttribute(new Float32Array(9 * F), 3).setUsage(THREE.DynamicDrawUsage);
    this.values = new THREE.BufferAttribute(new Float32Array(3 * F), 1).setUsage(THREE.DynamicDrawUsage);
    g.setAttribute('position', this.positions);
    g.setAttribute('value', this.values);
    g.setAttribute('partColour', new THREE.BufferAttribute(partColour, 3));
    this.lut = lutTexture();
    this.surfaceMaterial = new THREE.ShaderMaterial({
      vertexShader: SURFACE_VERTEX,
      fragmentShader: SURFACE_FRAGMENT,
      uniforms: { lut: { value: this.lut }, lo: { value: 0 }, hi: { value: 1 }, mode: { value: 0 } },
      side: THREE.DoubleSide,
      // Lines and points on the surface are drawn in front of it.
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
    });
    this.surface = new THREE.Mesh(g, this.surfaceMaterial);

    // The mesh lines (boundary triangles' edges), deformed with the surface.
    this.edgeList = uniqueEdges(faces);
    const eg = new THREE.BufferGeometry();
    this.edgePositions = new THREE.BufferAttribute(new Float32Array(3 * this.edgeList.length), 3).setUsage(THREE.DynamicDrawUsage);
    eg.setAttribute('position', this.edgePositions);
    this.edgeLines = new THREE.LineSegments(eg, lineMaterial('#000000', 0.25));
    this.edgeLines.visible = false;

    // The reference configuration: its feature edges (where the surface bends by > 25°).
    const rg = new THREE.BufferGeometry();
    rg.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(nodes.flat()), 3));
    rg.setIndex(faces.flatMap(([t]) => t));
    const feature = new THREE.EdgesGeometry(rg, 25);
    rg.dispose();
    this.reference = new THREE.LineSegments(feature, lineMaterial('#5c6670', 0.55));

    // Contact nodes and the velocity lines of the slipping ones (filled by update()).
    this.pointMaterial = new THREE.ShaderMaterial({
      vertexShader: POINT_VERTEX,
      fragmentShader: POINT_FRAGMENT,
      uniforms: { size: { value: 7 * this.renderer.getPixelRatio() } },
    });
    this.points = new THREE.Points(new THREE.BufferGeometry(), this.pointMaterial);
    this.arrows = new THREE.LineSegments(new THREE.BufferGeometry(), lineMaterial(SLIP, 1));
    this.nodeNormals = this.boundaryNormals();
    // The initial view looks from above; "Contact face" looks at Γ3 (where stick and slip
    // are shown) from outside, along its mean outward normal: from below when it faces down.
    const down = new THREE.Vector3();
    const a = new THREE.Vector3(), b = new THREE.Vector3(), c = new THREE.Vector3();
    const contactNodes = new Set();
    let area = 0;
    for (const [tri, part] of faces) {
      if (edgeKind(this.kinds, part) !== 'contact') continue;
      a.fromArray(nodes[tri[0]]);
      b.fromArray(nodes[tri[1]]).sub(a).cross(c.fromArray(nodes[tri[2]]).sub(a));
      down.add(b);
      area += b.length() / 2;
      for (const q of tri) contactNodes.add(q);
    }
    // The typical distance between contact nodes (the square root of Γ3's area per node).
    this.contactSpacing = contactNodes.size ? Math.sqrt(area / contactNodes.size) : this.size / 20;
    this.viewDir = VIEW_DIR.clone();
    this.contactDir = null;
    if (down.lengthSq() > 0) {
      const n = down.normalize();
      // Γ3 seen obliquely, as the initial view sees the top: the initial direction mirrored
      // when Γ3 faces down, else between its normal and the initial direction.
      if (n.z < -0.5) this.contactDir = new THREE.Vector3(VIEW_DIR.x, VIEW_DIR.y, -VIEW_DIR.z);
      else if (n.z > 0.5) this.contactDir = VIEW_DIR.clone();
      else this.contactDir = n.clone().multiplyScalar(1.5).add(VIEW_DIR).normalize();
    }

    this.scene = new THREE.Scene();
    this.scene.add(this.surface, this.edgeLines, this.reference, this.points, this.arrows);
    this.camera = new THREE.PerspectiveCamera(FOV, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.zoomToCursor = true;
    this.controls.minDistance = 0.05 * this.size;
    this.controls.maxDistance = 50 * this.size;
    this.controls.addEventListener('change', () => this.requestRender());
    this.camera.near = this.size / 200;
    this.camera.far = this.size * 200;
  }

  /** Outward unit normals at the boundary's nodes (the mean of their faces'), reference configuration. */
  boundaryNormals() {
    const N = this.mesh.nodes;
    const normals = new Map();
    const a = new THREE.Vector3(), b = new THREE.Vector3(), c = new THREE.Vector3();
    for (const [[i, j, k]] of this.faces) {
      a.fromArray(N[i]);
      b.fromArray(N[j]).sub(a);
      c.fromArray(N[k]).sub(a);
      const n = b.cross(c); // area-weighted
      for (const node of [i, j, k]) {
        if (!normals.has(node)) normals.set(node, new THREE.Vector3());
        normals.get(node).add(n);
      }
    }
    for (const n of normals.values()) n.normalize();
    return normals;
  }

  // ---- input --------------------------------------------------------------------------

  bindInput() {
    const c = this.canvas;
    c.addEventListener('keydown', (ev) => this.onKey(ev));
    c.addEventListener('dblclick', () => this.resetView());
    let buttons = 0;
    c.addEventListener('pointerdown', (ev) => {
      buttons = ev.buttons;
      c.focus({ preventScroll: true }); // the keys work on the picture just clicked
      this.showProbe(null);
    });
    c.addEventListener('pointerup', () => (buttons = 0));
    c.addEventListener('pointermove', (ev) => {
      if (buttons || ev.buttons) return; // orbiting or panning
      const r = c.getBoundingClientRect();
      this.pointer = [ev.clientX - r.left - c.clientLeft, ev.clientY - r.top - c.clientTop];
      cancelAnimationFrame(this.pendingProbe);
      this.pendingProbe = requestAnimationFrame(() => this.showProbe(this.pointer));
    });
    c.addEventListener('pointerleave', () => {
      this.pointer = null;
      this.showProbe(null);
    });
    // The context menu would cover the picture at the end of a right-button pan.
    c.addEventListener('contextmenu', (ev) => ev.preventDefault());
  }

  onKey(ev) {
    if (ev.altKey || ev.metaKey) return;
    const pan = ev.shiftKey || ev.ctrlKey;
    const steps = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] }[ev.key];
    if (steps && pan) this.pan(-steps[0] * KEY_PAN, -steps[1] * KEY_PAN);
    else if (steps) this.orbit(steps[0] * KEY_ANGLE, steps[1] * KEY_ANGLE);
    else if (ev.key === '+' || ev.key === '=') this.zoomBy(1.25);
    else if (ev.key === '-' || ev.key === '_') this.zoomBy(1 / 1.25);
    else if (ev.key === 'Home' || ev.key === '0') this.resetView();
    else return;
    ev.preventDefault();
  }

  /** Turns the camera about the target: `azimuth` about the vertical, `elevation` up. */
  orbit(azimuth, elevation) {
    if (!this.ok) return;
    const { camera, controls } = this;
    const offset = camera.position.clone().sub(controls.target);
    const s = new THREE.Spherical().setFromVector3(new THREE.Vector3(offset.x, offset.z, -offset.y)); // z up → y up
    s.theta += azimuth;
    s.phi = Math.min(Math.PI - 1e-3, Math.max(1e-3, s.phi - elevation));
    const o = new THREE.Vector3().setFromSpherical(s);
    camera.position.set(o.x, -o.z, o.y).add(controls.target);
    camera.lookAt(controls.target);
    controls.update();
  }

  /** Moves camera and target by fractions of the view's height (right, up). */
  pan(right, up) {
    if (!this.ok) return;
    const { camera, controls } = this;
    const dist = camera.position.distanceTo(controls.target);
    const h = 2 * dist * Math.tan(THREE.MathUtils.degToRad(camera.fov / 2));
    const x = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 0).multiplyScalar(right * h);
    const y = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 1).multiplyScalar(up * h);
    camera.position.add(x).add(y);
    controls.target.add(x).add(y);
    controls.update();
  }

  /** Zooms by `factor` (> 1: closer) towards the target. */
  zoomBy(factor) {
    if (!this.ok) return;
    const { camera, controls } = this;
    const offset = camera.position.clone().sub(controls.target);
    const d = Math.min(controls.maxDistance, Math.max(controls.minDistance, offset.length() / factor));
    camera.position.copy(controls.target).add(offset.setLength(d));
    controls.update();
  }

  /** The whole body in view, from the initial direction. */
  resetView() {
    if (!this.ok) return;
    this.fit();
    this.controls.update();
    this.requestRender();
  }

  /** Whether the body has a contact boundary Γ3 to look at (viewContact). */
  get hasContact() {
    return !!this.contactDir;
  }

  /** The whole body in view, looking at Γ3 from outside the body. */
  viewContact() {
    if (!this.ok || !this.contactDir) return;
    this.fit(this.contactDir);
    this.controls.update();
    this.requestRender();
  }

  /**
   * Looks at the body from direction `dir` (default: the initial one), from the least
   * distance at which the reference body and the deformed surface (at the current factor)
   * are inside the view with a small margin.
   */
  fit(dir = this.viewDir) {
    const p = this.positions.array;
    const box = this.box.clone();
    const v = new THREE.Vector3();
    for (let i = 0; i < p.length; i += 3) box.expandByPoint(v.set(p[i], p[i + 1], p[i + 2]));
    const centre = box.getCenter(new THREE.Vector3());
    // The camera's axes: `back` towards the camera, `right` and `up` on the screen.
    const back = dir;
    const right = new THREE.Vector3().crossVectors(this.camera.up, back).normalize();
    const up = new THREE.Vector3().crossVectors(back, right);
    const tv = 0.9 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    const th = tv * this.camera.aspect;
    // A point at (x, y, z) from the centre is in view from distance D when
    // |x| <= (D - z) th and |y| <= (D - z) tv.
    let dist = 0;
    const need = (q) => {
      q.sub(centre);
      dist = Math.max(dist, q.dot(back) + Math.max(Math.abs(q.dot(right)) / th, Math.abs(q.dot(up)) / tv));
    };
    for (let c = 0; c < 8; c++) {
      need(v.set(c & 1 ? this.box.max.x : this.box.min.x, c & 2 ? this.box.max.y : this.box.min.y, c & 4 ? this.box.max.z : this.box.min.z));
    }
    for (let i = 0; i < p.length; i += 3) need(v.set(p[i], p[i + 1], p[i + 2]));
    dist = Math.max(dist, this.controls.minDistance);
    this.controls.target.copy(centre);
    this.camera.position.copy(centre).addScaledVector(back, dist);
    this.camera.lookAt(centre);
  }

  // ---- the value under the pointer ----------------------------------------------------

  /** The shown field's value at CSS point p of the canvas (null: hide the readout). */
  showProbe(p) {
    const box = this.probeBox;
    const hit = p && this.ok && this.data ? this.pick(p) : null;
    if (!hit) {
      box.hidden = true;
      box.textContent = '';
      delete box.dataset.value;
      return;
    }
    const { face, w } = hit;
    const [[a, b, c], , cell] = this.faces[face];
    const N = this.mesh.nodes;
    const at = [0, 1, 2].map((k) => w[0] * N[a][k] + w[1] * N[b][k] + w[2] * N[c][k]);
    const { values, perCell, label, mode } = this.data;
    let value = null;
    if (values && mode !== 'parts') value = perCell ? values[cell] : w[0] * values[a] + w[1] * values[b] + w[2] * values[c];
    const part = this.faces[face][1];
    box.hidden = false;
    box.dataset.value = value === null ? '' : String(value);
    box.dataset.face = String(face);
    box.replaceChildren(
      mode === 'parts'
        ? el('span', { class: 'probe-value' }, `boundary: ${KINDS[edgeKind(this.kinds, part)].label}`)
        : el('span', { class: 'probe-value' }, `${label} = ${value === null ? 'not stored' : fmt(value)}`),
      el('span', { class: 'probe-where' }, `at (${at.map((x) => fmt(x, 3)).join(', ')})${perCell && mode !== 'parts' ? ` · tetrahedron ${this.mesh.surface ? this.mesh.cells[cell] : cell}` : ''}`),
    );
  }

  /** The boundary face under CSS point p and the point's barycentric weights in it. */
  pick([x, y]) {
    const c = this.canvas;
    const ndc = new THREE.Vector2((x / c.clientWidth) * 2 - 1, 1 - (y / c.clientHeight) * 2);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hit = ray.intersectObject(this.surface, false)[0];
    if (!hit || hit.faceIndex === undefined) return null;
    const w = hit.barycoord ? hit.barycoord.toArray() : [1 / 3, 1 / 3, 1 / 3];
    return { face: hit.faceIndex, w };
  }

  // ---- drawing ------------------------------------------------------------------------

  /**
   * Shows a step. opts: {width, height (the canvas's CSS size), disp: [ux0,uy0,uz0,...] | null, factor,
   * values (per node, or per tetrahedron when perCell) | null, perCell, range: [lo, hi],
   * label, mode: 'field' | 'parts', contact: [...] | null, showEdges, showArrows}.
   */
  update(opts) {
    if (!this.ok) return;
    const firstFrame = !this.data;
    this.data = opts;
    const cv = this.canvas;
    if (cv.style.height !== `${opts.height}px`) cv.style.height = `${opts.height}px`;
    // The drawing buffer matches the canvas's content box (inside its border).
    const width = cv.clientWidth || opts.width;
    const height = cv.clientHeight || opts.height;
    const sizeChanged = width !== this.width || height !== this.height;
    if (sizeChanged) {
      this.width = width;
      this.height = height;
      this.renderer.setSize(width, height, false);
      this.camera.aspect = width / height;
      this.camera.updateProjectionMatrix();
    }

    const N = this.mesh.nodes;
    const f = opts.disp && Number.isFinite(opts.factor) ? opts.factor : 0;
    const u = opts.disp;
    const at = (node, out, o) => {
      const p = N[node];
      out[o] = p[0] + (f ? f * u[3 * node] : 0);
      out[o + 1] = p[1] + (f ? f * u[3 * node + 1] : 0);
      out[o + 2] = p[2] + (f ? f * u[3 * node + 2] : 0);
    };
    const pos = this.positions.array;
    const fn = this.faceNodes;
    for (let i = 0; i < fn.length; i++) at(fn[i], pos, 3 * i);
    this.positions.needsUpdate = true;
    this.surface.geometry.computeBoundingSphere(); // for picking
    const val = this.values.array;
    const vals = opts.values;
    if (!vals) val.fill(0);
    else if (opts.perCell) this.faces.forEach(([, , cell], k) => val.fill(vals[cell] ?? 0, 3 * k, 3 * k + 3));
    else for (let i = 0; i < fn.length; i++) val[i] = vals[fn[i]];
    this.values.needsUpdate = true;
    const m = this.surfaceMaterial.uniforms;
    [m.lo.value, m.hi.value] = opts.range;
    m.mode.value = opts.mode === 'parts' ? 1 : 0;

    this.edgeLines.visible = !!opts.showEdges;
    if (opts.showEdges) {
      const e = this.edgeList, ep = this.edgePositions.array;
      for (let i = 0; i < e.length; i++) at(e[i], ep, 3 * i);
      this.edgePositions.needsUpdate = true;
    }
    this.updateContact(opts.contact, at, opts.showArrows);
    if (firstFrame) this.fit();
    this.controls.update();
    this.render();
    if (this.pointer) this.showProbe(this.pointer);
  }

  /** Contact nodes by state, and lines along the tangential velocity of the slipping ones. */
  updateContact(contact, at, showArrows) {
    const list = contact || [];
    const L = list.length;
    // The buffers are sized for the number of contact nodes (the same at every step of a
    // run): filled in place, not replaced, so the GPU buffers are not left behind.
    if (this.contactCapacity !== L) {
      this.contactCapacity = L;
      this.points.geometry.dispose();
      this.points.geometry = new THREE.BufferGeometry();
      this.points.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * L), 3).setUsage(THREE.DynamicDrawUsage));
      this.points.geometry.setAttribute('rgb', new THREE.BufferAttribute(new Float32Array(3 * L), 3).setUsage(THREE.DynamicDrawUsage));
      this.arrows.geometry.dispose();
      this.arrows.geometry = new THREE.BufferGeometry();
      this.arrows.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(18 * L), 3).setUsage(THREE.DynamicDrawUsage));
    }
    const pg = this.points.geometry;
    const pos = pg.attributes.position.array;
    const col = pg.attributes.rgb.array;
    const stick = rgb(STICK), slip = rgb(SLIP);
    list.forEach((c, i) => {
      at(c.node, pos, 3 * i);
      col.set(c.slipping ? slip : stick, 3 * i);
    });
    pg.attributes.position.needsUpdate = pg.attributes.rgb.needsUpdate = true;
    pg.computeBoundingSphere();

    // Lines: the longest is ARROW_LENGTH of the body, with two barbs in the tangent plane.
    const moving = showArrows ? list.filter((c) => c.slipping && Array.isArray(c.tangential_velocity)) : [];
    let vmax = 0;
    for (const c of moving) vmax = Math.max(vmax, Math.hypot(...c.tangential_velocity));
    const ag = this.arrows.geometry;
    const seg = ag.attributes.position.array;
    let k = 0;
    if (vmax > 0) {
      const p = [0, 0, 0];
      const t = new THREE.Vector3(), side = new THREE.Vector3(), tip = new THREE.Vector3(), barb = new THREE.Vector3();
      const push = (v) => {
        seg[k++] = v.x;
        seg[k++] = v.y;
        seg[k++] = v.z;
      };
      for (const c of moving) {
        t.fromArray(c.tangential_velocity).multiplyScalar((ARROW_LENGTH * this.size) / vmax);
        const len = t.length();
        if (!(len > 1e-9 * this.size)) continue;
        at(c.node, p, 0);
        tip.fromArray(p).add(t);
        push(new THREE.Vector3().fromArray(p));
        push(tip);
        const n = this.nodeNormals.get(c.node) || new THREE.Vector3(0, 0, 1);
        side.crossVectors(n, t).setLength(0.15 * len);
        for (const s of [1, -1]) {
          barb.copy(tip).addScaledVector(t, -0.26).addScaledVector(side, s);
          push(tip);
          push(barb);
        }
      }
    }
    ag.setDrawRange(0, k / 3);
    ag.attributes.position.needsUpdate = true;
    ag.computeBoundingSphere();
    this.arrows.visible = k > 0;
    this.points.visible = L > 0;
  }

  /** Draws at the next animation frame (many events make one frame). */
  requestRender() {
    if (!this.ok || this.pendingRender) return;
    this.pendingRender = requestAnimationFrame(() => {
      this.pendingRender = 0;
      this.render();
    });
  }

  render() {
    if (!this.ok || this.disposed || !this.width) return;
    // Contact points about half their spacing on the screen (a fine mesh's nodes do not
    // cover Γ3's colouring), within 3 to 8 CSS pixels.
    const dpr = this.renderer.getPixelRatio();
    const dist = this.camera.position.distanceTo(this.controls.target);
    const perUnit = this.height / (2 * dist * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
    this.pointMaterial.uniforms.size.value = dpr * Math.min(8, Math.max(3, 0.5 * this.contactSpacing * perUnit));
    this.renderer.render(this.scene, this.camera);
    this.frames++;
    // For tests and tools: frames drawn so far, and the camera (position, target).
    this.canvas.dataset.frame = String(this.frames);
    this.canvas.dataset.camera = JSON.stringify({
      position: this.camera.position.toArray().map((x) => Number(x.toPrecision(6))),
      target: this.controls.target.toArray().map((x) => Number(x.toPrecision(6))),
    });
  }

  /** The kinds of boundary part the surface has (for the legend). */
  kindsPresent() {
    if (this.presentKinds) return this.presentKinds;
    return new Set(this.faces.map(([, part]) => edgeKind(this.kinds, part)));
  }

  dispose() {
    this.disposed = true;
    cancelAnimationFrame(this.pendingRender);
    cancelAnimationFrame(this.pendingProbe);
    if (!this.ok) return;
    this.controls.dispose();
    this.scene.traverse((o) => {
      o.geometry?.dispose();
      o.material?.dispose();
    });
    this.lut.dispose();
    this.renderer.dispose();
    // Browsers keep few WebGL contexts alive: give this one back now, not at collection.
    this.renderer.forceContextLoss();
  }
}
