// A sculptor's session on the chair, end to end, asserting on
// the server's state and on the pixels: a stiffness stroke on the seat and
// its undo; a cell extruded from the seat; the clay back pulled, keeping a
// bend after the release; the cut-away, whose section shows the inside
// where the surface was (a viridis colour at the seat's middle, under the
// clipped surface), with its field switched and its plane moved; the
// design downloaded as a scene file and as glTF.
//
// Screenshots go to $DYNSOLID_E2E_OUT/chair/; with DYNSOLID_DOCS_PICTURES=1
// the cut-away one also becomes docs/viewer-cutaway.png.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { startViewer, outDir, pageHelpers, sleep, REPO } from './harness.js';
import { canvasShot, colourAt } from './pixels.js';

const out = outDir('chair');
let env;
let page;
let grpc;
let ref;

const { app, until, project, tool, canvasBox, pullUp } = pageHelpers(() => page);
const stats = () => grpc.call('GetStats', ref);
const log = async () => (await grpc.call('GetCommandLog', { session: ref })).entries;
const surface = async () => (await grpc.call('Inspect', { session: ref, surface_positions: true })).surface_positions;
// Parks the pointer in the canvas' corner (no brush disc over what is measured).
const park = async () => {
  const box = await canvasBox();
  await page.mouse.move(box.x + 8, box.y + box.height - 8);
  await sleep(250);
};
// The chair (scenes/chair.textproto): x, y 0..0.5 m; the seat z 0.4..0.5;
// the back y 0.4..0.5, z 0.5..1.2 m (clay).
const SEAT = { x: 0.25, y: 0.2, z: 0.5 };
const INSIDE_SEAT = { x: 0.25, y: 0.2, z: 0.45 };
const BACK_TOP = { x: 0.25, y: 0.45, z: 1.15 };
const settle = async (steps) => {
  const s = (await stats()).step + steps;
  await until(async () => (await stats()).step >= s, `${steps} steps`, 120000);
};
// The largest z of the surface points near the back's top (x 0.1..0.4).
const backTop = async () => {
  const p = await surface();
  let top = -Infinity;
  for (let i = 0; i < p.length; i += 3) {
    if (p[i] > 0.1 && p[i] < 0.4 && p[i + 1] > 0.3) top = Math.max(top, p[i + 2]);
  }
  return top;
};

before(async () => {
  env = await startViewer(out);
  ({ page, grpc } = env);
  await page.selectOption('#scene-select', 'chair');
  await page.click('#create');
  await until(() => app(() => window.__dynsolid.sizing && window.__dynsolid.sizing.done), 'the chair drawn', 90000);
  ref = await app(() => window.__dynsolid.session);
  await page.click('#view-buttons [data-view=iso]');
  await settle(300);  // standing on the floor
});

after(() => env && env.close());

test('a stiffness stroke on the seat, then Undo takes it back', async () => {
  await tool('stiffness');
  const a = await project(SEAT);
  const fields = (await stats()).fields_version;
  await page.mouse.click(a.x, a.y);
  await until(async () => (await stats()).fields_version > fields, 'the stroke painted', 60000);
  const painted = (await stats()).fields_version;
  await page.click('#undo');
  await until(async () => (await stats()).fields_version > painted, 'the stroke undone', 60000);
  const kinds = (await log()).map((e) => [e.kind, e.code]);
  const paint = kinds.findIndex(([k]) => k === 'paint_material');
  assert.ok(paint >= 0, JSON.stringify(kinds));
  assert.deepEqual(kinds.slice(paint).filter(([k]) => k === 'undo'), [['undo', 0]], JSON.stringify(kinds));
  const h = (await grpc.call('Inspect', { session: ref, history: true })).history;
  assert.ok(h.entries.some((e) => /stiffness/.test(e.what) && e.undone), JSON.stringify(h.entries));
});

test('a cell extruded from the seat', async () => {
  await tool('extrude');
  const cells = (await stats()).control_cells;
  const a = await project({ x: 0.15, y: 0.1, z: 0.5 });
  await page.mouse.click(a.x, a.y);
  await until(async () => (await stats()).control_cells > cells, 'the extruded cell', 60000);
  assert.equal((await stats()).control_cells, cells + 1);
  await settle(300);
});

test('the clay back pulled up keeps a bend after its release', async () => {
  const top0 = await backTop();
  await tool('drag');
  const a = await project(BACK_TOP);
  await pullUp(a, 3, 10, async () => {
    await until(async () => (await backTop()) > top0 + 0.02, 'the back raised by 2 cm', 60000);
    await settle(300);
  });
  await until(async () => (await log()).some((e) => e.kind === 'remove_load'), 'the drag released');
  await settle(1500);
  const kept = (await backTop()) - top0;
  fs.writeFileSync(path.join(out, 'back.txt'), `the back's top kept ${kept} m after 1.5 s\n`);
  assert.ok(kept > 0.002, `the back's top kept ${kept} m`);
});

