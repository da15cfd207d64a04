// The page's frame decoder: hand-built frames (keyframe, fixed-width and
// Rice deltas, bad frames) and the shared vectors the C++ tests write from
// the server's encoder and the C++ client decoder (DYNSOLID_VECTORS_DIR).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { SurfaceDecoder, FrameError } from '../../public/js/surface.js';
import { parseFrame } from '../../public/js/wire.js';
import { keyframe, delta, Writer } from './pbwriter.js';

// Two quads sharing an edge: 6 vertices.
const QUADS = [0, 1, 4, 3, 1, 2, 5, 4];
const CODES = [0, 0, 0, 10, 0, 0, 20, 0, 0, 0, 10, 0, 10, 10, 0, 20, 10, 0];

function start() {
  const d = new SurfaceDecoder();
  d.apply(keyframe({ step: 5, codes: CODES, quads: QUADS, origin: [1, 2, 3], gridStep: [0.5, 0.25, 2],
    fields: { stiffness: [1, 2, 3, 4, 5, 6] }, nodes: [10, 11, 12, 13, 14, 15] }));
  return d;
}

test('a keyframe decodes positions as origin + code * step, quads, nodes and fields', () => {
  const d = start();
  assert.equal(d.vertexCount, 6);
  assert.equal(d.step, 5);
  assert.deepEqual([...d.quads], QUADS);
  assert.deepEqual([...d.nodes], [10, 11, 12, 13, 14, 15]);
  assert.deepEqual([...d.positions.slice(3, 6)], [1 + 10 * 0.5, 2, 3]);
  assert.deepEqual([...d.positions.slice(12, 15)], [6, 4.5, 3]);
  assert.deepEqual([...d.fields.stiffness], [1, 2, 3, 4, 5, 6]);
  assert.equal(d.fields.displacement, null);
  assert.equal(d.lastChange, 'topology');
  assert.deepEqual(d.errorBound, [0.25, 0.125, 1]);
});

test('a fixed-width delta moves only the listed vertices and updates their fields', () => {
  const d = start();
  d.apply(delta({ step: 6, baseStep: 5, listed: [1, 4, 5], diffs: [3, 2, 0, -1, 0, 7, 0, 0, 4],
    bits: 5, fields: { stiffness: [20, 50, 60] } }));
  assert.equal(d.step, 6);
  assert.deepEqual(d.lastChange, [1, 4, 5]);
  assert.deepEqual([...d.codes], [0, 0, 0, 13, 2, 0, 20, 0, 0, 0, 10, 0, 9, 10, 7, 20, 10, 4]);
  assert.deepEqual([...d.positions.slice(3, 6)], [1 + 13 * 0.5, 2 + 2 * 0.25, 3]);
  assert.deepEqual([...d.positions.slice(15, 18)], [11, 4.5, 3 + 4 * 2]);
  assert.deepEqual([...d.fields.stiffness], [1, 20, 3, 4, 50, 60]);
  assert.deepEqual([...d.positions.slice(0, 3)], [1, 2, 3]);  // untouched
});

test('a Rice delta decodes, including the escape for large steps', () => {
  const d = start();
  // Vertex 2 moves +1000 codes on x: zigzag 2000 >> k=1 = 1000 >= 16, escaped.
  d.apply(delta({ step: 6, baseStep: 5, listed: [2, 3], diffs: [1000, 1, 1, 2, 0, 3],
    riceK: [1, 0, 0] }));
  assert.deepEqual([...d.codes.slice(6, 12)], [1020, 1, 1, 2, 10, 3]);
  assert.equal(d.lastRice, true);
  assert.equal(d.lastMoved, 2);
});

test('a delta where nothing moved only advances the step', () => {
  const d = start();
  d.apply(delta({ step: 9, baseStep: 5, listed: [], diffs: [], bits: 1, skipped: 3 }));
  assert.equal(d.step, 9);
  assert.equal(d.lastSkipped, 3);
  assert.deepEqual([...d.codes], CODES);
});

test('bad frames are rejected with a message and change nothing', () => {
  const d = start();
  const before = { positions: [...d.positions], step: d.step, codes: [...d.codes] };
  const same = () => {
    assert.deepEqual([...d.positions], before.positions);
    assert.equal(d.step, before.step);
    assert.deepEqual([...d.codes], before.codes);
  };
  const bad = (bytes, kind, pattern) => {
    assert.throws(() => d.apply(bytes), (e) => e instanceof FrameError && e.kind === kind && pattern.test(e.message));
    same();
  };
  bad(delta({ step: 7, baseStep: 4, listed: [0], diffs: [1, 1, 1], bits: 2 }), 'precondition', /base_step 4 but the last frame was step 5/);
  bad(delta({ step: 6, baseStep: 5, listed: [0], diffs: [-1, 0, 0], bits: 2 }), 'invalid', /vertex 0 axis 0 code -1 outside/);
  bad(delta({ step: 6, baseStep: 5, listed: [0], diffs: [1, 1, 1], bits: 20 }), 'invalid', /delta.bits: 20 outside \[1, 17\]/);
  bad(keyframe({ codes: CODES, quads: [0, 1, 2, 9] }), 'invalid', /keyframe.quads\[3\]: vertex 9 outside \[0, 6\)/);
  bad(keyframe({ codes: CODES, quads: QUADS, gridStep: [1, 0, 1] }), 'invalid', /keyframe.grid/);
  bad(keyframe({ codes: CODES, quads: QUADS, fields: { strain: [1, 2] } }), 'invalid', /keyframe.fields.strain: 2 values for 6 vertices/);
  bad(delta({ step: 6, baseStep: 5, listed: [0], diffs: [1, 1, 1], bits: 2, fields: { mass: [3] } }), 'invalid', /delta.fields.mass: present but the keyframe had none/);
  bad(Uint8Array.from([0x08, 0xff]), 'invalid', /varint runs past the end/);
  bad(new Writer().uint(1, 3).finish(), 'invalid', /neither keyframe nor delta/);
  const fresh = new SurfaceDecoder();
  assert.throws(() => fresh.apply(delta({ step: 1, baseStep: 0, listed: [0], diffs: [0, 0, 0], bits: 1 })),
    /before any keyframe/);
});

