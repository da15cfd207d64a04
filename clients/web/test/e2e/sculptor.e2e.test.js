// The viewer as a sculptor meets it, on the chair, asserting on
// the camera and the pixels, not only on messages: the tools sized to the
// chair, a missed press that leaves the camera where it was, the orbit
// above the floor, the view presets, the brush disc under the pointer,
// `[`/`]` and Ctrl+wheel, painting that shows the painted field, a default
// inflate that changes the shape by a few percent, Close that asks first.
//
// Screenshots go to $DYNSOLID_E2E_OUT/sculptor/; with
// DYNSOLID_DOCS_PICTURES=1 the last one also becomes docs/viewer.png.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { startViewer, outDir, pageHelpers, sleep, REPO } from './harness.js';
import { canvasShot, colourAt, yellowNear } from './pixels.js';

const out = outDir('sculptor');
let env;
let page;
let grpc;
let ref;

const { app, messages, until, shotTo, project, tool, canvasBox, hud } = pageHelpers(() => page);
const shot = shotTo(out);
const stats = () => grpc.call('GetStats', ref);
const camera = () => app(() => window.__dynsolid.view.camera.matrixWorld.toArray());
const params = () => app(() => ({ ...window.__dynsolid.tools.params }));
// The seat's centre (the chair: x, y 0..0.5 m, seat top at z = 0.5 m).
const SEAT = { x: 0.25, y: 0.2, z: 0.5 };

before(async () => {
  env = await startViewer(out);
  ({ page, grpc } = env);
});

after(() => env && env.close());

test('creating the chair shows progress; its tools are sized to it', async () => {
  await page.selectOption('#scene-select', 'chair');
  await page.click('#create');
  await until(() => app(() => document.querySelector('#banner .progress') !== null), 'a progress banner', 10000);
  await until(() => app(() => window.__dynsolid.sizing && window.__dynsolid.sizing.done), 'the tools sized', 60000);
  ref = await app(() => window.__dynsolid.session);
  const m = await messages();
  assert.ok(m.some((t) => /^creating chair: building the solid/.test(t)), m.join('\n'));
  await until(async () => (await messages()).some((t) => /created chair: .*drawn in \d+ ms/.test(t)), 'the ready message');
  const z = await app(() => window.__dynsolid.sizing.values);
  assert.ok(Math.abs(z.size - 1.2) < 0.05, `size ${z.size}`);
  assert.ok(Math.abs(z.cell - 0.1) < 0.005, `cell ${z.cell}`);
  const p = await params();
  assert.equal(p.radius, 0.15);
  assert.equal(p.extrudeDistance, 0.1);
  assert.ok(p.pressure >= 1e4 && p.pressure <= 1e5, `pressure ${p.pressure}`);
  await tool('extrude');
  assert.equal(await page.inputValue('#params input[data-param=extrudeDistance]'), '0.1');
  // The status line fits the 1280 px window; the full one is its tooltip
  // (refreshed by the page's half-second poll: waited for).
  await until(() => app(() => / corotational_cells \/ central_difference/.test(document.getElementById('status').title)),
    'the status line for the chair');
  const fits = await app(() => { const s = document.getElementById('status'); return [s.scrollWidth, s.clientWidth, s.title]; });
  assert.ok(fits[0] <= fits[1], `status ${fits[0]} px in ${fits[1]} px`);
  assert.match(fits[2], /chair .* corotational_cells \/ central_difference/);
});

test('a missed press in a tool leaves the camera where it was and says "no solid here"', async () => {
  await tool('inflate');
  const box = await canvasBox();
  const before = await camera();
  const n = (await grpc.call('GetCommandLog', { session: ref })).entries.length;
  await app(() => { window.__dynsolid.metrics.messages.length = 0; });
  await page.mouse.move(box.x + 40, box.y + 60);
  await page.mouse.down();
  for (let i = 1; i <= 8; ++i) await page.mouse.move(box.x + 40 + 25 * i, box.y + 60 + 10 * i);
  await page.mouse.up();
  await sleep(200);
  assert.deepEqual(await camera(), before, 'the camera did not move');
  // The HUD shows for 1.5 s, which a loaded machine can outlast before this
  // line runs: the page's message log says it without the clock.
  assert.equal((await messages()).filter((t) => t === 'no solid here').length, 1);
  assert.equal((await grpc.call('GetCommandLog', { session: ref })).entries.length, n, 'no command sent');
  // Alt+drag orbits in a tool.
  await page.keyboard.down('Alt');
  await page.mouse.move(box.x + 40, box.y + 60);
  await page.mouse.down();
  await page.mouse.move(box.x + 140, box.y + 60, { steps: 5 });
  await page.mouse.up();
  await page.keyboard.up('Alt');
  assert.notDeepEqual(await camera(), before, 'Alt+drag orbits');
});

