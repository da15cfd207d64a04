// A minimal protobuf wire-format reader for the messages the page decodes
// itself: dynsolid.Frame and what it holds (proto/dynsolid/service.proto).
// The gateway passes Watch frames through as the server's bytes; everything
// else reaches the page as JSON. Written from the protobuf encoding spec
// (varints, 64-bit, length-delimited, 32-bit; packed and unpacked repeated
// scalars), not from a library, so the page loads no protobuf runtime.

export class WireError extends Error {}

const WIRE_VARINT = 0;
const WIRE_I64 = 1;
const WIRE_LEN = 2;
const WIRE_I32 = 5;

export class Reader {
  constructor(bytes, start = 0, end = bytes.length) {
    this.bytes = bytes;
    this.pos = start;
    this.end = end;
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  }

  done() {
    return this.pos >= this.end;
  }

  // An unsigned varint as a Number (exact below 2^53; int64 fields in the
  // frames are steps and counts, far below that). Negative int32/int64
  // values (10-byte two's complement) come back negative.
  varint() {
    let result = 0;
    let scale = 1;
    for (let i = 0; i < 10; ++i) {
      if (this.pos >= this.end) throw new WireError(`varint runs past the end at byte ${this.pos}`);
      const b = this.bytes[this.pos++];
      result += (b & 0x7f) * scale;
      if ((b & 0x80) === 0) {
        // Two's complement of a negative 64-bit value: 2^64 - |v|.
        if (result >= 2 ** 63) return result - 2 ** 64;
        return result;
      }
      scale *= 128;
    }
    throw new WireError(`varint longer than 10 bytes at byte ${this.pos}`);
  }

  tag() {
    const t = this.varint();
    return { field: Math.floor(t / 8), wire: t & 7 };
  }

  double() {
    if (this.pos + 8 > this.end) throw new WireError(`double runs past the end at byte ${this.pos}`);
    const v = this.view.getFloat64(this.pos, true);
    this.pos += 8;
    return v;
  }

  float() {
    if (this.pos + 4 > this.end) throw new WireError(`float runs past the end at byte ${this.pos}`);
    const v = this.view.getFloat32(this.pos, true);
    this.pos += 4;
    return v;
  }

  // A length-delimited field: [start, end) of its bytes.
  span() {
    const len = this.varint();
    if (len < 0 || this.pos + len > this.end) {
      throw new WireError(`length ${len} at byte ${this.pos} runs past the end (${this.end})`);
    }
    const s = { start: this.pos, end: this.pos + len };
    this.pos += len;
    return s;
  }

  sub() {
    const s = this.span();
    return new Reader(this.bytes, s.start, s.end);
  }

  bytesField() {
    const s = this.span();
    return this.bytes.subarray(s.start, s.end);
  }

  skip(wire) {
    switch (wire) {
      case WIRE_VARINT:
        this.varint();
        return;
      case WIRE_I64:
        this.pos += 8;
        break;
      case WIRE_LEN:
        this.span();
        return;
      case WIRE_I32:
        this.pos += 4;
        break;
      default:
        throw new WireError(`unknown wire type ${wire} at byte ${this.pos}`);
    }
    if (this.pos > this.end) throw new WireError('field runs past the end');
  }

  // Appends a repeated scalar field's values to `out`, packed (one
  // length-delimited run) or not (one value): `scalarWire` is the type's
  // own wire type, `read` reads one value from a Reader.
  repeated(wire, out, scalarWire, read) {
    if (wire === WIRE_LEN) {
      const r = this.sub();
      while (!r.done()) out.push(read(r));
    } else if (wire === scalarWire) {
      out.push(read(this));
    } else {
      throw new WireError(`repeated field with wire type ${wire}, expected ${scalarWire} or packed`);
    }
  }

  repeatedVarint(wire, out) {
    this.repeated(wire, out, WIRE_VARINT, (r) => r.varint());
  }

  repeatedFloat(wire, out) {
    this.repeated(wire, out, WIRE_I32, (r) => r.float());
  }
}

function expect(wire, want, name) {
  if (wire !== want) throw new WireError(`${name}: wire type ${wire}, expected ${want}`);
}

export function readVec3(r) {
  const v = { x: 0, y: 0, z: 0 };
  while (!r.done()) {
    const { field, wire } = r.tag();
    if (field >= 1 && field <= 3 && wire === WIRE_I64) v['xyz'[field - 1]] = r.double();
    else r.skip(wire);
  }
  return v;
}

const FIELD_NAMES = ['displacement', 'strain', 'stiffness', 'mass'];

