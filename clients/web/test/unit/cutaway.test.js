// The cut-away's pure helpers (public/js/cutaway.js): the plane across the
// solid's bounds facing the camera, the section's colours and its line.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { cutPlane, sectionColors, sectionText, SECTION_FIELDS } from '../../public/js/cutaway.js';

const box = { min: [0, 0, 0], max: [2, 1, 4] };

test('the plane crosses the bounds along its axis and faces the eye', () => {
  assert.deepEqual(cutPlane('x', 0.25, box, [10, 0, 0]),
    { point: { x: 0.5, y: 0.5, z: 2 }, normal: { x: 1, y: 0, z: 0 } });
  assert.deepEqual(cutPlane('x', 0.25, box, [-10, 0, 0]).normal, { x: -1, y: 0, z: 0 });
  assert.deepEqual(cutPlane('z', 1, box, [0, 0, 9]).point, { x: 1, y: 0.5, z: 4 });
  // Out of range and not a number: clamped, the middle.
  assert.equal(cutPlane('y', 7, box, [0, 9, 0]).point.y, 1);
  assert.equal(cutPlane('y', NaN, box, [0, 9, 0]).point.y, 0.5);
});

test('section colours are viridis over the values, a line says what was cut', () => {
  const { colors, range } = sectionColors('strain', [0, 0.1, 0.2]);
  assert.equal(colors.length, 9);
  assert.equal(range[0], 0);
  assert.ok(Math.abs(range[1] - 0.2) < 1e-7);
  // Low is dark purple, high is yellow.
  assert.ok(colors[0] < 0.3 && colors[2] > 0.3);
  assert.ok(colors[6] > 0.9 && colors[7] > 0.8);
  assert.equal(sectionText({ field: 'stiffness', unit: 'Pa', min: 1e5, max: 1e6, cells_cut: 12, step: 40, values: [1] }),
    'stiffness 1.00e+5 – 1.00e+6 Pa · 12 cells cut (step 40)');
  assert.equal(sectionText({ field: 'strain', unit: '1', values: [] }), 'the plane misses the solid');
  assert.deepEqual(SECTION_FIELDS.map((f) => f.key), ['strain', 'displacement', 'stiffness', 'distortion']);
});
