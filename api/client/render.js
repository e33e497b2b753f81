// Draws a (deformed) triangle mesh coloured by a scalar field on a Canvas 2D.
//
// Canvas 2D cannot interpolate colours across a triangle, and filling triangles one by one
// leaves anti-aliased hairline seams between them. So the field is rasterised in JavaScript
// into an ImageData: per pixel, barycentric interpolation of nodal values (ζ, |w|) or the
// constant of the triangle (von Mises), mapped through the colour table. A few thousand
// triangles at ~1000×500 pixels take a few milliseconds. Lines (mesh, outline, contact
// boundary) are drawn afterwards with the ordinary 2D API.

import { LUT } from './colormap.js';

export const STICK = '#1971c2';
export const SLIP = '#e8590c';

/**
 * opts: {nodes: [[x,y]], triangles: [[a,b,c]], boundaryEdges: [[[a,b], part]],
 *        disp: [ux0,uy0,ux1,...] | null, factor, values, perCell, range: [lo, hi],
 *        contact: [{node, slipping}] | null, showEdges}
 * Returns the mapping from world to CSS pixels (for hit tests, if ever needed).
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
  const pad = 16 * dpr;
  const s = Math.min((W - 2 * pad) / (x1 - x0 || 1), (H - 2 * pad) / (y1 - y0 || 1));
  const ox = (W - s * (x1 - x0)) / 2 - s * x0;
  const oy = (H + s * (y1 - y0)) / 2 + s * y0; // y up
  const PX = new Float64Array(n);
  const PY = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    PX[i] = ox + s * X[i];
    PY[i] = oy - s * Y[i];
  }

  // Rasterise the field.
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
    const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    if (Math.abs(area) < 1e-12) continue;
    const inv = 1 / area;
    const va = perCell ? values[e] : values[a];
    const vb = perCell ? values[e] : values[b];
    const vc = perCell ? values[e] : values[c];
    const minX = Math.max(0, Math.floor(Math.min(ax, bx, cx)));
    const maxX = Math.min(W - 1, Math.ceil(Math.max(ax, bx, cx)));
    const minY = Math.max(0, Math.floor(Math.min(ay, by, cy)));
    const maxY = Math.min(H - 1, Math.ceil(Math.max(ay, by, cy)));
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
        const o = 4 * (py * W + px);
        data[o] = LUT[k];
        data[o + 1] = LUT[k + 1];
        data[o + 2] = LUT[k + 2];
        data[o + 3] = 255;
      }
    }
  }
  ctx.putImageData(img, 0, 0);

  ctx.lineJoin = 'round';
  ctx.lineCap = 'round';
  if (opts.showEdges) {
    ctx.strokeStyle = 'rgba(0,0,0,0.22)';
    ctx.lineWidth = 0.7 * dpr;
    ctx.beginPath();
    for (const [a, b, c] of triangles) {
      ctx.moveTo(PX[a], PY[a]);
      ctx.lineTo(PX[b], PY[b]);
      ctx.lineTo(PX[c], PY[c]);
      ctx.closePath();
    }
    ctx.stroke();
  }
  // Reference outline (dashed) and deformed outline.
  const edges = opts.boundaryEdges || [];
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
  ctx.strokeStyle = '#222';
  ctx.beginPath();
  for (const [[a, b]] of edges) {
    ctx.moveTo(PX[a], PY[a]);
    ctx.lineTo(PX[b], PY[b]);
  }
  ctx.stroke();

  // The contact boundary Γ3: its edges (both ends are contact nodes) and nodes, by state.
  if (opts.contact && opts.contact.length) {
    const slipping = new Map(opts.contact.map((c) => [c.node, c.slipping]));
    ctx.lineWidth = 4 * dpr;
    for (const [[a, b]] of edges) {
      if (!slipping.has(a) || !slipping.has(b)) continue;
      ctx.strokeStyle = slipping.get(a) || slipping.get(b) ? SLIP : STICK;
      ctx.beginPath();
      ctx.moveTo(PX[a], PY[a]);
      ctx.lineTo(PX[b], PY[b]);
      ctx.stroke();
    }
    const r = 3 * dpr;
    for (const c of opts.contact) {
      ctx.fillStyle = c.slipping ? SLIP : STICK;
      ctx.beginPath();
      ctx.arc(PX[c.node], PY[c.node], r, 0, 2 * Math.PI);
      ctx.fill();
    }
  }
  return { s: s / dpr, ox: ox / dpr, oy: oy / dpr };
}
