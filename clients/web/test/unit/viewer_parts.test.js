// The page's pure parts: refusals in plain words, the status
// line that fits 1280 px, the keys, the camera's rules and the creased
// normals and matcap of the shading.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { explain } from '../../public/js/explain.js';
import { statusText } from '../../public/js/status.js';
import { keyAction } from '../../public/js/keys.js';
import { faceLoop, isBoundaryFace, faceAccepted, facePoints } from '../../public/js/hover.js';
import { PRESETS, frameSphere, aboveGround } from '../../public/js/camera.js';
import { vertexQuads, creasedNormals, matcapShade, matcapPixels } from '../../public/js/shading.js';

const refusal = (message, codeName = 'INVALID_ARGUMENT') => ({ codeName, message });

test('refusals in plain words, the server\'s text kept as the detail', () => {
  const cases = [
    ['command.edit: cell 77 has zero volume 7.54e-19 (size 0.1); cells must have positive volume with outward face loops',
      /fold a cell flat/],
    ['command.edit.merge_faces.face_b: face 12 has 3 vertices but face_a (face 4) has 4; merge needs equal counts',
      /different shapes/],
    ['command.edit.merge_faces.face_a: face 3 is interior (shared by cells 1 and 2); only boundary faces merge',
      /outside of the solid/],
    ['command.edit.merge_faces: face_b: faces 3 and 9 share vertex 5; the connecting cell would be degenerate', /touch/],
    ['command.paint_material.material.yield_strain: painting clay (a material that yields) needs solver.model COROTATIONAL',
      /cannot hold clay/],
    ['command.edit.delete_cells.cells: deleting all 27 cells would leave nothing; keep at least one', /whole solid/],
    ['command.add_pressure: pressure.region selects no boundary face (no face has its rest centroid in the region ...)',
      /covers no part/],
    ['scene_text:2:18: nx must be >= 1', /scene file has an error/],
  ];
  for (const [message, re] of cases) {
    const e = explain(refusal(message));
    assert.match(e.text, re, message);
    assert.ok(e.hint.length > 0, message);
    assert.equal(e.detail, `refused (INVALID_ARGUMENT): ${message}`);
  }
  assert.match(explain(refusal('too many commands', 'RESOURCE_EXHAUSTED')).text, /busy/);
  // Unknown: a generic sentence, the details say why.
  const e = explain(refusal('something new'));
  assert.equal(e.text, 'The server refused that.');
  assert.equal(e.detail, 'refused (INVALID_ARGUMENT): something new');
  // A local error (not the server's): its own message.
  assert.deepEqual(explain(new Error('radius: must be > 0, got -1')), { text: 'radius: must be > 0, got -1', hint: '', detail: '' });
});

test('the status line fits 1280 px; the full one keeps every figure', () => {
  const s = statusText({
    connected: true, session: { id: '0123456789abcdef' }, reconnecting: false, latency: 12.3, idle: false,
    fps: 58.7, skipped: 1234, vertices: 123456,
    info: { scene_name: 'bridge', stats: { model: 'corotational_cells', integrator: 'central_difference', substeps: 42 } },
    stats: { step: 12345678, paused: true, steps_per_second: 999, time_step: 1e-3, step_ms_median: 27.8 },
  });
  // 990 px of 12 px monospace (7.2 px a character) less padding: 130.
  assert.ok(s.short.length <= 115, `${s.short.length}: ${s.short}`);
  assert.match(s.short, /^bridge · corotational ×42 · step 12345678 \(paused\) · 27\.8 ms\/step · cmd 12 ms · 59 fps · 123k vertices/);
  assert.match(s.full, /bridge 01234567 · corotational_cells \/ central_difference ×42 .* 999 steps\/s .* 1234 skipped · 123456 vertices/);
  // Running: the real-time factor.
  assert.match(statusText({ connected: true, session: { id: 'x' }, info: {}, stats: { step: 5, steps_per_second: 500, time_step: 1e-3 },
    latency: null, idle: true, fps: 0, skipped: 0, vertices: 10 }).short, /^\? · step 5 · real time ×0\.50 · 0\.0 ms\/step · cmd – · idle · 10 vertices$/);
  assert.equal(statusText({ connected: false, session: null }).short, 'gateway: disconnected · no session: create one or join one');
});