test('the orbit stays above the floor; front, side, top, iso and frame', async () => {
  await tool('view');
  const box = await canvasBox();
  // Dragging up swings the camera down: far past the floor.
  await page.mouse.move(box.x + box.width / 2, box.y + box.height - 40);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2, box.y + 20, { steps: 20 });
  await page.mouse.up();
  const low = await app(() => ({ z: window.__dynsolid.view.camera.position.z, ground: window.__dynsolid.view.groundZ }));
  assert.ok(low.z > low.ground, `camera z ${low.z} above the ground ${low.ground}`);
  await shot('01_lowest_orbit');
  const looking = () => app(() => {
    const v = window.__dynsolid.view;
    const d = v.controls.target.clone().sub(v.camera.position).normalize();
    return [d.x, d.y, d.z];
  });
  await page.click('#view-buttons [data-view=front]');
  let d = await looking();
  assert.ok(d[1] > 0.99, `front looks along +y: ${d}`);
  await page.click('#view-buttons [data-view=side]');
  d = await looking();
  assert.ok(d[0] < -0.99, `side looks along -x: ${d}`);
  await page.keyboard.press('7');
  d = await looking();
  assert.ok(d[2] < -0.99, `top looks down: ${d}`);
  await page.keyboard.press('0');
  d = await looking();
  assert.ok(d[2] < -0.3 && d[1] > 0.5, `iso: ${d}`);
  // Frame: the whole chair on screen from where the camera looks.
  await page.keyboard.press('f');
  const corners = [[0, 0, 0], [0.5, 0.5, 1.2], [0.5, 0, 0], [0, 0.5, 1.2]];
  for (const [x, y, z] of corners) {
    const s = await project({ x, y, z });
    assert.ok(s.x > box.x && s.x < box.x + box.width && s.y > box.y && s.y < box.y + box.height, `corner ${[x, y, z]} at ${JSON.stringify(s)}`);
  }
});

test('the brush disc lies under the pointer; [ and ] and Ctrl+wheel change its radius, shown by the pointer', async () => {
  await tool('stiffness');
  const a = await project(SEAT);
  const box = await canvasBox();
  await page.mouse.move(box.x + 8, box.y + box.height - 8);
  await sleep(200);
  const without = await yellowNear(page, await canvasShot(page, path.join(out, '02_no_disc.png')), a, 70);
  await page.mouse.move(a.x, a.y);
  await until(() => app(() => window.__dynsolid.view.cursor.visible), 'the disc shown');
  await sleep(200);
  const withDisc = await yellowNear(page, await canvasShot(page, path.join(out, '03_disc.png')), a, 70);
  assert.ok(without.share < 0.002, `yellow without the disc: ${without.share}`);
  assert.ok(withDisc.share > 0.02, `yellow around the pointer: ${withDisc.share}`);
  assert.ok(withDisc.centre, 'the disc\'s centre under the pointer');
  await page.keyboard.press(']');
  assert.equal((await params()).radius, 0.188);
  assert.equal(await hud(), 'radius (m): 0.188');
  assert.equal(await page.inputValue('#params input[data-param=radius]'), '0.188');
  await page.keyboard.press('Shift+BracketLeft');
  assert.equal((await params()).strength, 0.8);
  await page.keyboard.down('Control');
  await page.mouse.wheel(0, 100);
  await page.keyboard.up('Control');
  assert.ok((await params()).radius < 0.188, 'Ctrl+wheel down: smaller');
  await page.keyboard.press('[');
  await page.fill('#params input[data-param=radius]', '0.15');
  await page.dispatchEvent('#params input[data-param=radius]', 'change');
  await page.fill('#params input[data-param=strength]', '1');
  await page.dispatchEvent('#params input[data-param=strength]', 'change');
});