test('unknown fields are skipped (newer servers may add some)', () => {
  const k = keyframe({ codes: CODES, quads: QUADS });
  const extra = new Writer().uint(99, 12345).bytes(100, [1, 2, 3]).finish();
  const withExtra = new Uint8Array(k.length + extra.length);
  withExtra.set(k);
  withExtra.set(extra, k.length);
  const f = parseFrame(withExtra);
  assert.equal(f.keyframe.vertex_count, 6);
});

// ---- shared vectors from the C++ tests ----

const vectorsDir = process.env.DYNSOLID_VECTORS_DIR;

function readFrames(file) {
  const buf = fs.readFileSync(file);
  const frames = [];
  for (let at = 0; at < buf.length;) {
    const len = buf.readUInt32LE(at);
    frames.push(new Uint8Array(buf.buffer, buf.byteOffset + at + 4, len));
    at += 4 + len;
  }
  return frames;
}

test('shared vectors: the page decodes the server encoder\'s frames exactly like the C++ decoder',
  { skip: vectorsDir ? false : 'DYNSOLID_VECTORS_DIR is not set (CTest sets it after the C++ test writes them)' },
  () => {
    const frames = readFrames(path.join(vectorsDir, 'frames.bin'));
    const expected = JSON.parse(fs.readFileSync(path.join(vectorsDir, 'expected.json'), 'utf8'));
    assert.equal(frames.length, expected.length);
    assert.ok(frames.length >= 8, `only ${frames.length} frames`);
    const d = new SurfaceDecoder();
    const seen = { keyframe: 0, rice: 0, fixed: 0, empty: 0, skipped: 0, topology: 0 };
    let lastTopology = null;
    frames.forEach((bytes, i) => {
      const e = expected[i];
      const f = d.apply(bytes);
      const where = `frame ${i} (step ${e.step})`;
      assert.equal(d.step, e.step, where);
      assert.equal(Boolean(f.keyframe), e.keyframe, where);
      assert.equal(d.vertexCount, e.vertex_count, where);
      assert.equal(d.topologyVersion, e.topology_version, where);
      assert.deepEqual([...d.quads], e.quads, `${where}: quads`);
      // Bit-identical to the C++ decoder (the same double arithmetic).
      assert.equal(d.positions.length, e.positions.length, where);
      for (let j = 0; j < e.positions.length; ++j) {
        if (d.positions[j] !== e.positions[j]) {
          assert.fail(`${where}: coordinate ${j}: page ${d.positions[j]}, C++ ${e.positions[j]}`);
        }
        const bound = e.error_bound[j % 3] * (1 + 1e-12) + 1e-15;
        if (Math.abs(d.positions[j] - e.true_positions[j]) > bound) {
          assert.fail(`${where}: coordinate ${j} off the server's by more than ${e.error_bound[j % 3]}`);
        }
      }
      for (const name of ['displacement', 'strain', 'stiffness', 'mass']) {
        const got = d.fields[name] ? [...d.fields[name]] : [];
        const want = (e.fields && e.fields[name]) || [];
        assert.equal(got.length, want.length, `${where}: ${name} count`);
        for (let j = 0; j < want.length; ++j) {
          assert.equal(got[j], Math.fround(want[j]), `${where}: ${name}[${j}]`);
        }
      }
      if (f.keyframe) seen.keyframe++;
      else if (d.lastRice) seen.rice++;
      else if (d.lastMoved === 0) seen.empty++;
      else seen.fixed++;
      if (f.skipped > 0) seen.skipped++;
      if (lastTopology !== null && e.topology_version !== lastTopology) seen.topology++;
      lastTopology = e.topology_version;
    });
    for (const [kind, count] of Object.entries(seen)) {
      assert.ok(count > 0, `the vectors hold no ${kind} frame: ${JSON.stringify(seen)}`);
    }
  });

test('a view drawing less often than frames arrive can tell a topology change happened', () => {
  const d = start();
  const serial = d.topologySerial;
  // Same quads again: no topology change.
  d.apply(keyframe({ step: 6, codes: CODES, quads: QUADS }));
  assert.equal(d.topologySerial, serial);
  // New quads, then a delta before anyone looked: the serial still says so.
  d.apply(keyframe({ step: 7, topology: 2, codes: CODES, quads: [0, 1, 4, 3] }));
  d.apply(delta({ step: 8, baseStep: 7, listed: [0], diffs: [1, 1, 1], bits: 2 }));
  assert.equal(d.topologySerial, serial + 1);
  assert.deepEqual(d.lastChange, [0]);
});
