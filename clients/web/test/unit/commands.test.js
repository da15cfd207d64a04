// Tools as commands: shapes as service.proto takes them, parameter checks,
// the control-edge choice of the sharp tool, the drag plane.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as C from '../../public/js/commands.js';
import { Tools } from '../../public/js/tools.js';
import { loadService } from '../../gateway/grpc.js';
import { viridis, fieldRange, colorize, formatValue } from '../../public/js/colormap.js';

const P = { x: 0.1, y: 0.9, z: -0.2 };

test('drag, move, curve and pressure commands carry the picked material point', () => {
  assert.deepEqual(C.drag(P, { x: 1, y: 2, z: 3 }, 500),
    { drag: { material_point: P, target: { x: 1, y: 2, z: 3 }, stiffness: 500 } });
  assert.deepEqual(C.moveDrag(4, P), { move_drag: { load_id: 4, target: P } });
  assert.deepEqual(C.moveCurve(4, [P, P]).move_drag.targets.length, 2);
  assert.deepEqual(C.pressure(P, 0.3, -100),
    { add_pressure: { region: { sphere: { center: P, radius: 0.3 } }, pascals: -100 } });
  assert.throws(() => C.pressure(P, 0.3, 0), /pressure: must not be 0/);
  assert.throws(() => C.drag(P, P, NaN), /drag stiffness: must be a finite number, got NaN/);
  assert.throws(() => C.curve([P], [P], 10), /at least 2 points/);
});

test('brush dabs paint young_modulus or density with strength and falloff checked', () => {
  const dab = C.paint('mass', P, { radius: 0.2, strength: 1, falloff: 0.25, value: 5000 });
  assert.deepEqual(dab.paint_material.material, { density: 5000 });
  assert.deepEqual(C.paint('stiffness', P, { radius: 0.2, strength: 0.5, falloff: 0, value: 1e6 })
    .paint_material.material, { young_modulus: 1e6 });
  assert.throws(() => C.paint('stiffness', P, { radius: 0.2, strength: 2, falloff: 0, value: 1 }), /strength: must be in \(0, 1\]/);
  assert.throws(() => C.paint('stiffness', P, { radius: -1, strength: 1, falloff: 0, value: 1 }), /radius: must be > 0/);
  assert.throws(() => C.paint('colour', P, { radius: 1, strength: 1, falloff: 0, value: 1 }), /unknown field colour/);
});

test('the material brush paints a preset with the brush\'s radius, strength and falloff', () => {
  assert.deepEqual(C.paintPreset(P, { radius: 0.5, strength: 1, falloff: 0.25, preset: 'CLAY' }), {
    paint_material: { region: { sphere: { center: P, radius: 0.5 } }, material: { preset: 'CLAY' },
      strength: 1, falloff: 0.25 },
  });
  assert.deepEqual(C.paintPreset(P, { radius: 1, strength: 0.5, falloff: 0, preset: 'RUBBER' })
    .paint_material.material, { preset: 'RUBBER' });
  assert.deepEqual(C.PRESETS, ['RUBBER', 'CLAY', 'WAX']);
  assert.throws(() => C.paintPreset(P, { radius: 1, strength: 1, falloff: 0, preset: 'GLASS' }), /unknown preset GLASS/);
  assert.throws(() => C.paintPreset(P, { radius: 1, strength: 0, falloff: 0, preset: 'WAX' }), /strength: must be in \(0, 1\]/);
  assert.throws(() => C.paintPreset(P, { radius: 0, strength: 1, falloff: 0, preset: 'WAX' }), /radius: must be > 0/);
});

test('the panel\'s brushes: clay by default on the material brush, numbers on the others', () => {
  const tools = new Tools({ onToolChanged() {}, refreshMarkers() {} });
  assert.deepEqual(tools.brushCommand('material', P), {
    paint_material: { region: { sphere: { center: P, radius: 0.8 } }, material: { preset: 'CLAY' },
      strength: 1, falloff: 0.25 },
  });
  tools.params.preset = 'WAX';
  assert.deepEqual(tools.brushCommand('material', P).paint_material.material, { preset: 'WAX' });
  assert.deepEqual(tools.brushCommand('stiffness', P).paint_material.material, { young_modulus: 1e6 });
  assert.deepEqual(tools.brushCommand('mass', P).paint_material.material, { density: 5000 });
});

test('bake: an edit with an empty bake (the server fills in the rest positions)', () => {
  assert.deepEqual(C.bake(), { edit: { bake: {} } });
});

