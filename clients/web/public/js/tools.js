// The sculpting tools under the pointer: each press picks on the server
// (Pick: the hit's material point, control cell and face) and sends the
// tool's command; drags, pressure and curves last while the button is held.

import * as C from './commands.js';
import { adjust } from './sizing.js';

// Parameters per tool: [key, label, default, step], or for a choice
// [key, label, default, [[value, text], ...]]. The defaults here hold until
// a session's solid is measured: then sizing.js sets the sized ones (radius,
// pressure, distances, stiffnesses) for that solid.
export const PARAMS = {
  drag: [['dragStiffness', 'stiffness (N/m)', 5e4, 1e4]],
  inflate: [['pressure', 'pressure (Pa)', 3000, 500], ['radius', 'radius (m)', 0.8, 0.1]],
  deflate: [['pressure', 'pressure (Pa)', 3000, 500], ['radius', 'radius (m)', 0.8, 0.1]],
  stiffness: [['radius', 'radius (m)', 0.8, 0.1], ['strength', 'strength', 1, 0.05],
    ['falloff', 'falloff', 0.25, 0.05], ['stiffnessValue', 'value (Pa)', 1e6, 1e5]],
  mass: [['radius', 'radius (m)', 0.8, 0.1], ['strength', 'strength', 1, 0.05],
    ['falloff', 'falloff', 0.25, 0.05], ['massValue', 'value (kg/m³)', 5000, 500]],
  material: [['radius', 'radius (m)', 0.8, 0.1], ['strength', 'strength', 1, 0.05],
    ['falloff', 'falloff', 0.25, 0.05],
    ['preset', 'material', 'CLAY', [['RUBBER', 'Rubber'], ['CLAY', 'Clay'], ['WAX', 'Wax']]]],
  pin: [['pinRadius', 'radius (m)', 0.8, 0.1]],
  curve: [['curveStiffness', 'stiffness (N/m)', 2e4, 5e3]],
  extrude: [['extrudeDistance', 'distance (m)', 0.8, 0.1], ['extrudeLayers', 'layers', 1, 1]],
};

const MOVE_INTERVAL_MS = 1000 / 120;  // at most 120 target updates a second
const DAB_INTERVAL_MS = 40;
const BRUSHES = ['stiffness', 'mass', 'material'];
// The field a brush paints, shown while painting (the material brush's
// presets change the stiffness).
const PAINTED_FIELD = { stiffness: 'stiffness', mass: 'mass', material: 'stiffness' };

export class Tools {
  constructor(app) {
    this.app = app;
    this.tool = 'view';
    this.params = {};
    for (const list of Object.values(PARAMS)) for (const [k, , d] of list) this.params[k] = d;
    this.active = null;       // the press in progress
    this.curvePoints = [];    // [{material, point}] picked for a curve
    this.mergeFirst = null;   // {face, cell}
    this.roundTrips = [];     // drag round trips waiting for their frame
    this.touched = new Set(); // parameters the person set since joining (sizing leaves them)
  }

  // Sets the sized defaults ({key: value}) the person has not set since
  // joining; returns the keys set.
  applySizing(sized) {
    const set = [];
    for (const [k, v] of Object.entries(sized)) {
      if (this.touched.has(k) || !(k in this.params)) continue;
      this.params[k] = v;
      set.push(k);
    }
    return set;
  }

  // `[`/`]` (which = 'size'), with shift ('strength'), and the wheel with
  // a modifier: the tool's knob scaled by `steps` (sizing.js adjust);
  // returns {key, value} or null.
  nudge(which, steps) {
    const a = adjust(this.params, this.tool, which, steps);
    if (!a) return null;
    this.params[a.key] = a.value;
    this.touched.add(a.key);
    return a;
  }

  get view() { return this.app.view; }
  get conn() { return this.app.conn; }

  setTool(tool) {
    this.cancel();
    this.tool = tool;
    this.mergeFirst = null;
    if (tool !== 'curve') this.curvePoints = [];
    this.app.onToolChanged();
  }