test('painting shows the painted field: stiffness, then mass', async () => {
  assert.equal(await page.inputValue('#field'), '');
  const a = await project(SEAT);
  const box = await canvasBox();
  await page.mouse.move(box.x + 8, box.y + box.height - 8);
  await sleep(200);
  const c0 = await colourAt(page, await canvasShot(page, null), a);
  const fields = (await stats()).fields_version;
  await page.mouse.click(a.x, a.y);
  await until(async () => (await stats()).fields_version > fields, 'the stiffness painted', 60000);
  assert.equal(await page.inputValue('#field'), 'stiffness');
  await until(() => app(() => window.__dynsolid.view.range !== null && !document.getElementById('legend').hidden),
    'the stiffness legend');
  await page.mouse.move(box.x + 8, box.y + box.height - 8);
  await sleep(300);
  const c1 = await colourAt(page, await canvasShot(page, path.join(out, '04_painted_stiffness.png')), a);
  // Unpainted clay-coloured (red above blue); painted: a viridis colour
  // (green above blue, from its teal to its yellow end).
  assert.ok(c0[0] > c0[2] + 15, `the plain surface at the seat: ${c0}`);
  assert.ok(c1[1] > c1[2] + 15, `the stiffness colour at the seat: ${c1}`);
  await tool('mass');
  const f2 = (await stats()).fields_version;
  await page.mouse.click(a.x, a.y);
  await until(async () => (await stats()).fields_version > f2, 'the mass painted', 60000);
  assert.equal(await page.inputValue('#field'), 'mass');
  await until(() => app(() => /mass/.test(document.getElementById('legend-title').textContent)), 'the mass legend');
  await page.selectOption('#field', '');
});

test('a default inflate on the seat changes the chair by a few percent, not more', async () => {
  await tool('inflate');
  const rest = (await grpc.call('Inspect', { session: ref, surface_positions: true })).surface_positions;
  const a = await project(SEAT);
  const s0 = (await stats()).step;
  await page.mouse.move(a.x, a.y);
  await page.mouse.down();
  // 0.3 s of simulated time under the pressure.
  await until(async () => (await stats()).step >= s0 + 300, '300 steps held', 120000);
  const held = await grpc.call('Inspect', { session: ref, surface_positions: true });
  await page.mouse.up();
  let most = 0;
  for (let i = 0; i < rest.length; i += 3) {
    most = Math.max(most, Math.hypot(held.surface_positions[i] - rest[i], held.surface_positions[i + 1] - rest[i + 1],
      held.surface_positions[i + 2] - rest[i + 2]));
  }
  const share = most / 1.2;
  assert.ok(share > 0.001 && share < 0.1, `the most a point moved: ${most} m (${(100 * share).toFixed(2)} % of the chair)`);
  fs.writeFileSync(path.join(out, 'inflate.txt'), `default inflate on the seat, 300 steps: ${most} m\n`);
});

test('Close session asks first; Keep keeps it', async () => {
  await page.click('#close-session');
  assert.equal(await page.isVisible('#close-confirm'), true);
  await page.click('#close-no');
  assert.equal(await page.isVisible('#close-confirm'), false);
  assert.ok((await grpc.call('ListSessions', {})).sessions.some((s) => s.id === ref.id), 'still open');
});

test('the picture for the docs: the chair, its stiffness field, the control mesh and the brush disc', async () => {
  await page.check('#show-control');
  await page.selectOption('#field', 'stiffness');
  await tool('stiffness');
  await page.click('#view-buttons [data-view=iso]');
  await sleep(500);
  const a = await project({ x: 0.25, y: 0.45, z: 0.95 });
  await page.mouse.move(a.x - 30, a.y);
  await page.mouse.move(a.x, a.y, { steps: 3 });
  await page.keyboard.press(']');
  await sleep(300);
  const file = path.join(out, 'viewer.png');
  await page.screenshot({ path: file });
  if (process.env.DYNSOLID_DOCS_PICTURES === '1') fs.copyFileSync(file, path.join(REPO, 'docs/viewer.png'));
});
