// The viewer end to end in a real browser (Debian's Chromium, headless,
// WebGL on SwiftShader) against a real dynsolid-server and gateway: every
// check goes through the page's own buttons and pointer, and is confirmed
// on the server's side (GetStats, Inspect) or in the pixels.
//
// Screenshots go to $DYNSOLID_E2E_OUT/viewer/ (CTest: build/.../web_e2e).

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import path from 'node:path';
import { startViewer, openViewer, outDir, until, sleep } from './harness.js';
import { canvasShot, colourAt, purpleShare } from './pixels.js';

const out = outDir('viewer');
let server;
let env;
let browser;
let page;
let grpc;
let ref;  // the session {id, token}

const shot = (p, name) => p.screenshot({ path: path.join(out, `${name}.png`) });
const metrics = (p) => p.evaluate(() => {
  const a = window.__dynsolid;
  return { step: a.decoder.step, vertices: a.decoder.vertexCount, topology: a.decoder.topologyVersion,
    frames: a.metrics.framesReceived, rendered: a.metrics.framesRendered, reconnects: a.metrics.reconnects,
    lastError: a.metrics.lastError, messages: a.metrics.messages.map((m) => m.text),
    banner: document.getElementById('banner').hidden ? '' : document.getElementById('banner').textContent,
    status: document.getElementById('status').title, session: a.session, presses: a.metrics.presses,
    camera: a.view.camera.position.toArray(),
    range: a.view.range, legend: document.getElementById('legend-max').textContent };
});
const project = (p, point) => p.evaluate((q) => window.__dynsolid.view.project(q), point);
const tool = (p, name) => p.click(`#tool-buttons [data-tool=${name}]`);
const setParam = async (p, key, value) => {
  await p.fill(`#params input[data-param=${key}]`, String(value));
  await p.dispatchEvent(`#params input[data-param=${key}]`, 'change');
};
const inspect = (extra = {}) => grpc.call('Inspect', { session: ref, ...extra });
const maxZ = (positions) => {
  let m = -Infinity;
  for (let i = 2; i < positions.length; i += 3) m = Math.max(m, positions[i]);
  return m;
};
// Waits for the page to show a frame at or after `step`.
const pageAt = (p, step) => until(async () => (await metrics(p)).step >= step, `the page at step ${step}`);

before(async () => {
  env = await startViewer(out);
  ({ server, browser, page, grpc } = env);
});

after(() => env && env.close());

test('create block3 from the scene picker: the solid appears', async () => {
  await page.selectOption('#scene-select', 'block3');
  await page.click('#create');
  await until(async () => (await metrics(page)).rendered > 2, 'the first frames drawn');
  const m = await metrics(page);
  ref = m.session;
  const s = await grpc.call('GetSession', ref);
  assert.equal(s.scene_name, 'block3');
  assert.equal(s.stats.model, 'corotational_cells');
  const info = await inspect({ surface_positions: true });
  assert.equal(m.vertices, info.surface_vertices);
  // The status line (refreshed twice a second) names the model and integrator.
  await until(async () => /block3 .* corotational_cells \/ central_difference .* steps\/s/.test((await metrics(page)).status),
    'the status line');
  assert.match(page.url(), new RegExp(`#session=${ref.id}&token=${ref.token}`));
  await shot(page, '01_created');
});