test('the cut-away shows the inside: the section where the surface was, its field and plane', async () => {
  await tool('view');
  await page.selectOption('#field', '');  // the plain surface (the stroke showed stiffness)
  await park();
  const a = await project(INSIDE_SEAT);
  const c0 = await colourAt(page, await canvasShot(page, path.join(out, '00_before_cutaway.png')), a);
  await page.check('#cutaway');
  await page.selectOption('#cut-axis', 'x');
  await until(() => app(() => window.__dynsolid.metrics.section && window.__dynsolid.metrics.section.triangles > 0),
    'a section drawn', 30000);
  const s = await app(() => window.__dynsolid.metrics.section);
  assert.ok(Math.abs(s.point.x - 0.25) < 0.05, `the plane at x = ${s.point.x}`);
  assert.ok(s.cells_cut > 10, `${s.cells_cut} cells cut`);
  await sleep(300);
  const c1 = await colourAt(page, await canvasShot(page, path.join(out, '01_cutaway_strain.png')), a);
  // The surface there was the chair's (red above blue); the section is
  // viridis (blue or green above red).
  assert.ok(c0[0] > c0[2], `the surface at the seat's middle: ${c0}`);
  assert.ok(c1[2] > c1[0] || c1[1] > c1[0], `the section at the seat's middle: ${c1}`);
  assert.match(await page.textContent('#cut-status'), /^strain .* cells cut/);
  // Stiffness: the stiff legs (10 MPa) and the chair (3 MPa) and its clay
  // back (1 MPa) show as a range.
  await page.selectOption('#cut-field', 'stiffness');
  await until(() => app(() => window.__dynsolid.metrics.section.field === 'stiffness'), 'the stiffness section');
  const k = await app(() => window.__dynsolid.metrics.section);
  assert.ok(k.range[1] > 2 * k.range[0], `stiffness from ${k.range[0]} to ${k.range[1]} Pa`);
  assert.match(await page.textContent('#cut-status'), /^stiffness .* Pa/);
  // The plane moves with the slider.
  await page.fill('#cut-pos', '20');
  await page.dispatchEvent('#cut-pos', 'input');
  await until(() => app(() => window.__dynsolid.metrics.section.point.x < 0.2), 'the plane moved');
  await page.fill('#cut-pos', '50');
  await page.dispatchEvent('#cut-pos', 'input');
  await until(() => app(() => Math.abs(window.__dynsolid.metrics.section.point.x - 0.25) < 0.05), 'the plane back');
  // The picture: the section face on (the side view looks along -x), a
  // little from above.
  await page.click('#view-buttons [data-view=side]');
  await app(() => { const v = window.__dynsolid.view; v.camera.position.z += 0.4; v.camera.lookAt(0.25, 0.25, 0.55); v.needsRender = true; });
  await until(() => app(() => window.__dynsolid.metrics.section.normal.x > 0), 'the section facing the side view');
  await sleep(600);
  const file = path.join(out, 'viewer-cutaway.png');
  await page.screenshot({ path: file });
  if (process.env.DYNSOLID_DOCS_PICTURES === '1') fs.copyFileSync(file, path.join(REPO, 'docs/viewer-cutaway.png'));
  // Off: the surface whole again, nothing cut.
  await page.uncheck('#cutaway');
  await sleep(300);
  const c2 = await colourAt(page, await canvasShot(page, null), a);
  assert.ok(c2[0] > c2[2], `the surface back at the seat's middle: ${c2}`);
});

test('the design downloaded as a scene file and as glTF', async () => {
  for (const [format, check] of [
    ['scene', (b) => assert.match(b.toString('utf8', 0, 200), /^# dynsolid scene: a design saved by Export SCENE/)],
    ['glb', (b) => assert.equal(b.toString('latin1', 0, 4), 'glTF')]]) {
    if (await page.isHidden('#download-menu')) await page.click('#download');
    const event = page.waitForEvent('download', { timeout: 120000 });
    await page.click(`#download-formats button[data-format=${format}]`);
    const d = await event;
    const file = path.join(out, d.suggestedFilename());
    await d.saveAs(file);
    check(fs.readFileSync(file));
  }
  const downloads = await app(() => window.__dynsolid.metrics.downloads);
  assert.deepEqual(downloads.map((d) => d.ok), [true, true]);
  assert.match(downloads[0].file_name, /^chair-step\d+-level2\.textproto$/);
});
