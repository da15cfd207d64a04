// Clay and Bake in the viewer, through the page's own controls:
// the Material brush paints block3 clay, a pull stays after its release,
// Bake makes the pulled shape the rest shape (the status says "baked") and
// Undo takes it back; clay on a local-frame session is refused with the
// server's text.
//
// Screenshots go to $DYNSOLID_E2E_OUT/clay/.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startViewer, outDir, pageHelpers, sleep } from './harness.js';

const out = outDir('clay');
let env;
let page;
let grpc;
let ref;

const { messages, until, shotTo, project, tool, banner, pullUp } = pageHelpers(() => page);
const shot = shotTo(out);
const stats = () => grpc.call('GetStats', ref);
const lastError = () => page.evaluate(() => window.__dynsolid.metrics.lastError);
const setParam = async (key, value) => {
  await page.fill(`#params input[data-param=${key}]`, String(value));
  await page.dispatchEvent(`#params input[data-param=${key}]`, 'change');
};
const maxZ = (xyz) => {
  let m = -Infinity;
  for (let i = 2; i < xyz.length; i += 3) m = Math.max(m, xyz[i]);
  return m;
};
const surfaceTop = async () => maxZ((await grpc.call('Inspect', { session: ref, surface_positions: true }))
  .surface_positions);
const restTop = async () => maxZ((await grpc.call('Inspect', { session: ref, control_mesh: true }))
  .control_mesh.rest_positions);
// Waits until `steps` more steps have run (the solid settling).
const settle = async (steps) => {
  const until0 = (await stats()).step + steps;
  await until(async () => (await stats()).step >= until0, `${steps} steps`, 120000);
};

before(async () => {
  env = await startViewer(out);
  ({ page, grpc } = env);
});

after(() => env && env.close());

test('Bake is disabled until the page joins a session', async () => {
  assert.equal(await page.isDisabled('#bake'), true);
  await page.selectOption('#scene-select', 'block3');
  await page.click('#create');
  await until(() => page.evaluate(() => window.__dynsolid.metrics.framesRendered > 2), 'the solid drawn', 60000);
  ref = await page.evaluate(() => window.__dynsolid.session);
  assert.equal(await page.isDisabled('#bake'), false);
});

test('the Material brush paints clay; a pull then stays after its release', async () => {
  await tool('material');
  assert.equal(await page.inputValue('#params select[data-param=preset]'), 'CLAY');
  const preset = () => page.evaluate(() => window.__dynsolid.tools.params.preset);
  await page.selectOption('#params select[data-param=preset]', 'WAX');
  assert.equal(await preset(), 'WAX');
  await page.selectOption('#params select[data-param=preset]', 'CLAY');
  assert.equal(await preset(), 'CLAY');
  await setParam('radius', 6);  // every control cell
  const fields = (await stats()).fields_version;
  const a = await project({ x: 1.5, y: 1.5, z: 3 });
  await page.mouse.click(a.x, a.y + 4);
  await until(async () => (await stats()).fields_version > fields, 'the clay painted', 60000);
  const log = (await grpc.call('GetCommandLog', { session: ref })).entries;
  assert.deepEqual(log.filter((e) => e.kind === 'paint_material').map((e) => e.code), [0]);
  assert.equal(await lastError(), null);
  await settle(500);
  const top0 = await surfaceTop();
  const lift = await pull(a);
  await settle(3000);  // 3 s of damped motion: rubber would be back
  const kept = (await surfaceTop()) - top0;
  await shot('01_pulled_clay');
  assert.ok(kept > 0.005 && kept < lift, `the top kept ${kept} m of the ${lift} m pull`);
  assert.equal(await lastError(), null);
});

// Drags the point under screen point `a` up by 120 pixels, holds it until
// the top has risen 2.5 cm (clay, twice rubber's stiffness, rises about
// 4.5 cm) and a second more, and lets go; returns the lift.
async function pull(a) {
  const top0 = await surfaceTop();
  await tool('drag');
  await pullUp(a, 4, 12, async () => {
    await until(async () => (await surfaceTop()) > top0 + 0.025, 'the top raised by 2.5 cm', 30000);
    await sleep(1000);
  });
  const lift = (await surfaceTop()) - top0;
  await until(async () => (await grpc.call('GetCommandLog', { session: ref })).entries
    .some((e) => e.kind === 'remove_load'), 'the drag released');
  return lift;
}

test('Bake: the status says baked and the rest shape is the pulled one; Undo takes it back', async () => {
  const rest0 = await restTop();
  const topology = (await stats()).topology_version;
  await page.click('#bake');
  await until(async () => /^bake: .*baked/.test(await banner()), 'the bake\'s summary on the page', 60000);
  assert.equal(await lastError(), null);
  assert.ok((await stats()).topology_version > topology, 'a new topology version');
  const rest1 = await restTop();
  assert.ok(rest1 > rest0 + 0.005, `rest top ${rest0} -> ${rest1}`);
  await shot('02_baked');
  await page.click('#undo');
  await until(async () => Math.abs((await restTop()) - rest0) < 1e-9, 'the rest shape back', 60000);
});

test('clay on a local-frame session: the server\'s refusal shown as is', async () => {
  await page.selectOption('#model-select', 'LOCAL_FRAME');
  await page.click('#create');
  await until(async () => {
    const s = await page.evaluate(() => window.__dynsolid.session);
    return s && s.id !== ref.id;
  }, 'the page in the new session', 60000);
  await until(() => page.evaluate(() => window.__dynsolid.decoder.hasKeyframe), 'the solid drawn', 60000);
  await sleep(500);
  await tool('material');
  const a = await project({ x: 1.5, y: 1.5, z: 3 });
  await page.mouse.click(a.x, a.y + 4);
  await until(async () => /refused \(INVALID_ARGUMENT\): .*COROTATIONAL/.test(await banner()),
    'the refusal on the page', 60000);
  // In plain words first, with what to do.
  assert.match(await banner(), /^This session's material model cannot hold clay\. Create the session with Model: corotational/);
  await shot('03_refused');
  await page.selectOption('#model-select', '');
});
