// Small line plots as inline SVG (crisp at any size, no canvas bookkeeping): one series
// against time (or position), axis extremes as labels, a movable marker for the displayed
// step, the value under the pointer, and a click that reports the x under the pointer (the
// viewer seeks to that time).
//
// Legibility: the viewBox is VIEW_W user units wide and the page lays plots out at least
// that many CSS pixels wide (style.css .plots), so 12-unit text is never drawn under 12 px;
// the left margin is sized from the longest y label, so no label is cut.

import { distinctDigits, fmt } from './util.js';

const NS = 'http://www.w3.org/2000/svg';
const svg = (tag, attrs = {}) => {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  return e;
};

export const VIEW_W = 240;
const VIEW_H = 150;
const TICK_PX = 12; // tick label font size, user units
const CHAR_W = 0.62 * TICK_PX; // a digit's advance in the system font, with room to spare

/**
 * Appends a plot of ys over xs to `parent`; returns {setMarker(x), element}. `fromZero`:
 * the x axis starts at 0 (time: the initial state is t = 0 even if the series starts at k).
 * `onPick(x)`: called with the x of the nearest point when the plot is clicked. `dots`: the
 * points are drawn as dots (a scatter), not joined.
 */
export function linePlot(parent, { title, xs, ys, xLabel = 't', colour = '#1864ab', fromZero = true, onPick = null, dots = false, band = null, id }) {
  const w = VIEW_W, h = VIEW_H;
  const good = xs.map((x, i) => [x, ys[i]]).filter(([x, y]) => Number.isFinite(x) && Number.isFinite(y));
  // band: {lo, hi} beside ys, a shaded range around the line (binned data: each bin's extremes).
  const spread = band ? xs.map((x, i) => [x, band.lo[i], band.hi[i]]).filter((q) => q.every(Number.isFinite)) : [];
  let xmin = Math.min(...good.map((p) => p[0]));
  const xmax = Math.max(...good.map((p) => p[0]));
  if (fromZero && xmin > 0) xmin = 0;
  let ymin = Math.min(...good.map((p) => p[1]), ...spread.map((q) => q[1]));
  let ymax = Math.max(...good.map((p) => p[1]), ...spread.map((q) => q[2]));
  // A series constant up to rounding (no damage; a friction traction of 0.5 ± 1e-14) is
  // drawn flat in the middle with its value, not stretched into full-height noise.
  const flat = good.length > 0 && !(ymax - ymin > 1e-9 * Math.max(Math.abs(ymax), Math.abs(ymin), 1e-300));
  const flatValue = flat ? (ymin + ymax) / 2 : null;
  if (flat) {
    const d = Math.max(Math.abs(flatValue) * 0.05, 1e-9);
    ymin = flatValue - d;
    ymax = flatValue + d;
  }
  const yDigits = distinctDigits(ymax, ymin, 3);
  const yLabels = good.length ? [fmt(ymax, yDigits), fmt(ymin, yDigits)] : ['', ''];
  const m = { l: 8 + CHAR_W * Math.max(...yLabels.map((s) => s.length), 1), r: 10, t: 22, b: 24 };
  const X = (x) => m.l + ((x - xmin) / (xmax - xmin || 1)) * (w - m.l - m.r);
  const Y = (y) => h - m.b - ((y - ymin) / (ymax - ymin)) * (h - m.t - m.b);

  const root = svg('svg', { viewBox: `0 0 ${w} ${h}`, class: 'plot', role: 'img', 'aria-label': title });
  if (id) root.id = id;
  root.dataset.points = String(good.length);
  root.dataset.ymin = String(ymin);
  root.dataset.ymax = String(ymax);
  if (flat) root.dataset.flat = String(flatValue);
  const text = (x, y, s, anchor = 'start', cls = 'tick') => {
    const t = svg('text', { x, y, 'text-anchor': anchor, class: cls });
    t.textContent = s;
    return t;
  };
  root.append(
    svg('rect', { x: m.l, y: m.t, width: w - m.l - m.r, height: h - m.t - m.b, class: 'frame' }),
    text(4, 15, title, 'start', 'title'),
    text(m.l - 4, m.t + 10, yLabels[0], 'end'),
    text(m.l - 4, h - m.b, yLabels[1], 'end'),
    text(m.l, h - 7, good.length ? fmt(xmin, 3) : ''),
    text(w - m.r, h - 7, good.length ? fmt(xmax, 3) : '', 'end'),
    text((m.l + w - m.r) / 2, h - 7, xLabel, 'middle'),
  );
  if (spread.length && !flat) {
    const upper = spread.map(([x, , hi], i) => `${i ? 'L' : 'M'}${X(x).toFixed(1)},${Y(hi).toFixed(1)}`).join('');
    const lower = spread.slice().reverse().map(([x, lo]) => `L${X(x).toFixed(1)},${Y(lo).toFixed(1)}`).join('');
    root.append(svg('path', { d: `${upper}${lower}Z`, fill: colour, 'fill-opacity': 0.18, stroke: 'none', class: 'band' }));
    root.dataset.band = String(spread.length);
  }
  if (good.length) {
    if (dots) {
      const g = svg('g', { fill: colour });
      for (const [x, y] of good) g.append(svg('circle', { cx: X(x).toFixed(1), cy: Y(y).toFixed(1), r: 1.8 }));
      root.append(g);
    } else {
      const d = good.map(([x, y], i) => `${i ? 'L' : 'M'}${X(x).toFixed(1)},${Y(flat ? flatValue : y).toFixed(1)}`).join('');
      root.append(svg('path', { d, fill: 'none', stroke: colour, 'stroke-width': 1.6 }));
      if (good.length === 1) root.append(svg('circle', { cx: X(good[0][0]), cy: Y(good[0][1]), r: 2.5, fill: colour }));
    }
    if (flat) root.append(text(w - m.r - 4, Y(flatValue) - 5, `constant ${fmt(flatValue, 6)}`, 'end', 'tick flat-value'));
  }
  const marker = svg('line', { y1: m.t, y2: h - m.b, class: 'marker', visibility: 'hidden' });
  const dot = svg('circle', { r: 3, class: 'marker-dot', visibility: 'hidden' });
  // The value under the pointer: a ring on the nearest point and its value in the title row.
  const ring = svg('circle', { r: 4, class: 'hover-dot', visibility: 'hidden' });
  const readout = text(w - m.r, 15, '', 'end', 'hover-label');
  root.append(marker, dot, ring, readout);
  parent.append(root);

  const nearest = (x) => {
    let best = good[0];
    for (const p of good) if (Math.abs(p[0] - x) < Math.abs(best[0] - x)) best = p;
    return best;
  };
  /** The world x under a pointer event. */
  const xAt = (ev) => {
    const r = root.getBoundingClientRect();
    const ux = ((ev.clientX - r.left) / r.width) * w;
    return xmin + ((ux - m.l) / (w - m.l - m.r)) * (xmax - xmin || 1);
  };
  if (good.length) {
    root.addEventListener('pointermove', (ev) => {
      const [x, y] = nearest(xAt(ev));
      ring.setAttribute('cx', X(x).toFixed(1));
      ring.setAttribute('cy', Y(y).toFixed(1));
      ring.setAttribute('visibility', 'visible');
      readout.textContent = `${xLabel} = ${fmt(x, 3)}: ${fmt(y, 4)}`;
      root.dataset.hoverX = String(x);
      root.dataset.hoverValue = String(y);
    });
    root.addEventListener('pointerleave', () => {
      ring.setAttribute('visibility', 'hidden');
      readout.textContent = '';
      delete root.dataset.hoverX;
      delete root.dataset.hoverValue;
    });
    if (onPick) {
      root.classList.add('pickable');
      root.addEventListener('click', (ev) => onPick(nearest(xAt(ev))[0]));
    }
  }

  return {
    element: root,
    /** Moves the marker to x (the value shown is the series' value at the nearest x). */
    setMarker(x) {
      if (!good.length || !Number.isFinite(x)) return;
      const best = nearest(x);
      const px = X(best[0]).toFixed(1);
      marker.setAttribute('x1', px);
      marker.setAttribute('x2', px);
      dot.setAttribute('cx', px);
      dot.setAttribute('cy', Y(best[1]).toFixed(1));
      marker.setAttribute('visibility', 'visible');
      dot.setAttribute('visibility', 'visible');
    },
  };
}