test('a second session with the local-frame model from the picker; closed from the page', async () => {
  await page.selectOption('#model-select', 'LOCAL_FRAME');
  await page.click('#create');
  const other = await until(async () => {
    const m = await metrics(page);
    return m.session && m.session.id !== ref.id && m.rendered > 0 ? m : null;
  }, 'the page in the new session', 60000);
  const s = await grpc.call('GetSession', other.session);
  assert.equal(s.stats.model, 'local_frame');
  await until(async () => /local_frame \//.test((await metrics(page)).status), 'the status line naming it');
  // Close asks first (the session ends for everyone on its link).
  await page.click('#close-session');
  await page.click('#close-yes');
  await until(async () => !(await grpc.call('ListSessions', {})).sessions.some((x) => x.id === other.session.id),
    'the session closed');
  // Back to block3's session by its link.
  await page.selectOption('#model-select', '');
  await page.goto(`${page.url().split('#')[0]}#session=${ref.id}&token=${ref.token}`);
  await page.reload();
  await until(async () => {
    const m = await metrics(page);
    return m.session && m.session.id === ref.id && m.rendered > 0;
  }, 'the page back in block3', 30000);
});

test('a scene file with an error is refused with the server\'s message and nothing is created', async () => {
  const before = (await grpc.call('ListSessions', {})).sessions.length;
  await page.setInputFiles('#scene-file', { name: 'broken.textproto', mimeType: 'text/plain',
    buffer: Buffer.from('name: "broken"\nmesh { block { nx: 0 } }\n') });
  await until(async () => /refused/.test((await metrics(page)).banner), 'the refusal on the page');
  const m = await metrics(page);
  // A plain sentence, then the server's own words.
  assert.match(m.banner, /^The scene file has an error; nothing was created\./);
  assert.match(m.banner, /INVALID_ARGUMENT/);
  assert.match(m.banner, /scene_text|nx/);
  assert.equal((await grpc.call('ListSessions', {})).sessions.length, before);
  assert.deepEqual(m.session, ref, 'the page stays in its session');
});

test('drag the top of block3: the server\'s solid moves up, and the drag is gone on release', async () => {
  const rest = await inspect({ surface_positions: true });
  const top0 = maxZ(rest.surface_positions);
  await tool(page, 'drag');
  const a = await project(page, { x: 1.5, y: 1.5, z: 3 });
  await shot(page, '02_before_drag');
  await page.mouse.move(a.x, a.y + 4);
  await page.mouse.down();
  for (let i = 1; i <= 10; ++i) {
    await page.mouse.move(a.x, a.y + 4 - 12 * i);
    await sleep(30);
  }
  // Held: the top rises on the server.
  const lifted = await until(async () => {
    const r = await inspect({ surface_positions: true });
    return maxZ(r.surface_positions) > top0 + 0.05 ? r : null;
  }, 'the top to rise by 5 cm', 30000).catch(async (e) => {
    throw new Error(`${e.message}; page: ${JSON.stringify(await metrics(page))}; server: ${JSON.stringify(await grpc.call('GetStats', ref))}`);
  });
  const lift = maxZ(lifted.surface_positions) - top0;
  await pageAt(page, lifted.step);
  await shot(page, '02_dragging');
  await page.mouse.up();
  const stats = await until(async () => {
    const s = await grpc.call('GetStats', ref);
    return s.commands_applied >= 3 ? s : null;  // drag, moves, remove
  }, 'the drag commands applied');
  assert.ok(lift > 0.05, `lift ${lift}`);
  // Released: the page removed its spring (journaled, applied).
  const log = await until(async () => {
    const l = await grpc.call('GetCommandLog', { session: ref });
    return l.entries.some((e) => e.kind === 'remove_load') ? l : null;
  }, 'the drag released');
  const kinds = log.entries.map((e) => e.kind);
  assert.equal(kinds[0], 'drag');
  assert.ok(kinds.filter((k) => k === 'move_drag').length >= 2, kinds.join());
  assert.equal(kinds[kinds.length - 1], 'remove_load');
  assert.ok(log.entries.every((e) => e.code === 0), JSON.stringify(log.entries));
  assert.equal(stats.commands_rejected ?? 0, 0);
});

// Reads a screenshot of the canvas back in the page: the share of purple
// pixels (the low end of the colour map: red and blue well above green) and
// the colour at `at` (client coordinates), averaged over 5 x 5 pixels.
async function readPixels(p, file, at) {
  const box = await p.locator('#view canvas').boundingBox();
  // Over the canvas but off the solid (its bottom left corner): the tool
  // cursor hides (a move outside the canvas would leave it where the last
  // press was, on the surface).
  await p.mouse.move(box.x + 8, box.y + box.height - 8);
  await sleep(200);
  const s = await canvasShot(p, path.join(out, file));
  return { purple: await purpleShare(p, s), at: await colourAt(p, s, at) };
}

test('paint stiffness: the field colouring changes on screen where the brush went', async () => {
  await page.selectOption('#field', 'stiffness');
  await until(async () => (await metrics(page)).range !== null, 'the stiffness field on the page');
  const centre = { x: 1.5, y: 1.5, z: 3 };
  const before = await readPixels(page, '03_before_paint.png', await project(page, centre));
  const fieldsBefore = (await grpc.call('GetStats', ref)).fields_version;
  await tool(page, 'stiffness');
  await setParam(page, 'stiffnessValue', 1e7);
  const a = await project(page, centre);
  await page.mouse.click(a.x, a.y + 4);
  await until(async () => (await grpc.call('GetStats', ref)).fields_version > fieldsBefore, 'the paint applied');
  await until(async () => {
    const m = await metrics(page);
    return m.range && m.range[1] > 5e6;
  }, 'the painted stiffness on the page');
  await tool(page, 'view');
  const after = await readPixels(page, '04_after_paint.png', await project(page, centre));
  const m = await metrics(page);
  // Unpainted, the field is flat: one middle colour (teal), no purple.
  assert.ok(before.purple < 0.001, `purple before painting: ${before.purple}`);
  assert.ok(before.at[1] > before.at[0], `teal at the brush before: ${before.at}`);
  // Painted: the unpainted solid is the low end (purple), the brush's spot
  // the high end (yellow: red and green above blue).
  assert.ok(after.purple > 0.05, `purple after painting: ${after.purple}`);
  assert.ok(after.at[0] > after.at[2] && after.at[1] > after.at[2], `yellow at the brush: ${after.at}`);
  assert.match(m.legend, /e\+6|e\+7/);
  await shot(page, '05_painted');
});

test('extrude a picked face: the control mesh gains a cell; undo takes it back', async () => {
  const before = await grpc.call('GetStats', ref);
  const verticesBefore = (await metrics(page)).vertices;
  await tool(page, 'extrude');
  // The +x face's centre.
  const a = await project(page, { x: 3, y: 1.5, z: 1.5 });
  await page.mouse.click(a.x, a.y);
  const after = await until(async () => {
    const s = await grpc.call('GetStats', ref);
    return s.control_cells > before.control_cells ? s : null;
  }, 'the extrusion applied', 60000);
  assert.equal(after.control_cells, before.control_cells + 1);
  await until(async () => (await metrics(page)).vertices > verticesBefore, 'the new surface on the page', 30000);
  await sleep(300);
  await shot(page, '06_extruded');
  // Ctrl+Z.
  await page.keyboard.press('Control+z');
  const undone = await until(async () => {
    const s = await grpc.call('GetStats', ref);
    return s.control_cells === before.control_cells ? s : null;
  }, 'the undo applied', 60000);
  assert.equal(undone.redo_depth, 1);
  await until(async () => (await metrics(page)).vertices === verticesBefore, 'the page back to the old surface', 30000);
  await until(async () => /undo/.test((await metrics(page)).messages.join('\n')), 'the undo message');
});

test('a second person joining by the share link sees the first one\'s edits', async () => {
  const second = await openViewer(browser, page.url());
  try {
    await until(async () => (await metrics(second)).rendered > 0, 'the second page drawing');
    const v0 = (await metrics(second)).vertices;
    assert.equal(v0, (await metrics(page)).vertices);
    await tool(page, 'extrude');
    const a = await project(page, { x: 3, y: 1.5, z: 1.5 });
    await page.mouse.click(a.x, a.y);
    await until(async () => (await metrics(second)).vertices > v0, 'the edit on the second page', 60000);
    await shot(second, '07_second_person');
    // The second person grabs the top and closes the tab mid-drag: the
    // first sees the drag (Inspect lists every client's loads), then the
    // server releases it when that page's command stream ends.
    await tool(second, 'drag');
    const b = await project(second, { x: 1.5, y: 1.5, z: 3 });
    await second.mouse.move(b.x, b.y + 4);
    await second.mouse.down();
    await second.mouse.move(b.x, b.y - 30);
    const drags = async () => (await inspect({ loads: true })).loads.filter((l) => l.kind === 'drag');
    const held = await until(async () => { const d = await drags(); return d.length ? d : null; }, 'the drag listed');
    assert.match(held[0].client_id, /^web-/);
    await until(() => page.evaluate(() => window.__dynsolid.inspect.loads.some((l) => l.kind === 'drag')),
      'the first page drawing the second one\'s drag');
    await second.close();
    await until(async () => (await drags()).length === 0, 'the drag released when its page went away', 30000);
  } finally {
    if (!second.isClosed()) await second.close();
  }
});

test('kill -9 the server and restart it: the page says so and reconnects by itself', async () => {
  await page.selectOption('#field', '');
  const stepBefore = (await metrics(page)).step;
  await server.kill('SIGKILL');
  await until(async () => /unavailable|reconnecting/i.test((await metrics(page)).banner), 'the page to say the server is gone', 30000);
  await shot(page, '08_server_gone');
  await server.start();  // same address, same data dir: the session is recovered
  await until(async () => (await metrics(page)).reconnects >= 1, 'the page to reconnect', 60000);
  const m = await until(async () => {
    const x = await metrics(page);
    return x.step > 0 && x.frames > 0 ? x : null;
  }, 'frames again');
  assert.match(m.banner, /reconnected/);
  // The session goes on from its recovered state and the page follows it.
  const s = await grpc.call('GetStats', ref);
  await pageAt(page, s.step);
  assert.ok(m.step > 0, `step ${m.step} (before: ${stepBefore})`);
  await shot(page, '09_reconnected');
});
