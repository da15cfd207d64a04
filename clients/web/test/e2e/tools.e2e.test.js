// Every other tool of the viewer, through the page's buttons and pointer,
// checked on the server: pin and unpin, inflate, the mass brush, a curve,
// subdivide, delete, sharp edges, merge (a refusal shown with the server's
// text, then a handle between two extruded columns), pause/step/resume.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startViewer, outDir, pageHelpers, until as waitFor, sleep } from './harness.js';

const out = outDir('tools');
let server;
let env;
let page;
let grpc;
let ref;
let lastClick = null;

// Waits like harness.until; a timeout also says what the page said.
const until = (predicate, what, ms) => waitFor(predicate, what, ms).catch(async (e) => {
  const m = await page.evaluate(() => [window.__dynsolid.metrics.messages.map((x) => x.text).slice(-6),
    window.__dynsolid.metrics.presses.slice(-4), window.__dynsolid.tools.tool]);
  m.push(lastClick);
  throw new Error(`${e.message}; the page said ${JSON.stringify(m)}`);
});
const { shotTo, project, tool, banner } = pageHelpers(() => page);
const shot = shotTo(out);
const stats = () => grpc.call('GetStats', ref);
const log = async () => (await grpc.call('GetCommandLog', { session: ref })).entries;
// The log entries after the first `n`, once they include `kind`.
const logged = (n, kind) => until(async () => {
  const e = (await log()).slice(n);
  return e.some((x) => x.kind === kind) ? e : null;
}, `${kind} in the command log`, 60000);
// Waits until the page shows the server's current topology.
const caughtUp = async () => {
  const v = (await stats()).topology_version;
  await until(() => page.evaluate((t) => window.__dynsolid.decoder.topologyVersion >= t, v),
    `the page at topology ${v}`);
  await sleep(200);
};
// The highest point of the drawn surface above the square of side 1 around
// (x, 2.5): a column's top wherever the column leans now.
const columnTop = (x) => page.evaluate((cx) => {
  const pos = window.__dynsolid.view.geometry.getAttribute('position');
  let best = null;
  for (let i = 0; i < pos.count; ++i) {
    const p = { x: pos.getX(i), y: pos.getY(i), z: pos.getZ(i) };
    if (Math.abs(p.x - cx) < 0.5 && Math.abs(p.y - 2.5) < 0.5 && (!best || p.z > best.z)) best = p;
  }
  return { x: best.x, y: best.y, z: best.z - 0.05 };
}, x);
const clickAt = async (point, dy = 0) => {
  const a = await project(point);
  lastClick = await page.evaluate(({ x, y }) => {
    const e = document.elementFromPoint(x, y);
    return { x, y, at: e ? `${e.tagName}#${e.id}` : null };
  }, { x: a.x, y: a.y + dy });
  await page.mouse.click(a.x, a.y + dy);
};

before(async () => {
  env = await startViewer(out);
  ({ server, page, grpc } = env);
  await page.click('#create');
  await until(() => page.evaluate(() => window.__dynsolid.metrics.framesRendered > 2), 'the solid drawn', 60000);
  ref = await page.evaluate(() => window.__dynsolid.session);
});

after(() => env && env.close());

test('pause, step and resume from the buttons', async () => {
  await page.click('#pause');
  const paused = await until(async () => { const s = await stats(); return s.paused ? s : null; }, 'paused');
  await page.click('#step');
  await until(async () => (await stats()).step === paused.step + 1, 'one step');
  await page.click('#resume');
  await until(async () => !(await stats()).paused, 'running again');
});

test('pin a region and unpin it', async () => {
  const n = (await log()).length;
  await tool('pin');
  await clickAt({ x: 2.5, y: 1.5, z: 3 }, 3);
  const e = await logged(n, 'fix_region');
  assert.equal(e.find((x) => x.kind === 'fix_region').code, 0);
  // The page learns the pin from Inspect, then unpins the one under the cursor.
  await until(() => page.evaluate(() => window.__dynsolid.inspect.constraints.length > 0), 'the pin on the page');
  await shot('01_pinned');
  await tool('unpin');
  await clickAt({ x: 2.5, y: 1.5, z: 3 }, 3);
  const u = await logged(n, 'unfix');
  assert.equal(u.find((x) => x.kind === 'unfix').code, 0);
});

test('inflate while held: a pressure load, removed on release', async () => {
  const n = (await log()).length;
  await tool('inflate');
  const a = await project({ x: 1.5, y: 1.5, z: 3 });
  await page.mouse.move(a.x, a.y + 3);
  await page.mouse.down();
  await logged(n, 'add_pressure');
  await sleep(300);
  await page.mouse.up();
  const e = await logged(n, 'remove_load');
  assert.deepEqual(e.map((x) => [x.kind, x.code]), [['add_pressure', 0], ['remove_load', 0]]);
  // Held and let go: one undo entry (one gesture), not a "remove load"
  // whose undo would put back a pressure nobody holds.
  const h = (await grpc.call('Inspect', { session: ref, history: true })).history;
  const last = h.entries[h.entries.length - 1];
  assert.equal(last.what, 'inflate, released', JSON.stringify(h.entries.map((x) => x.what)));
});

