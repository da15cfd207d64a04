// Extrude and Merge show, under the pointer, the control face they would
// take: the server's Pick names the boundary control face under the
// pointer, Inspect gives the control mesh (its faces) and the control
// points' current positions; the face is drawn there, filled, over the
// surface (view.showFaces). Green: the tool takes it; red: it does not,
// with the reason by the pointer. Merge's first face stays drawn (blue)
// until the second is clicked.

// The vertex ids of face `face` of a ControlMeshInfo, or null.
export function faceLoop(mesh, face) {
  if (!mesh || !mesh.face_offsets || face < 0 || face + 1 >= mesh.face_offsets.length) return null;
  return mesh.face_vertices.slice(mesh.face_offsets[face], mesh.face_offsets[face + 1]);
}

// Whether face `face` is on the boundary (its second cell is -1).
export function isBoundaryFace(mesh, face) {
  const cells = mesh && mesh.face_cells;
  return Boolean(cells && 2 * face + 1 < cells.length && cells[2 * face + 1] === -1);
}

// Whether `tool` ('extrude' or 'merge') takes face `face` of `mesh`, given
// merge's first face `first` (or null): {ok, why}. What the server checks
// before the solid is rebuilt (scene.proto ExtrudeFaces, MergeFaces):
// boundary faces, for a merge two different ones with as many corners.
export function faceAccepted(tool, mesh, face, first = null) {
  const loop = faceLoop(mesh, face);
  if (!loop) return { ok: false, why: 'no control face here' };
  if (!isBoundaryFace(mesh, face)) return { ok: false, why: 'an inner face: only faces on the surface can be taken' };
  if (tool !== 'merge' || first === null || first === undefined) return { ok: true, why: '' };
  if (face === first) return { ok: false, why: 'the face already chosen: pick another one to join it to' };
  const a = faceLoop(mesh, first);
  if (a && a.length !== loop.length) {
    return { ok: false, why: `${loop.length} corners; the first face has ${a.length}: merge joins faces with as many corners` };
  }
  return { ok: true, why: '' };
}

// The face's corners at the control points' positions (x, y, z per
// control point), as [{x, y, z}, ...], or null.
export function facePoints(mesh, positions, face) {
  const loop = faceLoop(mesh, face);
  if (!loop || !positions) return null;
  const pts = [];
  for (const v of loop) {
    if (3 * v + 2 >= positions.length) return null;
    pts.push({ x: positions[3 * v], y: positions[3 * v + 1], z: positions[3 * v + 2] });
  }
  return pts;
}

export const HOVER_TOOLS = ['extrude', 'merge'];
const POSITIONS_MAX_AGE_MS = 300;

export class FaceHover {
  constructor(app) {
    this.app = app;
    this.face = null;         // the face under the pointer: {face, ok, why} or null
    this.busy = false;
    this.pending = null;      // the latest pointer position not yet looked up
    this.positionsAt = -Infinity;
    this.serial = 0;          // bumped by clear(): answers from before are dropped
  }

  get active() {
    return HOVER_TOOLS.includes(this.app.tools.tool) && Boolean(this.app.session);
  }

  // The pointer moved to client (x, y).
  move(x, y) {
    if (!this.active) return;
    if (!this.app.view.localHit(x, y)) {
      this.set(null);
      return;
    }
    this.pending = { x, y };
    if (!this.busy) this.run();
  }

  async run() {
    this.busy = true;
    try {
      while (this.pending) {
        const { x, y } = this.pending;
        this.pending = null;
        await this.lookUp(x, y);
      }
    } catch (err) {
      // A lost server shows in the status line; the highlight just goes.
      this.set(null);
    } finally {
      this.busy = false;
    }
  }

  async lookUp(x, y) {
    const serial = this.serial;
    const app = this.app;
    const ray = app.view.ray(x, y);
    const hit = await app.conn.call('Pick', { session: app.session, origin: ray.origin, direction: ray.direction });
    if (serial !== this.serial || !this.active) return;
    if (!hit.hit || hit.control_face < 0) {
      this.set(null);
      return;
    }
    // The control mesh of this topology; the control points' positions
    // fresh enough to draw the face where it is now.
    const stale = app.meshStale();
    if (stale || performance.now() - this.positionsAt > POSITIONS_MAX_AGE_MS) {
      await app.inspectOverlays({ mesh: stale, positions: true, loads: false });
      this.positionsAt = performance.now();
    }
    if (serial !== this.serial || !this.active) return;
    const first = app.tools.mergeFirst ? app.tools.mergeFirst.face : null;
    const verdict = faceAccepted(app.tools.tool, app.inspect.mesh, hit.control_face, app.tools.tool === 'merge' ? first : null);
    this.set({ face: hit.control_face, ...verdict }, x, y);
  }

  set(face, x, y) {
    const before = this.face;
    this.face = face;
    if (face && !face.ok && (!before || before.face !== face.face)) {
      this.app.feedback.hud(`${this.app.tools.tool}: ${face.why}`, x, y, 2500);
    }
    this.draw();
  }

  // Forgets the face under the pointer (a tool change, an edit).
  clear() {
    this.serial++;
    this.pending = null;
    this.face = null;
    this.draw();
  }

  draw() {
    const app = this.app;
    const mesh = app.inspect.mesh;
    const pos = app.inspect.positions;
    const faces = [];
    const first = app.tools.tool === 'merge' && app.tools.mergeFirst ? app.tools.mergeFirst.face : null;
    // The chosen face under the pointer again shows as refused only.
    const refusedFirst = this.face && this.face.face === first && !this.face.ok;
    if (first !== null && !refusedFirst) {
      const pts = facePoints(mesh, pos, first);
      if (pts) faces.push({ points: pts, kind: 'chosen' });
    }
    if (this.face && (this.face.face !== first || !this.face.ok)) {
      const pts = facePoints(mesh, pos, this.face.face);
      if (pts) faces.push({ points: pts, kind: this.face.ok ? 'ok' : 'refused' });
    }
    app.view.showFaces(faces);
  }
}
