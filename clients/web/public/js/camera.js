// The camera's rules, as pure functions on {x, y, z}: view presets (the
// scenes are z-up, the ground at the solid's lowest point), framing a
// bounding sphere, and the orbit kept above the ground plane.

const norm = (v) => {
  const l = Math.hypot(v.x, v.y, v.z) || 1;
  return { x: v.x / l, y: v.y / l, z: v.z / l };
};

// Where each preset looks from (unit vectors from the target to the eye).
// Top looks almost straight down (exactly down has no "up" left).
export const PRESETS = {
  front: norm({ x: 0, y: -1, z: 0.02 }),
  side: norm({ x: 1, y: 0, z: 0.02 }),
  top: norm({ x: 0, y: -1e-3, z: 1 }),
  iso: norm({ x: 0.62, y: -0.95, z: 0.55 }),
};

// The eye at `direction` from a bounding sphere's centre, far enough for
// the sphere to fit a view of vertical field of view `fovDeg` and
// `aspect` (width / height): {eye, target, distance}.
export function frameSphere(center, radius, direction, fovDeg, aspect = 1) {
  const r = Math.max(radius, 1e-3);
  const half = (fovDeg * Math.PI) / 360;
  const halfH = Math.atan(Math.tan(half) * Math.min(aspect, 1));
  const distance = (r / Math.sin(halfH)) * 1.1;
  const d = norm(direction);
  return {
    eye: { x: center.x + d.x * distance, y: center.y + d.y * distance, z: center.z + d.z * distance },
    target: { ...center },
    distance,
  };
}

// The eye and target moved so the target is not under the ground (z <
// groundZ) and the eye stays `margin` above it, at the same distance from
// the target: {eye, target, changed}.
export function aboveGround(eye, target, groundZ, margin) {
  let t = { ...target };
  let e = { ...eye };
  let changed = false;
  if (t.z < groundZ) {
    const dz = groundZ - t.z;
    t.z += dz;
    e.z += dz;
    changed = true;
  }
  const minZ = groundZ + margin;
  if (e.z < minZ) {
    const o = { x: e.x - t.x, y: e.y - t.y, z: e.z - t.z };
    const d = Math.hypot(o.x, o.y, o.z);
    const oz = Math.min(minZ - t.z, d);
    const h = Math.hypot(o.x, o.y);
    const hNew = Math.sqrt(Math.max(d * d - oz * oz, 0));
    const s = h > 1e-12 ? hNew / h : 0;
    e = { x: t.x + o.x * s, y: t.y + o.y * s + (h > 1e-12 ? 0 : -hNew), z: t.z + oz };
    changed = true;
  }
  return { eye: e, target: t, changed };
}