test('the mass brush paints density: the mass field changes', async () => {
  await page.selectOption('#field', 'mass');
  const before = (await stats()).fields_version;
  await tool('mass');
  await clickAt({ x: 0.5, y: 0.5, z: 3 }, 3);
  await until(async () => (await stats()).fields_version > before, 'the paint applied');
  await until(() => page.evaluate(() => {
    const f = window.__dynsolid.decoder.fields.mass;
    return f && Math.max(...f) > 2000;
  }), 'the painted density on the page (the field is 1000 kg/m^3 unpainted)');
  await sleep(300);
  await shot('02_mass_painted');
  await page.selectOption('#field', '');
});

test('a curve: points clicked on the solid, one of them dragged', async () => {
  const n = (await log()).length;
  await tool('curve');
  const pts = [{ x: 0.3, y: 0, z: 2.7 }, { x: 1.5, y: 0, z: 2.7 }, { x: 2.7, y: 0, z: 2.7 }];
  for (const p of pts) {
    await clickAt(p);
    await sleep(200);
  }
  await until(() => page.evaluate(() => window.__dynsolid.tools.curvePoints.length === 3), 'three curve points');
  const mid = await page.evaluate(() => window.__dynsolid.view.project(window.__dynsolid.tools.curvePoints[1].point));
  await page.mouse.move(mid.x, mid.y);
  await page.mouse.down();
  for (let i = 1; i <= 8; ++i) {
    await page.mouse.move(mid.x, mid.y - 6 * i);
    await sleep(40);
  }
  await page.mouse.up();
  const e = await logged(n, 'remove_load');
  const kinds = e.map((x) => x.kind);
  assert.equal(kinds[0], 'curve');
  assert.ok(kinds.includes('move_drag'), kinds.join());
  assert.ok(e.every((x) => x.code === 0), JSON.stringify(e));
});

test('subdivide a cell, then delete one: the control mesh follows', async () => {
  const s0 = await stats();
  await tool('subdivide');
  await clickAt({ x: 0.5, y: 0, z: 0.5 });  // the front bottom-left cell
  const s1 = await until(async () => { const s = await stats(); return s.control_cells > s0.control_cells ? s : null; },
    'the subdivision', 60000);
  assert.equal(s1.control_cells, s0.control_cells + 7, 'one cell became eight');
  await tool('delete');
  await clickAt({ x: 2.5, y: 0, z: 2.5 });  // the front top-right cell
  const s2 = await until(async () => { const s = await stats(); return s.control_cells < s1.control_cells ? s : null; },
    'the deletion', 60000);
  assert.equal(s2.control_cells, s1.control_cells - 1);
  await sleep(500);
  await shot('03_subdivided_deleted');
});

test('sharp: a click near a control edge toggles its tag', async () => {
  const sharpCount = async () => {
    const r = await grpc.call('Inspect', { session: ref, control_mesh: true });
    return r.control_mesh.edge_sharp.filter(Boolean).length;
  };
  await page.check('#show-control');
  const before = await sharpCount();
  await tool('sharp');
  // Near the top edge x = 1..2, y = 1 (inside the top face, close to it).
  await clickAt({ x: 1.5, y: 1.05, z: 3 });
  const after = await until(async () => { const c = await sharpCount(); return c !== before ? c : null; }, 'a sharp tag changed');
  assert.equal(Math.abs(after - before), 1);
  await page.uncheck('#show-control');
});

