// Colour map: viridis (perceptually uniform, readable in grey and by most colour-blind
// viewers), sampled from matplotlib's table at 11 points and interpolated linearly into a
// 256-entry lookup table. Low values are dark: for damage ζ (1 = sound, 0 = fully damaged)
// the damaged zones are the dark ones.

const STOPS = [
  [68, 1, 84], [72, 36, 117], [65, 68, 135], [53, 95, 141], [42, 120, 142], [33, 145, 140],
  [34, 168, 132], [68, 191, 112], [122, 209, 81], [189, 223, 38], [253, 231, 37],
];

/** 256 RGB triples, Uint8Array of length 768. */
export const LUT = (() => {
  const lut = new Uint8Array(256 * 3);
  for (let i = 0; i < 256; i++) {
    const x = (i / 255) * (STOPS.length - 1);
    const j = Math.min(Math.floor(x), STOPS.length - 2);
    const f = x - j;
    for (let c = 0; c < 3; c++) lut[3 * i + c] = Math.round(STOPS[j][c] * (1 - f) + STOPS[j + 1][c] * f);
  }
  return lut;
})();

/** The CSS gradient of the map (for the colour bar), left = low. */
export function cssGradient(direction = 'to right') {
  return `linear-gradient(${direction}, ${STOPS.map((c, i) => `rgb(${c}) ${(100 * i) / (STOPS.length - 1)}%`).join(', ')})`;
}

/**
 * A displayable range [lo, hi] for values with the given extremes: a constant field gets a
 * small symmetric range, so it is drawn in the middle colour instead of dividing by zero.
 */
export function niceRange(min, max) {
  if (!Number.isFinite(min) || !Number.isFinite(max)) return [0, 1];
  if (max - min <= 1e-12 * Math.max(1, Math.abs(max))) {
    const d = Math.max(Math.abs(max) * 1e-3, 1e-12);
    return [min - d, max + d];
  }
  return [min, max];
}

/**
 * About `count` round values (1, 2 or 5 × a power of ten apart) inside [lo, hi], for the
 * colour bar's ticks.
 */
export function niceTicks(lo, hi, count = 5) {
  if (!(hi > lo) || !Number.isFinite(lo) || !Number.isFinite(hi)) return [];
  const raw = (hi - lo) / Math.max(1, count - 1);
  const p = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((f) => f * p).find((s) => s >= raw * 0.999) ?? 10 * p;
  const out = [];
  for (let i = Math.ceil(lo / step - 1e-9); i * step <= hi + 1e-9 * step; i++) {
    out.push(Number((i * step).toPrecision(12)));
  }
  return out;
}