function readFields(r) {
  const f = { displacement: [], strain: [], stiffness: [], mass: [] };
  while (!r.done()) {
    const { field, wire } = r.tag();
    if (field >= 1 && field <= FIELD_NAMES.length) r.repeatedFloat(wire, f[FIELD_NAMES[field - 1]]);
    else r.skip(wire);
  }
  return f;
}

function emptyFields() {
  return { displacement: [], strain: [], stiffness: [], mass: [] };
}

function readGrid(r) {
  const g = { origin: { x: 0, y: 0, z: 0 }, step: { x: 0, y: 0, z: 0 } };
  while (!r.done()) {
    const { field, wire } = r.tag();
    if (field === 1) {
      expect(wire, WIRE_LEN, 'grid.origin');
      g.origin = readVec3(r.sub());
    } else if (field === 2) {
      expect(wire, WIRE_LEN, 'grid.step');
      g.step = readVec3(r.sub());
    } else r.skip(wire);
  }
  return g;
}

function readKeyframe(r) {
  const k = {
    topology_version: 0, vertex_count: 0, quads: [], grid: readGrid(new Reader(new Uint8Array(0))),
    error_bound: { x: 0, y: 0, z: 0 }, codes: new Uint8Array(0), fields: emptyFields(), nodes: [],
  };
  while (!r.done()) {
    const { field, wire } = r.tag();
    switch (field) {
      case 1: expect(wire, WIRE_VARINT, 'keyframe.topology_version'); k.topology_version = r.varint(); break;
      case 2: expect(wire, WIRE_VARINT, 'keyframe.vertex_count'); k.vertex_count = r.varint(); break;
      case 3: r.repeatedVarint(wire, k.quads); break;
      case 4: expect(wire, WIRE_LEN, 'keyframe.grid'); k.grid = readGrid(r.sub()); break;
      case 5: expect(wire, WIRE_LEN, 'keyframe.error_bound'); k.error_bound = readVec3(r.sub()); break;
      case 6: expect(wire, WIRE_LEN, 'keyframe.codes'); k.codes = r.bytesField(); break;
      case 7: expect(wire, WIRE_LEN, 'keyframe.fields'); k.fields = readFields(r.sub()); break;
      case 8: r.repeatedVarint(wire, k.nodes); break;
      default: r.skip(wire);
    }
  }
  return k;
}

function readDelta(r) {
  const d = {
    base_step: 0, runs: [], bits: 0, packed: new Uint8Array(0), error_bound: { x: 0, y: 0, z: 0 },
    fields: emptyFields(), moved: 0, rice_k: [],
  };
  while (!r.done()) {
    const { field, wire } = r.tag();
    switch (field) {
      case 1: expect(wire, WIRE_VARINT, 'delta.base_step'); d.base_step = r.varint(); break;
      case 2: r.repeatedVarint(wire, d.runs); break;
      case 3: expect(wire, WIRE_VARINT, 'delta.bits'); d.bits = r.varint(); break;
      case 4: expect(wire, WIRE_LEN, 'delta.packed'); d.packed = r.bytesField(); break;
      case 5: expect(wire, WIRE_LEN, 'delta.error_bound'); d.error_bound = readVec3(r.sub()); break;
      case 6: expect(wire, WIRE_LEN, 'delta.fields'); d.fields = readFields(r.sub()); break;
      case 7: expect(wire, WIRE_VARINT, 'delta.moved'); d.moved = r.varint(); break;
      case 8: r.repeatedVarint(wire, d.rice_k); break;
      default: r.skip(wire);
    }
  }
  return d;
}

// Parses one serialized dynsolid.Frame (a Uint8Array). Throws WireError on
// malformed bytes.
export function parseFrame(bytes) {
  const r = new Reader(bytes);
  const f = { step: 0, time: 0, keyframe: null, delta: null, skipped: 0, watcher_id: 0 };
  while (!r.done()) {
    const { field, wire } = r.tag();
    switch (field) {
      case 1: expect(wire, WIRE_VARINT, 'frame.step'); f.step = r.varint(); break;
      case 2: expect(wire, WIRE_I64, 'frame.time'); f.time = r.double(); break;
      case 3: expect(wire, WIRE_LEN, 'frame.keyframe'); f.keyframe = readKeyframe(r.sub()); f.delta = null; break;
      case 4: expect(wire, WIRE_LEN, 'frame.delta'); f.delta = readDelta(r.sub()); f.keyframe = null; break;
      case 5: expect(wire, WIRE_VARINT, 'frame.skipped'); f.skipped = r.varint(); break;
      case 6: expect(wire, WIRE_VARINT, 'frame.watcher_id'); f.watcher_id = r.varint(); break;
      default: r.skip(wire);
    }
  }
  return f;
}

export { FIELD_NAMES };
