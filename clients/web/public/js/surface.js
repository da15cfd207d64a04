// The watched boundary surface in the page: rebuilds positions from a Watch
// stream's keyframes and quantized deltas (service.proto "Watch"), like the
// C++ client library's SurfaceDecoder, written from the same documented
// wire format. Shared test vectors written by the C++ tests (the server's
// encoder, the C++ decoder's answers) hold the two together
// (test/unit/surface.test.js).

import { parseFrame, FIELD_NAMES } from './wire.js';

export class FrameError extends Error {
  // kind: 'invalid' (a malformed frame) or 'precondition' (a delta that
  // does not follow the frames applied: ask for a new stream).
  constructor(kind, message) {
    super(message);
    this.kind = kind;
  }
}

const invalid = (m) => new FrameError('invalid', m);

function checkFields(fields, count, where) {
  for (const name of FIELD_NAMES) {
    const size = fields[name].length;
    if (size !== 0 && size !== count) {
      throw invalid(`${where}.fields.${name}: ${size} values for ${count} vertices`);
    }
  }
}

export class SurfaceDecoder {
  constructor() {
    this.reset();
  }

  reset() {
    this.hasKeyframe = false;
    this.step = -1;
    this.time = 0;
    this.topologyVersion = 0;
    this.vertexCount = 0;
    this.quads = new Int32Array(0);
    this.nodes = new Int32Array(0);
    this.codes = new Uint16Array(0);
    this.origin = [0, 0, 0];
    this.gridStep = [0, 0, 0];
    this.errorBound = [0, 0, 0];
    // Float64, 3 per vertex (the renderer converts).
    this.positions = new Float64Array(0);
    // name -> Float32Array (one per vertex) or null when absent.
    this.fields = { displacement: null, strain: null, stiffness: null, mass: null };
    // What the last frame changed: 'keyframe', 'topology' (a keyframe with
    // new quads), or the listed vertex indices of a delta.
    this.lastChange = null;
    // Counts topology changes (new quads): a view that draws less often
    // than frames arrive compares it to know when to rebuild its mesh.
    this.topologySerial = (this.topologySerial || 0) + 1;
    this.lastSkipped = 0;
    this.lastRice = false;
    this.lastMoved = 0;
  }

  // Applies one frame, given as bytes (the gateway's binary message) or as
  // an already parsed frame. On error nothing changes; throws FrameError.
  apply(frameOrBytes) {
    let frame = frameOrBytes;
    if (frameOrBytes instanceof Uint8Array) {
      try {
        frame = parseFrame(frameOrBytes);
      } catch (e) {
        throw invalid(`frame: ${e.message}`);
      }
    }
    if (frame.keyframe) this.applyKeyframe(frame);
    else if (frame.delta) this.applyDelta(frame);
    else throw invalid(`frame at step ${frame.step}: neither keyframe nor delta`);
    this.lastSkipped = frame.skipped;
    return frame;
  }

  applyKeyframe(frame) {
    const k = frame.keyframe;
    const n = k.vertex_count;
    if (n < 0) throw invalid(`keyframe.vertex_count: ${n} is negative`);
    if (k.quads.length % 4 !== 0) {
      throw invalid(`keyframe.quads: ${k.quads.length} indices, not a multiple of 4`);
    }
    for (let i = 0; i < k.quads.length; ++i) {
      if (k.quads[i] < 0 || k.quads[i] >= n) {
        throw invalid(`keyframe.quads[${i}]: vertex ${k.quads[i]} outside [0, ${n})`);
      }
    }
    if (k.codes.length !== 6 * n) {
      throw invalid(`keyframe.codes: ${k.codes.length} bytes for ${n} vertices (6 each)`);
    }
    if (k.nodes.length !== 0 && k.nodes.length !== n) {
      throw invalid(`keyframe.nodes: ${k.nodes.length} for ${n} vertices`);
    }
    const origin = [k.grid.origin.x, k.grid.origin.y, k.grid.origin.z];
    const step = [k.grid.step.x, k.grid.step.y, k.grid.step.z];
    for (let a = 0; a < 3; ++a) {
      if (!Number.isFinite(origin[a]) || !Number.isFinite(step[a]) || step[a] <= 0) {
        throw invalid(`keyframe.grid: origin ${origin[a]} / step ${step[a]} on axis ${a} ` +
                      '(steps must be finite and > 0)');
      }
    }
    checkFields(k.fields, n, 'keyframe');

    const codes = new Uint16Array(3 * n);
    for (let i = 0; i < 3 * n; ++i) codes[i] = k.codes[2 * i] | (k.codes[2 * i + 1] << 8);
    const topologyChanged = !this.hasKeyframe || k.topology_version !== this.topologyVersion ||
        n !== this.vertexCount || !sameInts(this.quads, k.quads);
    this.codes = codes;
    this.origin = origin;
    this.gridStep = step;
    this.hasKeyframe = true;
    this.step = frame.step;
    this.time = frame.time;
    this.topologyVersion = k.topology_version;
    this.vertexCount = n;
    if (topologyChanged) {
      this.quads = Int32Array.from(k.quads);
      this.topologySerial++;
    }
    this.nodes = Int32Array.from(k.nodes);
    for (const name of FIELD_NAMES) {
      this.fields[name] = k.fields[name].length ? Float32Array.from(k.fields[name]) : null;
    }
    this.errorBound = [k.error_bound.x, k.error_bound.y, k.error_bound.z];
    this.positions = new Float64Array(3 * n);
    for (let v = 0; v < n; ++v) this.decode(v);
    this.lastChange = topologyChanged ? 'topology' : 'keyframe';
    this.lastRice = false;
    this.lastMoved = n;
  }

