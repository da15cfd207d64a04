// The cut-away (the paper's Fig. 13): a plane the user moves through the
// solid; the surface is clipped on the near side and the server's Section
// (solver/export/section.h) is drawn where the plane cuts, coloured by
// strain, displacement, stiffness or element distortion. The helpers at the
// top are pure (tested in Node: test/unit/cutaway.test.js); CutAway binds
// them to the page.

import { colorize, fieldRange, formatValue } from './colormap.js';
import { bounds } from './sizing.js';

export const SECTION_FIELDS = [
  { key: 'strain', label: 'strain', what: 'the largest stretch between two corners of each cell' },
  { key: 'displacement', label: 'displacement', what: 'how far each point moved, metres' },
  { key: 'stiffness', label: 'stiffness', what: 'Young\'s modulus as painted, Pa' },
  { key: 'distortion', label: 'distortion', what: 'how far each cell is from a scaled copy of its rest shape, 0 to 1' },
];

const AXES = { x: 0, y: 1, z: 2 };

// The plane across `bounds` ({min, max}) along `axis` ('x', 'y' or 'z') at
// fraction t in [0, 1], its normal towards `eye` (the camera's position:
// the near half is cut away, so the section faces the viewer).
export function cutPlane(axis, t, bounds, eye) {
  const a = AXES[axis] ?? 0;
  const f = Math.min(1, Math.max(0, Number.isFinite(t) ? t : 0.5));
  const point = [0, 1, 2].map((k) => 0.5 * (bounds.min[k] + bounds.max[k]));
  point[a] = bounds.min[a] + f * (bounds.max[a] - bounds.min[a]);
  const normal = [0, 0, 0];
  normal[a] = eye && eye[a] < point[a] ? -1 : 1;
  return {
    point: { x: point[0], y: point[1], z: point[2] },
    normal: { x: normal[0], y: normal[1], z: normal[2] },
  };
}

// Vertex colours (3 per value) of a SectionReply's values over its range,
// and the range a legend shows.
export function sectionColors(field, values) {
  const v = Float32Array.from(values || []);
  const range = fieldRange(field === 'distortion' ? 'strain' : field, v);
  const out = new Float32Array(3 * v.length);
  colorize(v, range, out);
  return { colors: out, range };
}

// The line under the controls: "strain 0 – 0.12 · 214 cells cut".
export function sectionText(reply) {
  if (!reply) return '';
  if (!reply.values || reply.values.length === 0) return 'the plane misses the solid';
  const unit = reply.unit && reply.unit !== '1' ? ` ${reply.unit}` : '';
  return `${reply.field} ${formatValue(reply.min)} – ${formatValue(reply.max)}${unit} · ` +
    `${reply.cells_cut} cells cut (step ${reply.step})`;
}

const $ = (id) => document.getElementById(id);

export class CutAway {
  constructor(app) {
    this.app = app;
    this.on = false;
    this.inFlight = false;
    this.again = false;
    this.lastStep = -1;
    this.reply = null;
    const field = $('cut-field');
    for (const f of SECTION_FIELDS) {
      const o = new Option(f.label, f.key);
      o.title = f.what;
      field.add(o);
    }
    $('cutaway').onchange = () => this.toggle($('cutaway').checked);
    for (const id of ['cut-axis', 'cut-pos', 'cut-field']) {
      $(id).oninput = () => this.request();
    }
    setInterval(() => this.poll(), 300);
  }

  toggle(on) {
    this.on = on;
    $('cut-controls').hidden = !on;
    if (!on) {
      this.app.view.setSection(null);
      this.reply = null;
      $('cut-status').textContent = '';
      this.app.metrics.section = null;
      return;
    }
    this.request();
  }

  // Again while the solid moves (a new step since the last cut).
  poll() {
    if (!this.on || !this.app.session) return;
    const step = this.app.decoder && this.app.decoder.step !== undefined ? this.app.decoder.step : -1;
    if (step !== this.lastStep) this.request();
  }

  plane() {
    const b = this.app.decoder && this.app.decoder.positions ? bounds(this.app.decoder.positions) : null;
    if (!b) return null;
    const c = this.app.view.camera.position;
    return cutPlane($('cut-axis').value, Number($('cut-pos').value) / 100, b, [c.x, c.y, c.z]);
  }

  async request() {
    if (!this.on || !this.app.session) return;
    if (this.inFlight) {
      this.again = true;
      return;
    }
    const plane = this.plane();
    if (!plane) return;
    this.inFlight = true;
    const field = $('cut-field').value;
    try {
      const reply = await this.app.conn.call('Section', { session: this.app.session, point: plane.point,
        normal: plane.normal, field });
      if (!this.on) return;
      this.reply = reply;
      this.lastStep = Number(reply.step);
      const { colors, range } = sectionColors(field, reply.values);
      this.app.view.setSection({ plane, positions: Float32Array.from(reply.positions || []), colors });
      $('cut-status').textContent = sectionText(reply);
      this.app.metrics.section = { field, triangles: (reply.values || []).length / 3, range,
        cells_cut: reply.cells_cut, normal: plane.normal, point: plane.point };
    } catch (err) {
      $('cut-status').textContent = `cut-away: ${err.message}`;
    } finally {
      this.inFlight = false;
      if (this.again) {
        this.again = false;
        this.request();
      }
    }
  }
}