  cancel() {
    this.curvePoints = [];
    this.mergeFirst = null;
    this.app.refreshMarkers();
    if (this.app.faceHover) this.app.faceHover.draw();
  }

  brushRadius() {
    if (['inflate', 'deflate', ...BRUSHES].includes(this.tool)) return this.params.radius;
    if (this.tool === 'pin') return this.params.pinRadius;
    return this.app.scale * 0.02;
  }

  async pick(clientX, clientY) {
    const ray = this.view.ray(clientX, clientY);
    const reply = await this.conn.call('Pick', { session: this.app.session, origin: ray.origin,
      direction: ray.direction });
    if (!reply.hit) this.app.noSolid(clientX, clientY);
    return reply.hit ? reply : null;
  }

  // The world point under the pointer on the plane through `p`, facing
  // the camera, pushed along the view by `depth`.
  planePoint(e, p, depth = 0) {
    const ray = this.view.ray(e.clientX, e.clientY);
    const d = this.view.viewDirection();
    const q = C.rayPlane(ray.origin, ray.direction, p, d);
    if (!q) return null;
    return { x: q.x + depth * d.x, y: q.y + depth * d.y, z: q.z + depth * d.z };
  }

  // Whether a press is a tool's left press that misses the solid: it does
  // nothing (no orbit) and says so. Alt+left orbits in any tool.
  missesSolid(e) {
    return this.tool !== 'view' && Boolean(this.app.session) && e.button === 0 && !e.altKey &&
      !this.wantsPress(e);
  }

  // Whether a press at (x, y) starts this tool (else the view orbits).
  wantsPress(e) {
    if (this.tool === 'view' || !this.app.session || e.button !== 0 || e.altKey) return false;
    if (this.tool === 'curve' && this.curveHandleAt(e) >= 0) return true;
    return this.view.localHit(e.clientX, e.clientY) !== null;
  }

  curveHandleAt(e) {
    if (this.curvePoints.length < 2) return -1;
    for (let i = 0; i < this.curvePoints.length; ++i) {
      const s = this.view.project(this.curvePoints[i].point);
      if (Math.hypot(s.x - e.clientX, s.y - e.clientY) < 14) return i;
    }
    return -1;
  }

  async down(e) {
    const press = { x: e.clientX, y: e.clientY, last: e, done: false, depth: 0 };
    this.active = press;
    try {
      switch (this.tool) {
        case 'drag': return await this.startDrag(press);
        case 'inflate': case 'deflate': return await this.startPressure(press);
        case 'stiffness': case 'mass': case 'material': return await this.dab(press);
        case 'curve': return await this.curveDown(press);
        default: return await this.click(press);
      }
    } catch (err) {
      this.app.showError(err);
    }
  }

  move(e) {
    const press = this.active;
    // The disc follows the pointer, also along a brush's stroke.
    if (!press || BRUSHES.includes(this.tool)) this.showCursorAt(e.clientX, e.clientY);
    if (!press) {
      this.app.faceHover.move(e.clientX, e.clientY);
      return;
    }
    press.last = e;
    if (press.onMove) press.onMove(e);
  }

  showCursorAt(x, y) {
    const hit = this.tool !== 'view' && this.app.session ? this.view.localHit(x, y) : null;
    this.view.showCursor(hit, this.brushRadius());
  }

  wheel(e) {
    const press = this.active;
    if (!press || !press.onMove) return false;
    press.depth += (e.deltaY > 0 ? 1 : -1) * this.app.scale * 0.05;
    press.onMove(press.last);
    return true;
  }

  async up() {
    const press = this.active;
    this.active = null;
    if (!press) return;
    press.done = true;
    if (press.onUp) {
      try {
        await press.onUp();
      } catch (err) {
        this.app.showError(err);
      }
    }
  }