  applyDelta(frame) {
    const d = frame.delta;
    if (!this.hasKeyframe) {
      throw new FrameError('precondition', `delta at step ${frame.step} before any keyframe`);
    }
    if (d.base_step !== this.step) {
      throw new FrameError('precondition', `delta at step ${frame.step}: base_step ` +
                           `${d.base_step} but the last frame was step ${this.step}`);
    }
    const n = this.vertexCount;
    const listed = [];
    let at = 0;
    for (let r = 0; r < d.runs.length; ++r) {
      const len = d.runs[r];
      if (r % 2 === 1) for (let i = 0; i < len && at + i < n; ++i) listed.push(at + i);
      at += len;
      if (at > n) throw invalid(`delta.runs: run ${r} ends at vertex ${at}, past the ${n} vertices`);
    }
    if (listed.length !== d.moved) {
      throw invalid(`delta.moved: ${d.moved} but runs list ${listed.length} vertices`);
    }
    checkFields(d.fields, d.moved, 'delta');
    for (const name of FIELD_NAMES) {
      if (d.fields[name].length !== 0 && this.fields[name] === null) {
        throw invalid(`delta.fields.${name}: present but the keyframe had none`);
      }
    }
    const rice = d.rice_k.length > 0;
    const updated = new Uint16Array(3 * listed.length);
    if (listed.length) {
      const bits = d.bits;
      if (rice) {
        if (d.rice_k.length !== 3) {
          throw invalid(`delta.rice_k: ${d.rice_k.length} values, expected 3 (x, y, z)`);
        }
        for (let a = 0; a < 3; ++a) {
          if (d.rice_k[a] > 16 || d.rice_k[a] < 0) {
            throw invalid(`delta.rice_k[${a}]: ${d.rice_k[a]} outside [0, 16]`);
          }
        }
      } else {
        if (bits < 1 || bits > 17) throw invalid(`delta.bits: ${bits} outside [1, 17]`);
        const want = Math.ceil((3 * listed.length * bits) / 8);
        if (d.packed.length !== want) {
          throw invalid(`delta.packed: ${d.packed.length} bytes, expected ${want} for ` +
                        `${listed.length} vertices at ${bits} bits`);
        }
      }
      const bytes = d.packed;
      const sizeBits = 8 * bytes.length;
      let bit = 0;
      let overrun = false;
      const read = (count) => {
        let z = 0;
        for (let b = 0; b < count; ++b, ++bit) {
          if (bit >= sizeBits) {
            overrun = true;
            return z;
          }
          z |= ((bytes[bit >> 3] >> (bit & 7)) & 1) << b;
        }
        return z >>> 0;
      };
      for (let v = 0; v < listed.length; ++v) {
        for (let a = 0; a < 3; ++a) {
          let z;
          if (!rice) {
            z = read(bits);
          } else {
            const k = d.rice_k[a];
            let ones = 0;
            while (ones < 16 && read(1) === 1 && !overrun) ++ones;
            z = ones < 16 ? ((ones << k) | read(k)) >>> 0 : read(17);
          }
          if (overrun) {
            throw invalid(`delta.packed: ${bytes.length} bytes end inside vertex ${listed[v]} ` +
                          `axis ${a} (${listed.length} vertices listed)`);
          }
          const diff = (z & 1) ? -(z >>> 1) - 1 : (z >>> 1);
          const code = this.codes[3 * listed[v] + a] + diff;
          if (code < 0 || code > 65535) {
            throw invalid(`delta.packed: vertex ${listed[v]} axis ${a} code ${code} ` +
                          'outside [0, 65535]');
          }
          updated[3 * v + a] = code;
        }
      }
      if (rice && bytes.length !== Math.ceil(bit / 8)) {
        throw invalid(`delta.packed: ${bytes.length} bytes, the Rice codes take ${Math.ceil(bit / 8)}`);
      }
    }
    // Valid: commit.
    for (let v = 0; v < listed.length; ++v) {
      for (let a = 0; a < 3; ++a) this.codes[3 * listed[v] + a] = updated[3 * v + a];
    }
    for (const name of FIELD_NAMES) {
      const values = d.fields[name];
      const out = this.fields[name];
      for (let i = 0; i < values.length; ++i) out[listed[i]] = values[i];
    }
    this.step = frame.step;
    this.time = frame.time;
    for (const v of listed) this.decode(v);
    this.lastChange = listed;
    this.lastRice = rice;
    this.lastMoved = listed.length;
  }

  decode(v) {
    for (let a = 0; a < 3; ++a) {
      this.positions[3 * v + a] = this.origin[a] + this.codes[3 * v + a] * this.gridStep[a];
    }
  }

  // Axis-aligned bounds of the positions ({min, max}, zeros when empty).
  bounds() {
    const min = [0, 0, 0];
    const max = [0, 0, 0];
    for (let v = 0; v < this.vertexCount; ++v) {
      for (let a = 0; a < 3; ++a) {
        const x = this.positions[3 * v + a];
        if (v === 0 || x < min[a]) min[a] = x;
        if (v === 0 || x > max[a]) max[a] = x;
      }
    }
    return { min, max };
  }
}

function sameInts(a, b) {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; ++i) if (a[i] !== b[i]) return false;
  return true;
}
