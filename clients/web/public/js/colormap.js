// Field colouring: a perceptual colour map (viridis, sampled at 9 stops and
// interpolated), each field's unit, and the value range a legend shows.

const STOPS = [
  [0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530], [0.207, 0.372, 0.553],
  [0.164, 0.471, 0.558], [0.128, 0.567, 0.551], [0.135, 0.659, 0.518], [0.267, 0.749, 0.441],
  [0.478, 0.821, 0.318], [0.741, 0.873, 0.150], [0.993, 0.906, 0.144],
];

// Colour of t in [0, 1] (clamped) as [r, g, b] in [0, 1].
export function viridis(t) {
  if (!(t > 0)) t = 0;  // also NaN
  if (t > 1) t = 1;
  const x = t * (STOPS.length - 1);
  const i = Math.min(Math.floor(x), STOPS.length - 2);
  const f = x - i;
  const a = STOPS[i];
  const b = STOPS[i + 1];
  return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
}

export const FIELDS = {
  displacement: { label: 'displacement', unit: 'm', fromZero: true },
  strain: { label: 'strain', unit: '1', fromZero: true },
  stiffness: { label: 'stiffness (Young\'s modulus)', unit: 'Pa', fromZero: false },
  mass: { label: 'mass density', unit: 'kg/m³', fromZero: false },
};

// The range a legend shows for `values` (a Float32Array): [min, max],
// from 0 for fields that start there; a flat field gets a range around
// its value so it maps to the middle colour.
export function fieldRange(name, values) {
  let lo = Infinity;
  let hi = -Infinity;
  for (let i = 0; i < values.length; ++i) {
    const v = values[i];
    if (v < lo) lo = v;
    if (v > hi) hi = v;
  }
  if (!Number.isFinite(lo)) return [0, 1];
  if (FIELDS[name] && FIELDS[name].fromZero) lo = Math.min(0, lo);
  if (hi - lo <= 1e-9 * Math.max(Math.abs(hi), Math.abs(lo), 1e-30)) {
    const pad = Math.abs(hi) * 0.5 || 1;
    return [lo - pad, hi + pad];
  }
  return [lo, hi];
}

// Writes colours (3 per vertex, 0..1) of `values` mapped over `range`.
export function colorize(values, range, out) {
  const [lo, hi] = range;
  const scale = hi > lo ? 1 / (hi - lo) : 0;
  for (let i = 0; i < values.length; ++i) {
    const c = viridis((values[i] - lo) * scale);
    out[3 * i] = c[0];
    out[3 * i + 1] = c[1];
    out[3 * i + 2] = c[2];
  }
}

// A short number for the legend: 3 significant digits, SI exponents.
export function formatValue(v) {
  if (v === 0) return '0';
  const a = Math.abs(v);
  if (a >= 1e-2 && a < 1e5) return Number(v.toPrecision(3)).toString();
  return v.toExponential(2);
}
