// A tiny protobuf writer for the unit tests: builds Frame bytes by hand
// from the wire-format spec, so the decoder is also checked against input
// that did not come from the server's encoder.

export class Writer {
  constructor() { this.out = []; }
  varint(v) {
    let x = BigInt.asUintN(64, BigInt(v));
    do {
      let b = Number(x & 0x7fn);
      x >>= 7n;
      if (x) b |= 0x80;
      this.out.push(b);
    } while (x);
    return this;
  }
  tag(field, wire) { return this.varint(field * 8 + wire); }
  uint(field, v) { return this.tag(field, 0).varint(v); }
  double(field, v) {
    const b = new Uint8Array(8);
    new DataView(b.buffer).setFloat64(0, v, true);
    this.tag(field, 1);
    this.out.push(...b);
    return this;
  }
  bytes(field, bytes) {
    this.tag(field, 2).varint(bytes.length);
    this.out.push(...bytes);
    return this;
  }
  message(field, w) { return this.bytes(field, w.finish()); }
  packedVarints(field, values) {
    const w = new Writer();
    for (const v of values) w.varint(v);
    return this.bytes(field, w.finish());
  }
  packedFloats(field, values) {
    const b = new Uint8Array(4 * values.length);
    const view = new DataView(b.buffer);
    values.forEach((v, i) => view.setFloat32(4 * i, v, true));
    return this.bytes(field, b);
  }
  finish() { return Uint8Array.from(this.out); }
}

export function vec3(x, y, z) {
  return new Writer().double(1, x).double(2, y).double(3, z);
}

// Keyframe bytes for `codes` (3 per vertex) on grid origin/step.
export function keyframe({ step = 0, topology = 1, codes, quads, origin = [0, 0, 0],
  gridStep = [1, 1, 1], fields = {}, nodes = [] }) {
  const n = codes.length / 3;
  const codeBytes = new Uint8Array(2 * codes.length);
  codes.forEach((c, i) => { codeBytes[2 * i] = c & 0xff; codeBytes[2 * i + 1] = c >> 8; });
  const k = new Writer().uint(1, topology).uint(2, n).packedVarints(3, quads)
    .message(4, new Writer().message(1, vec3(...origin)).message(2, vec3(...gridStep)))
    .message(5, vec3(gridStep[0] / 2, gridStep[1] / 2, gridStep[2] / 2))
    .bytes(6, codeBytes);
  const f = new Writer();
  ['displacement', 'strain', 'stiffness', 'mass'].forEach((name, i) => {
    if (fields[name]) f.packedFloats(i + 1, fields[name]);
  });
  k.message(7, f);
  if (nodes.length) k.packedVarints(8, nodes);
  return new Writer().uint(1, step).double(2, step * 1e-3).message(3, k).finish();
}

// A bit stream filled from each byte's least significant bit.
export class Bits {
  constructor() { this.bytes = []; this.n = 0; }
  put(value, count) {
    for (let b = 0; b < count; ++b, ++this.n) {
      if ((this.n & 7) === 0) this.bytes.push(0);
      if ((value >> b) & 1) this.bytes[this.n >> 3] |= 1 << (this.n & 7);
    }
  }
  rice(z, k) {
    const u = z >> k;
    if (u < 16) {
      for (let i = 0; i < u; ++i) this.put(1, 1);
      this.put(0, 1);
      this.put(z & ((1 << k) - 1), k);
    } else {
      for (let i = 0; i < 16; ++i) this.put(1, 1);
      this.put(z, 17);
    }
  }
}

export const zigzag = (d) => (d >= 0 ? 2 * d : -2 * d - 1);

// Delta bytes: `listed` vertex indices with code differences `diffs` (3
// per listed vertex), fixed width `bits` or Rice parameters `riceK`.
export function delta({ step, baseStep, vertexCount, listed, diffs, bits = 0, riceK = null,
  fields = {}, skipped = 0 }) {
  const runs = [];
  let at = 0;
  let i = 0;
  while (i < listed.length) {
    let j = i;
    while (j + 1 < listed.length && listed[j + 1] === listed[j] + 1) ++j;
    runs.push(listed[i] - at, j - i + 1);
    at = listed[j] + 1;
    i = j + 1;
  }
  const b = new Bits();
  diffs.forEach((d, idx) => {
    const z = zigzag(d);
    if (riceK) b.rice(z, riceK[idx % 3]);
    else b.put(z, bits);
  });
  const d = new Writer().uint(1, baseStep).packedVarints(2, runs).uint(3, riceK ? 0 : bits)
    .bytes(4, Uint8Array.from(b.bytes)).message(5, vec3(0.5, 0.5, 0.5));
  const f = new Writer();
  ['displacement', 'strain', 'stiffness', 'mass'].forEach((name, k) => {
    if (fields[name]) f.packedFloats(k + 1, fields[name]);
  });
  d.message(6, f).uint(7, listed.length);
  if (riceK) d.packedVarints(8, riceK);
  void vertexCount;
  return new Writer().uint(1, step).double(2, step * 1e-3).message(4, d).uint(5, skipped).finish();
}
