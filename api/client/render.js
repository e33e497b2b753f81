// Draws a (deformed) triangle mesh coloured by a scalar field on a Canvas 2D, and answers
// "which triangle, and which value, is under this pixel" for the picture last drawn.
//
// Canvas 2D cannot interpolate colours across a triangle, and filling triangles one by one
// leaves anti-aliased hairline seams between them. So the field is rasterised in JavaScript
// into an ImageData: per pixel, barycentric interpolation of nodal values (ζ, |w|) or the
// constant of the triangle (von Mises), mapped through the colour table. The same pass writes
// the triangle of every pixel into an index buffer, so the value under the pointer is found
// in constant time (and exactly where the picture shows the body: nothing in a hole). A few
// thousand triangles at ~1000×500 pixels take a few milliseconds; triangles outside the view
// (zoomed in) cost only their bounding-box test.
//
// Lines are drawn afterwards with the ordinary 2D API, each set as one path: the mesh lines
// (every edge once, butt caps: a path of closed triangles with round joins took Chromium
// ~1.5 s per redraw at 16k triangles), the reference outline, the boundary by the kind of
// its part, and the contact boundary Γ3 by its stick/slip state.

import { LUT } from './colormap.js';

export const STICK = '#1971c2';
export const SLIP = '#e8590c';

/** Colours of the boundary by the kind of its part (null part: traction-free). */
export const KINDS = {
  clamped: { colour: '#c92a2a', label: 'clamped (Γ1)', width: 3 },
  traction: { colour: '#be4bdb', label: 'traction (Γ2)', width: 3 },
  contact: { colour: STICK, label: 'contact (Γ3)', width: 3 },
  free: { colour: '#212529', label: 'traction-free', width: 1 },
  other: { colour: '#868e96', label: 'other part', width: 3 },
};

/** The kind of each boundary part: from the mesh's `parts` (the scene's boundary list). */
export function partKinds(mesh) {
  return (mesh.parts || []).map((p) => (KINDS[p?.type] ? p.type : 'other'));
}

/** The kind of a boundary edge [[a, b], part]. */
export function edgeKind(kinds, part) {
  if (part === null || part === undefined) return 'free';
  return kinds[part] || 'other';
}

/** The bounding box [x0, y0, x1, y1] of a list of [x, y] points. */
export function boundingBox(nodes) {
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const [x, y] of nodes) {
    if (x < x0) x0 = x;
    if (x > x1) x1 = x;
    if (y < y0) y0 = y;
    if (y > y1) y1 = y;
  }
  return [x0, y0, x1, y1];
}

/** Per canvas: the reusable triangle index buffer. */
const buffers = new WeakMap();

/**
 * opts: {nodes: [[x,y]], triangles: [[a,b,c]], boundaryEdges: [[[a,b], part]], kinds: [kind per part],
 *        disp: [ux0,uy0,ux1,...] | null, factor, values, perCell, range: [lo, hi],
 *        contact: [{node, slipping}] | null, showEdges, view: {zoom, panX, panY} | null}
 * The body (reference and deformed) is fitted into the canvas; `view` then zooms by `zoom`
 * about the fitted centre moved by (panX, panY) in world units.
 * Returns the frame: {s, ox, oy} (world → CSS pixels: X = ox + s x, Y = oy − s y), the fit
 * {s0, cx, cy} and what `probe` needs.
 */
