// Small line plots as inline SVG (crisp at any size, no canvas bookkeeping): one series
// against time, axis extremes as labels, and a movable marker for the displayed step.

import { fmt } from './util.js';

const NS = 'http://www.w3.org/2000/svg';
const svg = (tag, attrs = {}) => {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  return e;
};

/**
 * Appends a plot of ys over xs to `parent`; returns {setMarker(x)}.
 * The SVG uses a fixed viewBox and scales with its container (CSS width: 100%).
 */
export function linePlot(parent, { title, xs, ys, xLabel = 't', colour = '#1864ab' }) {
  const w = 220, h = 120;
  const m = { l: 44, r: 8, t: 18, b: 20 };
  const root = svg('svg', { viewBox: `0 0 ${w} ${h}`, class: 'plot', role: 'img', 'aria-label': title });
  const good = xs.map((x, i) => [x, ys[i]]).filter(([x, y]) => Number.isFinite(x) && Number.isFinite(y));
  const xmin = Math.min(...good.map((p) => p[0]));
  const xmax = Math.max(...good.map((p) => p[0]));
  let ymin = Math.min(...good.map((p) => p[1]));
  let ymax = Math.max(...good.map((p) => p[1]));
  if (!(ymax > ymin)) {
    // A constant series (e.g. no damage): centre it.
    const d = Math.max(Math.abs(ymax) * 0.05, 1e-9);
    ymin -= d;
    ymax += d;
  }
  const X = (x) => m.l + ((x - xmin) / (xmax - xmin || 1)) * (w - m.l - m.r);
  const Y = (y) => h - m.b - ((y - ymin) / (ymax - ymin)) * (h - m.t - m.b);

  const text = (x, y, s, anchor = 'start', cls = 'tick') => {
    const t = svg('text', { x, y, 'text-anchor': anchor, class: cls });
    t.textContent = s;
    return t;
  };
  root.append(
    svg('rect', { x: m.l, y: m.t, width: w - m.l - m.r, height: h - m.t - m.b, class: 'frame' }),
    text(m.l, 12, title, 'start', 'title'),
    text(m.l - 4, m.t + 8, fmt(ymax), 'end'),
    text(m.l - 4, h - m.b, fmt(ymin), 'end'),
    text(m.l, h - 6, fmt(xmin)),
    text(w - m.r, h - 6, fmt(xmax), 'end'),
    text((m.l + w - m.r) / 2, h - 6, xLabel, 'middle'),
  );
  if (good.length) {
    const d = good.map(([x, y], i) => `${i ? 'L' : 'M'}${X(x).toFixed(1)},${Y(y).toFixed(1)}`).join('');
    root.append(svg('path', { d, fill: 'none', stroke: colour, 'stroke-width': 1.6 }));
    if (good.length === 1) root.append(svg('circle', { cx: X(good[0][0]), cy: Y(good[0][1]), r: 2.5, fill: colour }));
  }
  const marker = svg('line', { y1: m.t, y2: h - m.b, class: 'marker', visibility: 'hidden' });
  const dot = svg('circle', { r: 3, class: 'marker-dot', visibility: 'hidden' });
  root.append(marker, dot);
  parent.append(root);

  return {
    /** Moves the marker to time x (the value shown is the series' value at the nearest x). */
    setMarker(x) {
      if (!good.length || !Number.isFinite(x)) return;
      let best = good[0];
      for (const p of good) if (Math.abs(p[0] - x) < Math.abs(best[0] - x)) best = p;
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