test('keys: undo, redo, Esc, [ ] with shift, view presets', () => {
  const k = (key, extra = {}) => keyAction({ key, code: '', ctrlKey: false, metaKey: false, altKey: false, shiftKey: false, ...extra });
  assert.deepEqual(k('z', { ctrlKey: true }), { action: 'undo' });
  assert.deepEqual(k('Z', { ctrlKey: true, shiftKey: true }), { action: 'redo' });
  assert.deepEqual(k('y', { metaKey: true }), { action: 'redo' });
  assert.deepEqual(k('Escape'), { action: 'cancel' });
  assert.deepEqual(k('?', { code: 'Slash', shiftKey: true }), { action: 'help' });
  assert.deepEqual(k(']', { code: 'BracketRight' }), { action: 'nudge', which: 'size', steps: 1 });
  assert.deepEqual(k('{', { code: 'BracketLeft', shiftKey: true }), { action: 'nudge', which: 'strength', steps: -1 });
  assert.deepEqual(k('1'), { action: 'look', preset: 'front' });
  assert.deepEqual(k('7'), { action: 'look', preset: 'top' });
  assert.deepEqual(k('f'), { action: 'look', preset: 'frame' });
  assert.deepEqual(k('End', { code: 'Numpad1' }), { action: 'look', preset: 'front' });
  assert.equal(k('x'), null);
  assert.equal(k('1', { ctrlKey: true }), null);
});

test('the camera: presets, framing, and never under the ground', () => {
  for (const d of Object.values(PRESETS)) assert.ok(Math.abs(Math.hypot(d.x, d.y, d.z) - 1) < 1e-12);
  assert.ok(PRESETS.top.z > 0.999 && PRESETS.front.y < -0.99 && PRESETS.side.x > 0.99);
  const f = frameSphere({ x: 0, y: 0, z: 1 }, 1, PRESETS.front, 40, 1.5);
  assert.ok(Math.abs(f.distance - 1.1 / Math.sin((20 * Math.PI) / 180)) < 1e-9);
  assert.ok(f.eye.y < -3);
  // A narrow window backs off further (the horizontal view is the tighter).
  assert.ok(frameSphere({ x: 0, y: 0, z: 0 }, 1, PRESETS.front, 40, 0.5).distance > f.distance);
  // An eye under the floor comes up to the margin, at the same distance.
  const t = { x: 0, y: 0, z: 0.5 };
  const m = aboveGround({ x: 3, y: 0, z: -1 }, t, 0, 0.05);
  assert.ok(m.changed);
  assert.ok(Math.abs(m.eye.z - 0.05) < 1e-12);
  assert.ok(Math.abs(Math.hypot(m.eye.x - t.x, m.eye.y - t.y, m.eye.z - t.z) - Math.hypot(3, 1.5)) < 1e-9);
  // A target panned under the floor comes up with its eye.
  const p = aboveGround({ x: 0, y: -3, z: 1 }, { x: 0, y: 0, z: -0.5 }, 0, 0.05);
  assert.deepEqual(p.target, { x: 0, y: 0, z: 0 });
  assert.equal(p.eye.z, 1.5);
  assert.equal(aboveGround({ x: 0, y: -3, z: 1 }, t, 0, 0.05).changed, false);
});

test('creased normals: a cube\'s corners keep each face\'s normal; a gentle fold is smoothed', () => {
  // Two quads meeting along the x axis: flat (0 degrees) and folded 90 degrees.
  const quads = new Int32Array([0, 1, 2, 3, 1, 0, 5, 4]);
  const flat = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 1, -1, 0, 0, -1, 0];
  const fold = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 1, 0, -1, 0, 0, -1];
  const adj = vertexQuads(quads, 6);
  assert.deepEqual(Array.from(adj.offsets), [0, 2, 4, 5, 6, 7, 8]);
  const out = new Float32Array(24);
  const scratch = { area: new Float32Array(6), unit: new Float32Array(6) };
  creasedNormals(flat, quads, adj, out, scratch);
  for (let k = 0; k < 8; ++k) assert.deepEqual(Array.from(out.slice(3 * k, 3 * k + 3)), [0, 0, 1]);
  creasedNormals(fold, quads, adj, out, scratch);
  // The first quad faces +z, the second -y: each keeps its own at the shared edge.
  assert.deepEqual(Array.from(out.slice(0, 3)), [0, 0, 1]);
  const second = Array.from(out.slice(12, 15)).map((v) => Math.round(v * 1e6) / 1e6);
  assert.deepEqual(second.map(Math.abs), [0, 1, 0]);
  // At 100 degrees' crease angle the fold is smoothed: the shared corner's
  // normal is the two faces' mean.
  creasedNormals(fold, quads, adj, out, scratch, 100);
  assert.ok(Math.abs(out[2] - Math.SQRT1_2) < 1e-6 && Math.abs(Math.abs(out[1]) - Math.SQRT1_2) < 1e-6);
});

