// Tools sized to the solid: the defaults of the brush radius, pressure,
// extrude distance and spring stiffnesses computed from the solid's size
// (its surface bounds), its control cell size and its stiffness, so that a
// first inflate changes the shape by a few percent and a first extrude is
// about one control cell, on a 3 m rubber block as on a 1.2 m chair.
// Pure functions (the unit tests hold them to block3 and the chair).

// A default inflate strains the softest material by about this much: the
// pressure is this share of its Young's modulus (a half-space under a
// pressed disc of radius r sinks about 1.8 p r / E: 1.8 % of r; at 2 % the
// chair's seat pushed it 13 % of its size, sliding it on its floor).
export const INFLATE_STRAIN = 0.01;

// Rounds to 2 significant digits (0.15, 2000, 1.5e5).
export function round2(v) {
  if (!(v > 0) || !Number.isFinite(v)) return v;
  const e = Math.floor(Math.log10(v)) - 1;
  const m = 10 ** e;
  return Number((Math.round(v / m) * m).toPrecision(2));
}

// A step for a number input holding `v`: a tenth of its leading digit's
// unit (0.15 -> 0.01, 2000 -> 100).
export function stepFor(v) {
  if (!(v > 0) || !Number.isFinite(v)) return 1;
  return Number((10 ** (Math.floor(Math.log10(v)) - 1)).toPrecision(1));
}

// The solid's bounds from surface positions (x, y, z per vertex):
// {min, max, size} with size the largest extent.
export function bounds(positions) {
  const min = [Infinity, Infinity, Infinity];
  const max = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i + 2 < positions.length; i += 3) {
    for (let a = 0; a < 3; ++a) {
      const v = positions[i + a];
      if (v < min[a]) min[a] = v;
      if (v > max[a]) max[a] = v;
    }
  }
  if (!Number.isFinite(min[0])) return null;
  const size = Math.max(max[0] - min[0], max[1] - min[1], max[2] - min[2]);
  return { min, max, size };
}

// The control cell size: the median control edge length of Inspect's
// control_mesh (rest positions), or null without edges.
export function cellSize(mesh) {
  const ev = mesh && mesh.edge_vertices;
  const x = mesh && mesh.rest_positions;
  if (!ev || !x || ev.length < 2) return null;
  const lengths = [];
  for (let e = 0; 2 * e + 1 < ev.length; ++e) {
    const a = 3 * ev[2 * e];
    const b = 3 * ev[2 * e + 1];
    lengths.push(Math.hypot(x[a] - x[b], x[a + 1] - x[b + 1], x[a + 2] - x[b + 2]));
  }
  lengths.sort((p, q) => p - q);
  return lengths[lengths.length >> 1] || null;
}

// Without the control mesh: the edge of a cube holding the bounds' volume
// shared by `cells` cells.
export function cellSizeFromCount(b, cells) {
  const ext = [0, 1, 2].map((a) => Math.max(b.max[a] - b.min[a], b.size * 1e-3));
  return Math.cbrt((ext[0] * ext[1] * ext[2]) / Math.max(cells, 1));
}

// The range of a per-vertex field (the stiffness the watch sends):
// {min, max}, or null when empty.
export function valueRange(values) {
  if (!values || !values.length) return null;
  let min = Infinity;
  let max = -Infinity;
  for (const v of values) {
    if (!(v > 0)) continue;
    if (v < min) min = v;
    if (v > max) max = v;
  }
  return Number.isFinite(min) ? { min, max } : null;
}

const clamp = (v, lo, hi) => Math.min(Math.max(v, lo), hi);

// The tools' defaults for a solid of largest extent `size` (m), control
// cells of edge `cell` (m), Young's modulus `stiffness` ({min, max} Pa, or
// one number) and mass density `density` (kg/m^3). Sized to the softest
// material: a default must not wreck it.
export function sizeTools({ size, cell, stiffness, density = 1000 }) {
  if (!(size > 0) || !(cell > 0)) throw new Error(`sizeTools: size ${size} and cell ${cell} must be > 0`);
  const E = typeof stiffness === 'number' ? stiffness : stiffness && stiffness.min;
  if (!(E > 0)) throw new Error(`sizeTools: stiffness ${E} must be > 0`);
  // One and a half cells, within a twentieth and a quarter of the solid.
  const radius = round2(clamp(1.5 * cell, 0.05 * size, 0.25 * size));
  return {
    radius,
    pinRadius: radius,
    pressure: round2(INFLATE_STRAIN * E),
    extrudeDistance: round2(cell),
    // A spring about half as stiff as the solid under a one-cell grip
    // (E times the cell): the point follows most of the way.
    dragStiffness: round2(0.5 * E * cell),
    curveStiffness: round2(0.2 * E * cell),
    stiffnessValue: round2(10 * E),
    massValue: round2(5 * density),
  };
}

// What `[`/`]` (size) and with shift (strength) change per tool.
export const KNOBS = {
  inflate: { size: 'radius', strength: 'pressure' },
  deflate: { size: 'radius', strength: 'pressure' },
  stiffness: { size: 'radius', strength: 'strength' },
  mass: { size: 'radius', strength: 'strength' },
  material: { size: 'radius', strength: 'strength' },
  pin: { size: 'pinRadius' },
  drag: { strength: 'dragStiffness' },
  curve: { strength: 'curveStiffness' },
  extrude: { size: 'extrudeDistance' },
};

// Each step scales a value by this much (a wheel notch by its square root).
export const STEP_FACTOR = 1.25;

// The parameter `which` ('size' or 'strength') of `tool` changed by
// `steps` (+ bigger, - smaller; fractions for the wheel): {key, value}, or
// null when the tool has no such knob. A tool with one knob changes it
// for either. A brush's strength stays in (0, 1].
export function adjust(params, tool, which, steps) {
  const knobs = KNOBS[tool];
  if (!knobs) return null;
  const key = knobs[which] || knobs.size || knobs.strength;
  const v = params[key];
  if (!(v > 0)) return null;
  let value = Number((v * STEP_FACTOR ** steps).toPrecision(3));
  if (key === 'strength') value = clamp(value, 0.01, 1);
  return { key, value };
}
