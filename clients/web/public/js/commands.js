// The viewer's tools as dynsolid.Command messages (JSON, field names as in
// proto/dynsolid/*.proto). Pure functions: the app calls them with what a
// pick returned and the side panel's parameters; the unit tests check them.

const vec = (p) => ({ x: p.x, y: p.y, z: p.z });

function finite(name, ...values) {
  for (const v of values) {
    if (!Number.isFinite(v)) throw new Error(`${name}: must be a finite number, got ${v}`);
  }
}

function positive(name, v) {
  finite(name, v);
  if (!(v > 0)) throw new Error(`${name}: must be > 0, got ${v}`);
}

export function sphere(center, radius) {
  positive('radius', radius);
  return { sphere: { center: vec(center), radius } };
}

// Pull and push: a spring from the picked material point to `target`.
export function drag(materialPoint, target, stiffness) {
  positive('drag stiffness', stiffness);
  return { drag: { material_point: vec(materialPoint), target: vec(target), stiffness } };
}

export function moveDrag(loadId, target) {
  return { move_drag: { load_id: loadId, target: vec(target) } };
}

export function moveCurve(loadId, targets) {
  return { move_drag: { load_id: loadId, targets: targets.map(vec) } };
}

export function curve(materialPoints, targets, stiffness, samples = 0) {
  if (materialPoints.length < 2) throw new Error('curve: needs at least 2 points on the solid');
  if (targets.length !== materialPoints.length) {
    throw new Error(`curve: ${targets.length} targets for ${materialPoints.length} points`);
  }
  positive('curve stiffness', stiffness);
  return {
    curve: { material_points: materialPoints.map(vec), targets: targets.map(vec), stiffness, samples },
  };
}

export function removeLoad(loadId) {
  return { remove_load: { load_id: loadId } };
}

// Inflate (pascals > 0) or deflate (< 0) the boundary within `radius` of a
// material point.
export function pressure(materialPoint, radius, pascals) {
  finite('pressure', pascals);
  if (pascals === 0) throw new Error('pressure: must not be 0');
  return { add_pressure: { region: sphere(materialPoint, radius), pascals } };
}

// A dab of the stiffness, mass or damping brush. `field`: 'stiffness'
// (young_modulus, Pa), 'mass' (density, kg/m^3) or 'damping' (kg/(m^3 s)).
export function paint(field, materialPoint, { radius, strength, falloff, value }) {
  const key = { stiffness: 'young_modulus', mass: 'density', damping: 'damping' }[field];
  if (!key) throw new Error(`paint: unknown field ${field}`);
  positive(`${field} value`, value);
  return brushDab(materialPoint, { [key]: value }, radius, strength, falloff);
}

// The material brush's presets (scene.proto Material.Preset): rubber never
// yields; clay yields (what you pull stays); wax is stiffer clay.
export const PRESETS = ['RUBBER', 'CLAY', 'WAX'];

// A dab of the material brush: paints a whole preset.
export function paintPreset(materialPoint, { radius, strength, falloff, preset }) {
  if (!PRESETS.includes(preset)) throw new Error(`paint: unknown preset ${preset}`);
  return brushDab(materialPoint, { preset }, radius, strength, falloff);
}

function brushDab(materialPoint, material, radius, strength, falloff) {
  finite('strength', strength);
  if (!(strength > 0 && strength <= 1)) throw new Error(`strength: must be in (0, 1], got ${strength}`);
  finite('falloff', falloff);
  if (!(falloff >= 0 && falloff <= 1)) throw new Error(`falloff: must be in [0, 1], got ${falloff}`);
  return { paint_material: { region: sphere(materialPoint, radius), material, strength, falloff } };
}

export function pin(materialPoint, radius) {
  return { fix_region: sphere(materialPoint, radius) };
}

export function unpin(constraintId) {
  return { unfix: { constraint_id: constraintId } };
}

export function deleteCell(cell) {
  return { edit: { delete_cells: { cells: [cell] } } };
}

export function extrudeFace(face, distance, layers = 1) {
  positive('extrude distance', distance);
  return { edit: { extrude_faces: { faces: [face], distance, layers } } };
}

export function mergeFaces(faceA, faceB) {
  if (faceA === faceB) throw new Error(`merge: face ${faceA} with itself; pick two faces`);
  return { edit: { merge_faces: { face_a: faceA, face_b: faceB } } };
}

export function subdivideCell(cell) {
  return { edit: { subdivide_cells: { cells: [cell] } } };
}

export function sharpEdge(v0, v1, sharp) {
  return { edit: { sharp_edges: { edges: [{ v0, v1 }], sharp } } };
}

// The solid's current shape becomes its rest shape (the server fills in
// rest_positions).
export const bake = () => ({ edit: { bake: {} } });

// The whole session back to the scene it was created from (undoable by
// the sender).
export const revertToScene = () => ({ revert_to_scene: {} });

export const undo = () => ({ undo: {} });
export const redo = () => ({ redo: {} });
export const pause = () => ({ pause: {} });
export const resume = () => ({ resume: {} });
export const step = (count = 1) => ({ step: { count } });

// The control edge of boundary face `face` nearest the rest-space point
// `p` (a pick's material point), from Inspect's control_mesh: {v0, v1,
// sharp} or null.
export function nearestFaceEdge(mesh, face, p) {
  if (!mesh || face < 0 || face + 1 >= mesh.face_offsets.length) return null;
  const verts = mesh.face_vertices.slice(mesh.face_offsets[face], mesh.face_offsets[face + 1]);
  const x = (v) => [mesh.rest_positions[3 * v], mesh.rest_positions[3 * v + 1],
    mesh.rest_positions[3 * v + 2]];
  let best = null;
  for (let i = 0; i < verts.length; ++i) {
    const a = x(verts[i]);
    const b = x(verts[(i + 1) % verts.length]);
    const d = distanceToSegment([p.x, p.y, p.z], a, b);
    if (!best || d < best.d) best = { v0: verts[i], v1: verts[(i + 1) % verts.length], d };
  }
  if (!best) return null;
  const sharp = edgeSharp(mesh, best.v0, best.v1);
  return { v0: best.v0, v1: best.v1, sharp };
}

function edgeSharp(mesh, a, b) {
  const ev = mesh.edge_vertices || [];
  for (let e = 0; 2 * e + 1 < ev.length; ++e) {
    if ((ev[2 * e] === a && ev[2 * e + 1] === b) || (ev[2 * e] === b && ev[2 * e + 1] === a)) {
      return Boolean((mesh.edge_sharp || [])[e]);
    }
  }
  return false;
}

export function distanceToSegment(p, a, b) {
  const ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
  const ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
  const len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
  let t = len2 > 0 ? (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2 : 0;
  t = Math.max(0, Math.min(1, t));
  const d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
  return Math.hypot(d[0], d[1], d[2]);
}

// A point where the ray (origin o, unit direction d) meets the plane
// through `p` with normal `n`; null when parallel.
export function rayPlane(o, d, p, n) {
  const denom = d.x * n.x + d.y * n.y + d.z * n.z;
  if (Math.abs(denom) < 1e-12) return null;
  const t = ((p.x - o.x) * n.x + (p.y - o.y) * n.y + (p.z - o.z) * n.z) / denom;
  return { x: o.x + t * d.x, y: o.y + t * d.y, z: o.z + t * d.z };
}