export function drawField(canvas, opts) {
  const dpr = window.devicePixelRatio || 1;
  const cssW = canvas.clientWidth;
  const cssH = canvas.clientHeight;
  const W = Math.max(1, Math.round(cssW * dpr));
  const H = Math.max(1, Math.round(cssH * dpr));
  if (canvas.width !== W || canvas.height !== H) {
    canvas.width = W;
    canvas.height = H;
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.clearRect(0, 0, W, H);

  const { nodes, triangles, values, perCell } = opts;
  const n = nodes.length;
  const f = opts.disp ? opts.factor : 0;
  // Deformed positions.
  const X = new Float64Array(n);
  const Y = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    X[i] = nodes[i][0] + (f ? f * opts.disp[2 * i] : 0);
    Y[i] = nodes[i][1] + (f ? f * opts.disp[2 * i + 1] : 0);
  }
  // Fit the union of the reference and the deformed body, so the reference outline stays
  // in view and the picture does not jump when the deformation is small.
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (let i = 0; i < n; i++) {
    x0 = Math.min(x0, X[i], nodes[i][0]);
    x1 = Math.max(x1, X[i], nodes[i][0]);
    y0 = Math.min(y0, Y[i], nodes[i][1]);
    y1 = Math.max(y1, Y[i], nodes[i][1]);
  }
  if (!(x1 >= x0)) [x0, x1, y0, y1] = [0, 1, 0, 1];
  const pad = 16 * dpr;
  const s0 = Math.min((W - 2 * pad) / (x1 - x0 || 1), (H - 2 * pad) / (y1 - y0 || 1));
  const view = opts.view || { zoom: 1, panX: 0, panY: 0 };
  const s = s0 * view.zoom;
  const fcx = (x0 + x1) / 2;
  const fcy = (y0 + y1) / 2;
  const ox = W / 2 - s * (fcx + view.panX);
  const oy = H / 2 + s * (fcy + view.panY); // y up
  const PX = new Float64Array(n);
  const PY = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    PX[i] = ox + s * X[i];
    PY[i] = oy - s * Y[i];
  }

  // Rasterise the field, and which triangle each pixel shows.
  let ids = buffers.get(canvas);
  if (!ids || ids.length !== W * H) {
    ids = new Int32Array(W * H);
    buffers.set(canvas, ids);
  }
  ids.fill(-1);
  const img = ctx.createImageData(W, H);
  const data = img.data;
  const [lo, hi] = opts.range;
  const scale = 255 / (hi - lo);
  const colour = (v) => {
    let k = Math.round((v - lo) * scale);
    k = k < 0 ? 0 : k > 255 ? 255 : k;
    return 3 * k;
  };
  for (let e = 0; e < triangles.length; e++) {
    const [a, b, c] = triangles[e];
    const ax = PX[a], ay = PY[a], bx = PX[b], by = PY[b], cx = PX[c], cy = PY[c];
    const minX = Math.max(0, Math.floor(Math.min(ax, bx, cx)));
    const maxX = Math.min(W - 1, Math.ceil(Math.max(ax, bx, cx)));
    if (minX > maxX) continue;
    const minY = Math.max(0, Math.floor(Math.min(ay, by, cy)));
    const maxY = Math.min(H - 1, Math.ceil(Math.max(ay, by, cy)));
    if (minY > maxY) continue;
    const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    if (Math.abs(area) < 1e-12) continue;
    const inv = 1 / area;
    const va = perCell ? values[e] : values[a];
    const vb = perCell ? values[e] : values[b];
    const vc = perCell ? values[e] : values[c];
    // A small tolerance closes cracks along shared edges (pixels there are written twice).
    const eps = -1e-9;
    for (let py = minY; py <= maxY; py++) {
      const y = py + 0.5;
      for (let px = minX; px <= maxX; px++) {
        const x = px + 0.5;
        const wa = ((bx - x) * (cy - y) - (by - y) * (cx - x)) * inv;
        const wb = ((cx - x) * (ay - y) - (cy - y) * (ax - x)) * inv;
        const wc = 1 - wa - wb;
        if (wa < eps || wb < eps || wc < eps) continue;
        const k = colour(wa * va + wb * vb + wc * vc);
        const p = py * W + px;
        const o = 4 * p;
        data[o] = LUT[k];
        data[o + 1] = LUT[k + 1];
        data[o + 2] = LUT[k + 2];
        data[o + 3] = 255;
        ids[p] = e;
      }
    }
  }
  ctx.putImageData(img, 0, 0);

  ctx.lineJoin = 'round';
  ctx.lineCap = 'round';
  if (opts.showEdges) {
    ctx.strokeStyle = 'rgba(0,0,0,0.22)';
    ctx.lineWidth = 0.7 * dpr;
    ctx.lineCap = 'butt';
    const E = uniqueEdges(triangles);
    ctx.beginPath();
    for (let k = 0; k < E.length; k += 2) {
      ctx.moveTo(PX[E[k]], PY[E[k]]);
      ctx.lineTo(PX[E[k + 1]], PY[E[k + 1]]);
    }
    ctx.stroke();
    ctx.lineCap = 'round';
  }
  // Reference outline (dashed) and the deformed boundary, by the kind of its part.
  const edges = opts.boundaryEdges || [];
  const kinds = opts.kinds || [];
  ctx.setLineDash([4 * dpr, 4 * dpr]);
  ctx.strokeStyle = 'rgba(60,60,60,0.7)';
  ctx.lineWidth = 1 * dpr;
  ctx.beginPath();
  for (const [[a, b]] of edges) {
    ctx.moveTo(ox + s * nodes[a][0], oy - s * nodes[a][1]);
    ctx.lineTo(ox + s * nodes[b][0], oy - s * nodes[b][1]);
  }
  ctx.stroke();
  ctx.setLineDash([]);
  // Contact edges are drawn by their state when it is known (both ends are contact nodes).
  const slipping = opts.contact && opts.contact.length ? new Map(opts.contact.map((c) => [c.node, c.slipping])) : null;
  const byState = { stick: [], slip: [] };
  for (const kind of ['free', 'other', 'traction', 'clamped', 'contact']) {
    ctx.strokeStyle = KINDS[kind].colour;
    ctx.lineWidth = KINDS[kind].width * dpr;
    ctx.beginPath();
    for (const [[a, b], part] of edges) {
      if (edgeKind(kinds, part) !== kind) continue;
      if (slipping && (kind === 'contact' || kind === 'other') && slipping.has(a) && slipping.has(b)) {
        (slipping.get(a) || slipping.get(b) ? byState.slip : byState.stick).push(a, b);
        continue;
      }
      ctx.moveTo(PX[a], PY[a]);
      ctx.lineTo(PX[b], PY[b]);
    }
    ctx.stroke();
  }

  // The contact boundary Γ3 by state: its edges and nodes.
  if (slipping) {
    ctx.lineWidth = 4 * dpr;
    for (const [state, list] of Object.entries(byState)) {
      ctx.strokeStyle = state === 'slip' ? SLIP : STICK;
      ctx.beginPath();
      for (let k = 0; k < list.length; k += 2) {
        ctx.moveTo(PX[list[k]], PY[list[k]]);
        ctx.lineTo(PX[list[k + 1]], PY[list[k + 1]]);
      }
      ctx.stroke();
    }
    const r = 3 * dpr;
    for (const slip of [false, true]) {
      ctx.fillStyle = slip ? SLIP : STICK;
      ctx.beginPath();
      for (const c of opts.contact) {
        if (!!c.slipping !== slip) continue;
        ctx.moveTo(PX[c.node] + r, PY[c.node]);
        ctx.arc(PX[c.node], PY[c.node], r, 0, 2 * Math.PI);
      }
      ctx.fill();
    }
  }
  return {
    s: s / dpr, ox: ox / dpr, oy: oy / dpr, // world → CSS pixels
    fit: { s0: s0 / dpr, cx: fcx, cy: fcy },
    dpr, W, H, PX, PY, ids,
  };
}

