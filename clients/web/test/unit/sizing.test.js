// Tools sized to the solid (public/js/sizing.js): block3 (3 m, 1 m cells,
// E 1e5) and the chair (1.2 m, 10 cm cells, E 3e6..2e7).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as S from '../../public/js/sizing.js';

const BLOCK3 = { size: 3, cell: 1, stiffness: { min: 1e5, max: 1e5 } };
const CHAIR = { size: 1.2, cell: 0.1, stiffness: { min: 3e6, max: 2e7 } };

// A half-space pressed over a disc of radius r by p sinks about
// 1.8 p r / E: the default inflate's indent as a share of the radius.
const indentShare = (t, E) => (1.8 * t.pressure * t.radius) / E / t.radius;

test('block3: a 0.75 m brush, 1 kPa, a one-metre extrude, springs like the old defaults', () => {
  const t = S.sizeTools(BLOCK3);
  assert.deepEqual(t, { radius: 0.75, pinRadius: 0.75, pressure: 1000, extrudeDistance: 1,
    dragStiffness: 5e4, curveStiffness: 2e4, stiffnessValue: 1e6, massValue: 5000 });
});

test('the chair: a 15 cm brush, 30 kPa, a 10 cm extrude, springs for 3 MPa', () => {
  const t = S.sizeTools(CHAIR);
  assert.deepEqual(t, { radius: 0.15, pinRadius: 0.15, pressure: 3e4, extrudeDistance: 0.1,
    dragStiffness: 1.5e5, curveStiffness: 6e4, stiffnessValue: 3e7, massValue: 5000 });
});

test('a default inflate dents by a few percent, a default extrude is one cell, the brush fits the solid', () => {
  for (const [name, s] of [['block3', BLOCK3], ['chair', CHAIR]]) {
    const t = S.sizeTools(s);
    const share = indentShare(t, s.stiffness.min);
    assert.ok(share > 0.01 && share < 0.1, `${name}: indent ${share} of the radius`);
    assert.ok(Math.abs(t.extrudeDistance / s.cell - 1) < 0.05, `${name}: extrude ${t.extrudeDistance}`);
    assert.ok(t.radius >= 0.05 * s.size && t.radius <= 0.25 * s.size, `${name}: radius ${t.radius}`);
  }
  // The stiff legs (2e7) dent less than the soft parts the sizing is for.
  const t = S.sizeTools(CHAIR);
  assert.ok(indentShare(t, 2e7) < indentShare(t, 3e6));
  // One number for the stiffness is its minimum.
  assert.deepEqual(S.sizeTools({ ...CHAIR, stiffness: 3e6 }), t);
  assert.throws(() => S.sizeTools({ ...CHAIR, cell: 0 }), /cell 0 must be > 0/);
  assert.throws(() => S.sizeTools({ ...CHAIR, stiffness: null }), /stiffness null must be > 0/);
});

test('bounds, cell size from the control mesh or from the cell count, the stiffness range', () => {
  // The chair's bounds: 0.5 x 0.5 x 1.2 m.
  const b = S.bounds(new Float64Array([0, 0, 0, 0.5, 0.5, 1.2, 0.2, 0.1, 0.6]));
  assert.deepEqual(b, { min: [0, 0, 0], max: [0.5, 0.5, 1.2], size: 1.2 });
  assert.equal(S.bounds([]), null);
  // A unit cube of 1 m edges (12 edges) and one longer diagonal: the median is 1.
  const x = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1];
  const ev = [0, 1, 1, 2, 2, 3, 3, 0, 4, 5, 5, 6, 6, 7, 7, 4, 0, 4, 1, 5, 2, 6, 3, 7, 0, 6];
  assert.equal(S.cellSize({ rest_positions: x, edge_vertices: ev }), 1);
  assert.equal(S.cellSize({ rest_positions: [], edge_vertices: [] }), null);
  assert.equal(S.cellSize(null), null);
  // block3's 27 cells in 3 x 3 x 3 m: 1 m; the chair's 76 in its bounds: about 16 cm.
  assert.ok(Math.abs(S.cellSizeFromCount({ min: [0, 0, 0], max: [3, 3, 3], size: 3 }, 27) - 1) < 1e-12);
  assert.ok(Math.abs(S.cellSizeFromCount(b, 76) - 0.158) < 0.001);
  assert.deepEqual(S.valueRange(new Float32Array([3e6, 2e7, 3e6])), { min: 3e6, max: 2e7 });
  assert.equal(S.valueRange(new Float32Array(0)), null);
});

test('rounding and input steps', () => {
  assert.equal(S.round2(0.1499999), 0.15);
  assert.equal(S.round2(1234), 1200);
  assert.equal(S.round2(150000.3), 1.5e5);
  assert.equal(S.stepFor(0.15), 0.01);
  assert.equal(S.stepFor(2000), 100);
  assert.equal(S.stepFor(0.75), 0.01);
  assert.equal(S.stepFor(0), 1);
});

test('[ and ] change the size, shift the strength; a brush strength stays in (0, 1]', () => {
  const p = { radius: 0.15, pressure: 6e4, strength: 0.9, dragStiffness: 1.5e5, extrudeDistance: 0.1 };
  assert.deepEqual(S.adjust(p, 'inflate', 'size', 1), { key: 'radius', value: 0.188 });
  assert.deepEqual(S.adjust(p, 'inflate', 'size', -1), { key: 'radius', value: 0.12 });
  assert.deepEqual(S.adjust(p, 'deflate', 'strength', 1), { key: 'pressure', value: 7.5e4 });
  assert.deepEqual(S.adjust(p, 'stiffness', 'strength', 1), { key: 'strength', value: 1 });
  assert.deepEqual(S.adjust(p, 'mass', 'strength', -1), { key: 'strength', value: 0.72 });
  // One knob: either key changes it.
  assert.deepEqual(S.adjust(p, 'drag', 'size', 1), { key: 'dragStiffness', value: 1.88e5 });
  assert.deepEqual(S.adjust(p, 'extrude', 'strength', -1), { key: 'extrudeDistance', value: 0.08 });
  assert.equal(S.adjust(p, 'view', 'size', 1), null);
  assert.equal(S.adjust(p, 'delete', 'size', 1), null);
});