test('merge: a refusal shows the server\'s text; two extruded columns joined by a handle', async () => {
  // Two columns on the top (the +y-most row is still whole: y 2..3).
  await tool('extrude');
  await page.fill('#params input[data-param=extrudeLayers]', '2');
  await page.dispatchEvent('#params input[data-param=extrudeLayers]', 'change');
  await page.fill('#params input[data-param=extrudeDistance]', '1');
  await page.dispatchEvent('#params input[data-param=extrudeDistance]', 'change');
  // The block at rest first (the edits before this test set it moving;
  // damping: motion decays in about 1 s of simulated time), as before each
  // column's click.
  const rest = async () => {
    const settled = (await stats()).step + 2000;
    await until(async () => ((await stats()).step >= settled) || null, 'the block at rest', 120000);
    await caughtUp();
  };
  let cells = (await stats()).control_cells;
  for (const x of [0.5, 2.5]) {
    await rest();
    await clickAt({ x, y: 2.5, z: 3 }, 2);
    cells = await until(async () => { const s = await stats(); return s.control_cells > cells ? s.control_cells : null; },
      `the column at x = ${x}`, 60000).catch(async (e) => { await shot(`column_${x}_failed`); throw e; });
  }
  // Paused from here to the handle: the columns (soft, local-frame model)
  // lean under gravity, and the clicks below aim at faces where they stand,
  // once they have stopped swaying.
  await rest();
  await page.click('#pause');
  await until(async () => (await stats()).paused, 'paused');
  // Refused: the two columns' top faces (parallel, facing the same way),
  // clicked where each top is now (1 m in 2 layers: near z = 4, leaning
  // by as much as the column swayed when paused).
  await tool('merge');
  await clickAt(await columnTop(0.5), 4);
  await sleep(300);
  await clickAt(await columnTop(2.5), 4);
  await until(async () => /refused/.test(await banner()), 'the refusal on the page', 60000).catch(async (e) => {
    await shot('merge_failed');
    const m = await page.evaluate(() => window.__dynsolid.metrics.messages.map((x) => x.text));
    throw new Error(`${e.message}; messages ${JSON.stringify(m)}; log ${JSON.stringify(await log())}`);
  });
  assert.match(await banner(), /refused \(\w+\): .*merge/i);
  assert.match(await banner(), /^(Merge|Those|That)/, 'a plain sentence first');
  assert.equal((await stats()).control_cells, cells, 'nothing changed');
  // The facing sides x = 1 and x = 2 of the upper layer: look at each from
  // the gap between the columns (as a person would orbit there).
  const look = (eye, target) => page.evaluate(({ eye, target }) => {
    const v = window.__dynsolid.view;
    v.camera.position.set(eye.x, eye.y, eye.z);
    v.controls.target.set(target.x, target.y, target.z);
    v.controls.update();
    v.needsRender = true;
  }, { eye, target });
  const centre = async () => {
    const box = await page.locator('#view canvas').boundingBox();
    await page.mouse.click(box.x + box.width / 2, box.y + box.height / 2);
  };
  // Where those sides are now: half a layer below the lower column top,
  // the drawn surface's points nearest the gap from either side.
  const sides = await page.evaluate(({ l, r }) => {
    const pos = window.__dynsolid.view.geometry.getAttribute('position');
    const z = Math.min(l.z, r.z) - 0.2;
    let left = null, right = null;
    for (let i = 0; i < pos.count; ++i) {
      const p = { x: pos.getX(i), y: pos.getY(i), z: pos.getZ(i) };
      if (Math.abs(p.y - 2.5) > 0.25 || Math.abs(p.z - z) > 0.15) continue;
      if (p.x < (l.x + r.x) / 2 && (!left || p.x > left.x)) left = p;
      if (p.x > (l.x + r.x) / 2 && (!right || p.x < right.x)) right = p;
    }
    return { left: { x: left.x, y: 2.5, z }, right: { x: right.x, y: 2.5, z } };
  }, { l: await columnTop(0.5), r: await columnTop(2.5) });
  const gap = (sides.left.x + sides.right.x) / 2;
  await look({ x: gap, y: 2.5, z: sides.left.z }, sides.left);
  await sleep(200);
  await centre();
  await until(async () => /face \d+ chosen/.test(await banner()), 'the first face chosen');
  await look({ x: gap, y: 2.5, z: sides.right.z }, sides.right);
  await sleep(200);
  await centre();
  const merged = await until(async () => { const s = await stats(); return s.control_cells > cells ? s : null; },
    'the handle', 60000);
  assert.equal(merged.control_cells, cells + 1);
  await page.click('#resume');
  await until(async () => !(await stats()).paused, 'running again');
  await caughtUp();
  await page.click('#view-buttons [data-view=iso]');
  await sleep(500);
  await shot('04_handle');
});

test('the picture for the docs: the sculpted block with its stiffness field, control mesh and a pin', async () => {
  await tool('stiffness');
  await page.fill('#params input[data-param=stiffnessValue]', '1e7');
  await page.dispatchEvent('#params input[data-param=stiffnessValue]', 'change');
  await page.selectOption('#field', 'stiffness');
  const before = (await stats()).fields_version;
  await clickAt({ x: 1.5, y: 2, z: 3.75 });  // the handle's side facing the camera
  await until(async () => (await stats()).fields_version > before, 'the paint applied', 60000);
  await tool('pin');
  await clickAt({ x: 0.5, y: 0, z: 1.5 });
  await until(() => page.evaluate(() => window.__dynsolid.inspect.constraints.length > 0), 'the pin drawn');
  await page.check('#show-control');
  await tool('view');
  await page.mouse.move(300, 790);
  await sleep(1500);
  await shot('viewer');
});