test('the matcap never goes dark and is lit from above', () => {
  let lo = 1;
  for (let a = 0; a < 64; ++a) {
    for (let b = 0; b < 32; ++b) {
      const th = (a / 64) * 2 * Math.PI;
      const ph = (b / 32) * (Math.PI / 2);
      lo = Math.min(lo, matcapShade(Math.cos(th) * Math.sin(ph), Math.sin(th) * Math.sin(ph), Math.cos(ph)));
    }
  }
  assert.ok(lo >= 0.42, `darkest ${lo}`);
  assert.ok(matcapShade(0, 0.8, 0.6) > matcapShade(0, -0.8, 0.6));
  const px = matcapPixels(16);
  assert.equal(px.length, 16 * 16 * 4);
  // Row 0 is the bottom of the sphere (a DataTexture): darker than the top row.
  assert.ok(px[4 * (1 * 16 + 8)] < px[4 * (14 * 16 + 8)]);
});

test('hover: the control faces Extrude and Merge take', () => {
  // Two cells: a quad shared (face 1, inner), boundary quads 0 and 2, a
  // boundary triangle 3.
  const mesh = {
    face_offsets: [0, 4, 8, 12, 15],
    face_vertices: [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 0, 1, 4],
    face_cells: [0, -1, 0, 1, 1, -1, 1, -1],
  };
  assert.deepEqual(faceLoop(mesh, 1), [4, 5, 6, 7]);
  assert.equal(faceLoop(mesh, 4), null);
  assert.equal(faceLoop(mesh, -1), null);
  assert.equal(isBoundaryFace(mesh, 0), true);
  assert.equal(isBoundaryFace(mesh, 1), false);
  assert.deepEqual(faceAccepted('extrude', mesh, 0), { ok: true, why: '' });
  assert.match(faceAccepted('extrude', mesh, 1).why, /inner face/);
  assert.equal(faceAccepted('extrude', mesh, 9).ok, false);
  assert.equal(faceAccepted('merge', mesh, 0, null).ok, true);
  assert.equal(faceAccepted('merge', mesh, 2, 0).ok, true);
  assert.match(faceAccepted('merge', mesh, 0, 0).why, /already chosen/);
  assert.match(faceAccepted('merge', mesh, 3, 0).why, /3 corners; the first face has 4/);
  const positions = [];
  for (let v = 0; v < 12; ++v) positions.push(v, 2 * v, 3 * v);
  assert.deepEqual(facePoints(mesh, positions, 3), [{ x: 0, y: 0, z: 0 }, { x: 1, y: 2, z: 3 }, { x: 4, y: 8, z: 12 }]);
  assert.equal(facePoints(mesh, positions.slice(0, 6), 3), null);
});

test('scene picker: the size as last built here, or that it is not known yet', async () => {
  const { keepStats, optionText, aboutText } = await import('../../public/js/scenes.js');
  const k = keepStats({ control_cells: 120, control_vertices: 260, levels: 2, cells: 7680, boundary_faces: 4864,
    model: 'corotational_cells', nodes: 9 });
  assert.deepEqual(k, { control_cells: 120, control_vertices: 260, levels: 2, cells: 7680, boundary_faces: 4864,
    model: 'corotational_cells' });
  assert.equal(optionText('chair', k), 'chair · 7.7k cells');
  assert.equal(optionText('chair', undefined), 'chair');
  assert.equal(optionText('big', { ...k, cells: 123456 }), 'big · 123k cells');
  assert.equal(aboutText('chair', k), 'chair as last built here: 120 control cells, 260 control points; 7.7k cells and 4.9k surface quads at level 2, corotational_cells');
  assert.match(aboutText('torus', null), /not built in this browser yet/);
});

test('scene picker: what the server lists (ListScenes) says what a scene is for and its size', async () => {
  const { serverOptionText, serverAboutText } = await import('../../public/js/scenes.js');
  const chair = { name: 'chair', description: 'A chair built from 76 voxel cells.', control_cells: 76, levels: 2,
    cells: '4864', size: { x: 0.5, y: 0.5, z: 1.2 } };
  assert.equal(serverOptionText(chair), 'chair · 4.9k cells');
  assert.equal(serverAboutText(chair), 'A chair built from 76 voxel cells. (76 control cells, 4.9k cells at level 2; 0.50 x 0.50 x 1.2 m)');
});
