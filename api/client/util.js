// Small DOM and formatting helpers shared by the modules.

/** Creates an element: el('td', {class: 'num', title: 'x'}, 'text', childNode, ...). */
export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith('on') && typeof v === 'function') e.addEventListener(k.slice(2), v);
    else if (k === 'dataset') Object.assign(e.dataset, v);
    else e.setAttribute(k, v === true ? '' : String(v));
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    e.append(c instanceof Node ? c : String(c));
  }
  return e;
}

export const $ = (sel, root = document) => root.querySelector(sel);

/** A number in a compact, readable form (4 significant digits, exponent when needed). */
export function fmt(x, digits = 4) {
  if (x === null || x === undefined || Number.isNaN(x)) return '–';
  if (x === 0) return '0';
  const a = Math.abs(x);
  if (a >= 1e-3 && a < 1e5) return String(Number(x.toPrecision(digits)));
  return x.toExponential(digits - 1);
}

/**
 * The fewest significant digits (at least `min`, at most 15) at which fmt tells a from b
 * apart: the two ends of an axis over near-constant data (1.3712 and 1.3718) must not both
 * read "1.37".
 */
export function distinctDigits(a, b, min = 3) {
  let d = min;
  while (d < 15 && a !== b && fmt(a, d) === fmt(b, d)) d++;
  return d;
}

/**
 * Significant digits for tick labels `ticks` (evenly spaced): enough to resolve their step,
 * so 0.9992, 0.9994, 0.9996 do not all read "0.999"; at least `min`.
 */
export function tickDigits(ticks, min = 3) {
  if (ticks.length < 2) return min;
  const step = Math.abs(ticks[1] - ticks[0]);
  const big = Math.max(...ticks.map((t) => Math.abs(t)));
  if (!(step > 0) || !(big > 0)) return min;
  const d = Math.floor(Math.log10(big)) - Math.floor(Math.log10(step)) + 1;
  return Math.min(15, Math.max(min, d));
}

/** Mesh sizes and time steps read best as 1/n when they are reciprocals of integers. */
export function fmtStep(x) {
  if (typeof x !== 'number' || !(x > 0)) return fmt(x);
  const n = 1 / x;
  if (Math.abs(n - Math.round(n)) < 1e-9 * n && Math.round(n) > 1) return `1/${Math.round(n)}`;
  return fmt(x);
}

export function fmtSeconds(s) {
  if (s === null || s === undefined) return '–';
  if (s < 0.01) return `${Number((s * 1000).toPrecision(2))} ms`;
  if (s < 1) return `${(s * 1000).toFixed(0)} ms`;
  if (s < 120) return `${s.toFixed(1)} s`;
  return `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
}

/** A size in bytes as people read it: "812 B", "12 kB", "2.4 MB" (SI units, 2 significant digits). */
export function fmtBytes(n) {
  if (typeof n !== 'number' || !Number.isFinite(n) || n < 0) return '–';
  if (n < 995) return `${Math.round(n)} B`;
  const units = ['kB', 'MB', 'GB', 'TB'];
  let v = n / 1000;
  let i = 0;
  while (v >= 995 && i < units.length - 1) {
    v /= 1000;
    i++;
  }
  return `${Number(v.toPrecision(2))} ${units[i]}`;
}