test('bake and the preset paint survive the real service.proto (as the gateway sends them)', () => {
  const m = loadService().definition['dynsolid.Sessions'].Commands;
  const roundTrip = (command) => m.requestDeserialize(m.requestSerialize({ seq: 1, command })).command;
  const baked = roundTrip(C.bake());
  assert.equal(baked.kind, 'edit');
  assert.equal(baked.edit.kind, 'bake');
  assert.deepEqual(baked.edit.bake.rest_positions, []);
  const dab = roundTrip(C.paintPreset(P, { radius: 0.5, strength: 1, falloff: 0.25, preset: 'WAX' }));
  assert.equal(dab.kind, 'paint_material');
  assert.equal(dab.paint_material.material.preset, 'WAX');
  assert.equal(dab.paint_material.region.sphere.radius, 0.5);
});

test('topology edits name the picked ids', () => {
  assert.deepEqual(C.deleteCell(3), { edit: { delete_cells: { cells: [3] } } });
  assert.deepEqual(C.extrudeFace(7, 0.4, 2), { edit: { extrude_faces: { faces: [7], distance: 0.4, layers: 2 } } });
  assert.deepEqual(C.mergeFaces(1, 2), { edit: { merge_faces: { face_a: 1, face_b: 2 } } });
  assert.throws(() => C.mergeFaces(2, 2), /face 2 with itself/);
  assert.deepEqual(C.sharpEdge(4, 5, true), { edit: { sharp_edges: { edges: [{ v0: 4, v1: 5 }], sharp: true } } });
});

test('the sharp tool takes the face edge nearest the material point and knows its tag', () => {
  // One square face z = 0 with corners 0..3; edge 1-2 tagged sharp.
  const mesh = {
    rest_positions: [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0],
    face_offsets: [0, 4], face_vertices: [0, 1, 2, 3], face_cells: [0, -1],
    edge_vertices: [0, 1, 1, 2, 2, 3, 3, 0], edge_sharp: [false, true, false, false],
  };
  assert.deepEqual(C.nearestFaceEdge(mesh, 0, { x: 0.9, y: 0.5, z: 0 }), { v0: 1, v1: 2, sharp: true });
  assert.deepEqual(C.nearestFaceEdge(mesh, 0, { x: 0.5, y: 0.05, z: 0 }), { v0: 0, v1: 1, sharp: false });
  assert.equal(C.nearestFaceEdge(mesh, 5, P), null);
});

test('the drag plane: a ray meets the plane facing the camera', () => {
  const q = C.rayPlane({ x: 0, y: 0, z: 5 }, { x: 0, y: 0, z: -1 }, { x: 0, y: 0, z: 1 }, { x: 0, y: 0, z: 1 });
  assert.deepEqual(q, { x: 0, y: 0, z: 1 });
  assert.equal(C.rayPlane({ x: 0, y: 0, z: 5 }, { x: 1, y: 0, z: 0 }, P, { x: 0, y: 0, z: 1 }), null);
  assert.equal(C.distanceToSegment([0, 1, 0], [-1, 0, 0], [1, 0, 0]), 1);
});

test('the colour map runs from dark purple to yellow; ranges and labels', () => {
  const lo = viridis(0);
  const hi = viridis(1);
  assert.ok(lo[2] > lo[1] && lo[0] > lo[1], 'purple at 0');
  assert.ok(hi[0] > 0.9 && hi[1] > 0.85 && hi[2] < 0.2, 'yellow at 1');
  assert.deepEqual(viridis(NaN), viridis(0));
  assert.deepEqual(fieldRange('displacement', Float32Array.from([0.2, 0.5])), [0, 0.5]);
  assert.deepEqual(fieldRange('stiffness', Float32Array.from([1e5, 1e6])).map(Math.round), [1e5, 1e6]);
  const flat = fieldRange('stiffness', Float32Array.from([1e5, 1e5]));
  assert.ok(flat[0] < 1e5 && flat[1] > 1e5, 'a flat field maps to the middle');
  const out = new Float32Array(6);
  colorize(Float32Array.from([0, 1]), [0, 1], out);
  assert.deepEqual([...out.slice(3)].map((v) => Math.round(v * 100)), hi.map((v) => Math.round(v * 100)));
  assert.equal(formatValue(100000), '1.00e+5');
  assert.equal(formatValue(0.25), '0.25');
});