/**
 * What the picture `frame` shows at CSS pixel (x, y) of the canvas: null outside the body, or
 * {triangle, weights: [wa, wb, wc]} (barycentric coordinates of the point in that triangle;
 * the same weights give the point in the reference configuration).
 */
export function probe(frame, triangles, x, y) {
  if (!frame) return null;
  const px = Math.floor(x * frame.dpr);
  const py = Math.floor(y * frame.dpr);
  if (px < 0 || py < 0 || px >= frame.W || py >= frame.H) return null;
  const e = frame.ids[py * frame.W + px];
  if (e < 0) return null;
  const [a, b, c] = triangles[e];
  const { PX, PY } = frame;
  const X = x * frame.dpr, Y = y * frame.dpr;
  const area = (PX[b] - PX[a]) * (PY[c] - PY[a]) - (PY[b] - PY[a]) * (PX[c] - PX[a]);
  let wa = ((PX[b] - X) * (PY[c] - Y) - (PY[b] - Y) * (PX[c] - X)) / area;
  let wb = ((PX[c] - X) * (PY[a] - Y) - (PY[c] - Y) * (PX[a] - X)) / area;
  // The pixel's centre is in the triangle; the pointer may be a fraction of a pixel outside.
  wa = Math.min(1, Math.max(0, wa));
  wb = Math.min(1 - wa, Math.max(0, wb));
  return { triangle: e, weights: [wa, wb, 1 - wa - wb] };
}

/** Every edge of the triangles once, as a flat [a0, b0, a1, b1, ...] (cached per mesh). */
const edgeCache = new WeakMap();
function uniqueEdges(triangles) {
  let E = edgeCache.get(triangles);
  if (E) return E;
  const seen = new Set();
  const out = [];
  for (const t of triangles) {
    for (let j = 0; j < 3; j++) {
      const a = t[j], b = t[(j + 1) % 3];
      const lo = a < b ? a : b, hi = a < b ? b : a;
      const key = lo * 4294967296 + hi;
      if (seen.has(key)) continue;
      seen.add(key);
      out.push(lo, hi);
    }
  }
  E = Int32Array.from(out);
  edgeCache.set(triangles, E);
  return E;
}