  // A load held while the button is: its id, then moves, then removal.
  holdLoad(press, commandPromise, moveCommand) {
    let loadId = null;
    let timer = null;
    let wanted = null;
    const flush = () => {
      timer = null;
      if (loadId === null || wanted === null || press.done) return;
      const t0 = performance.now();
      const sent = this.conn.command(moveCommand(loadId, wanted));
      wanted = null;
      sent.then((reply) => this.roundTrips.push({ t0, step: reply.applied_step }),
        (err) => this.app.showError(err));
    };
    press.onMove = (e) => {
      wanted = e;
      if (!timer) timer = setTimeout(flush, MOVE_INTERVAL_MS);
    };
    press.onUp = async () => {
      clearTimeout(timer);
      const reply = await commandPromise;
      if (reply) await this.conn.command(C.removeLoad(reply.load_id));
    };
    // Released before the pick and the command came back: let go now.
    if (press.done) press.onUp().catch((err) => this.app.showError(err));
    return commandPromise.then((reply) => {
      loadId = reply.load_id;
      if (press.done) return;
      if (wanted && !timer) timer = setTimeout(flush, MOVE_INTERVAL_MS);
    });
  }

  async startDrag(press) {
    const hit = await this.pick(press.x, press.y);
    if (!hit) return;
    const origin = hit.point;
    const cmd = this.conn.command(C.drag(hit.material_point, origin, this.params.dragStiffness));
    cmd.catch(() => {});
    await this.holdLoad(press, cmd, (id, e) => C.moveDrag(id, this.planePoint(e, origin, press.depth) || origin));
  }

  async startPressure(press) {
    const hit = await this.pick(press.x, press.y);
    if (!hit) return;
    const sign = this.tool === 'inflate' ? 1 : -1;
    // Held and let go: one action for undo (Command.gesture), which leaves
    // no pressure behind that nobody holds.
    const gesture = this.nextGesture();
    const cmd = this.conn.command({ ...C.pressure(hit.material_point, this.params.radius,
      sign * this.params.pressure), gesture });
    cmd.catch(() => {});
    press.onUp = async () => {
      const reply = await cmd;
      await this.conn.command({ ...C.removeLoad(reply.load_id), gesture });
    };
    if (press.done) press.onUp().catch((err) => this.app.showError(err));
    await cmd;
  }

  // Brush: a dab at the press, then one per DAB_INTERVAL_MS while moving,
  // never more than one in flight (the server's answer paces the brush).
  async dab(press) {
    const tool = this.tool;
    let busy = false;
    let moved = false;
    // The stroke's dabs are one action for undo (Command.gesture).
    const gesture = this.nextGesture();
    const once = async (x, y) => {
      busy = true;
      try {
        const hit = await this.pick(x, y);
        if (hit) await this.conn.command({ ...this.brushCommand(tool, hit.material_point), gesture });
      } finally {
        busy = false;
      }
    };
    press.onMove = () => { moved = true; };
    this.app.showField(PAINTED_FIELD[tool]);
    await once(press.x, press.y);
    while (!press.done) {
      await new Promise((r) => setTimeout(r, DAB_INTERVAL_MS));
      if (moved && !busy && !press.done) {
        moved = false;
        await once(press.last.clientX, press.last.clientY);
      }
    }
  }

  // A new gesture id (Command.gesture: this page's consecutive commands with
  // the same id are one entry of its undo history).
  nextGesture() {
    this.gestures = (this.gestures || 0) + 1;
    return this.gestures;
  }

  // A dab of brush `tool` at a material point, with the panel's parameters.
  brushCommand(tool, materialPoint) {
    const p = this.params;
    const brush = { radius: p.radius, strength: p.strength, falloff: p.falloff };
    if (tool === 'material') return C.paintPreset(materialPoint, { ...brush, preset: p.preset });
    const value = { stiffness: p.stiffnessValue, mass: p.massValue }[tool];
    return C.paint(tool, materialPoint, { ...brush, value });
  }

  async curveDown(press) {
    const handle = this.curveHandleAt(press.last);
    if (handle < 0) {
      const hit = await this.pick(press.x, press.y);
      if (!hit) return;
      this.curvePoints.push({ material: hit.material_point, point: hit.point });
      this.app.message(`curve: ${this.curvePoints.length} point(s); drag a point to bend (Esc clears)`);
      this.app.refreshMarkers();
      return;
    }
    const pts = this.curvePoints;
    const anchor = pts[handle].point;
    const cmd = this.conn.command(C.curve(pts.map((p) => p.material), pts.map((p) => p.point),
      this.params.curveStiffness));
    cmd.catch(() => {});
    await this.holdLoad(press, cmd, (id, e) => {
      const q = this.planePoint(e, anchor, press.depth) || anchor;
      const d = { x: q.x - anchor.x, y: q.y - anchor.y, z: q.z - anchor.z };
      return C.moveCurve(id, pts.map((p) => ({ x: p.point.x + d.x, y: p.point.y + d.y, z: p.point.z + d.z })));
    });
    const up = press.onUp;
    press.onUp = async () => {
      await up();
      this.curvePoints = [];
      this.app.refreshMarkers();
    };
  }

  // One-click tools: pin, unpin and the topology edits.
  async click(press) {
    const hit = await this.pick(press.x, press.y);
    if (!hit) return;
    const p = this.params;
    switch (this.tool) {
      case 'pin':
        await this.conn.command(C.pin(hit.material_point, p.pinRadius));
        break;
      case 'unpin': {
        const c = this.app.nearestConstraint(hit.material_point);
        if (!c) throw new Error('unpin: no pin under the cursor');
        await this.conn.command(C.unpin(c.id));
        break;
      }
      case 'delete':
        await this.edit(C.deleteCell(hit.control_cell), `delete cell ${hit.control_cell}`);
        break;
      case 'extrude':
        await this.edit(C.extrudeFace(hit.control_face, p.extrudeDistance, Math.round(p.extrudeLayers)),
          `extrude face ${hit.control_face}`);
        break;
      case 'subdivide':
        await this.edit(C.subdivideCell(hit.control_cell), `subdivide cell ${hit.control_cell}`);
        break;
      case 'merge':
        if (!this.mergeFirst) {
          this.mergeFirst = { face: hit.control_face };
          this.app.faceHover.clear();  // drawn as the chosen face now
          this.app.message(`merge: face ${hit.control_face} chosen; click the face to join it to`);
          return;
        } else {
          const a = this.mergeFirst.face;
          this.mergeFirst = null;
          await this.edit(C.mergeFaces(a, hit.control_face), `merge faces ${a} and ${hit.control_face}`);
        }
        break;
      case 'sharp': {
        const mesh = await this.app.controlMesh();
        const edge = C.nearestFaceEdge(mesh, hit.control_face, hit.material_point);
        if (!edge) throw new Error(`sharp: no control edge found on face ${hit.control_face}`);
        await this.edit(C.sharpEdge(edge.v0, edge.v1, !edge.sharp),
          `${edge.sharp ? 'unsharp' : 'sharp'} edge ${edge.v0}-${edge.v1}`);
        break;
      }
      default:
        break;
    }
  }

  // A topology edit or a bake: the solid is rebuilt on the server, shown
  // as "building…" with the seconds so far until the answer.
  async edit(command, what) {
    this.app.faceHover.clear();
    this.app.feedback.progress(`${what}: building…`);
    let reply;
    try {
      reply = await this.conn.command(command);
    } finally {
      this.app.feedback.stopProgress();
    }
    const e = reply.edit || {};
    const text = e.summary || `${e.control_cells_before} → ${e.control_cells_after} control cells`;
    this.app.message(`${what}: ${text}` + (reply.hold_ms ? `, ${reply.hold_ms.toFixed(0)} ms` : ''));
  }

  // Called after a frame is drawn: drag round trips whose command's step
  // this frame shows (pointer move -> first frame at or after the step the
  // server applied it at + 1).
  framesShown(step, now) {
    const done = [];
    this.roundTrips = this.roundTrips.filter((r) => {
      if (step > r.step) {
        done.push(now - r.t0);
        return false;
      }
      return true;
    });
    return done;
  }
}
