// The viewer's hints on block3, asserted on pixels and the page's state, not
// on time: the help overlay on a first visit (remembered, reopened with
// ?), the scene picker's size of a scene built here, Extrude and Merge lighting the control face under the pointer (green:
// taken, blue: merge's first, red: refused with the reason by the pointer),
// and a topology edit shown as "building…" with the seconds so far.
//
// Screenshots go to $DYNSOLID_E2E_OUT/hover/.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import path from 'node:path';
import { startViewer, openViewer, outDir, pageHelpers, sleep } from './harness.js';
import { canvasShot, share } from './pixels.js';

const out = outDir('hover');
let env;
let page;
let grpc;
let ref;

const { app, messages, until, project, tool, canvasBox, hud } = pageHelpers(() => page);
const stats = () => grpc.call('GetStats', ref);
const hover = () => app(() => window.__dynsolid.faceHover.face);
// The highlight colours over the clay-coloured surface (view.js
// FACE_COLORS at 55 %): green above red and blue, red well above green,
// blue above red.
const GREEN = (r, g, b) => g > r + 40 && g > b + 30;
const RED = (r, g, b) => r > g + 60 && r > b + 60;
const BLUE = (r, g, b) => b > r + 50 && b > g + 15;
// The top face of block3's middle cell (the block: 3 m cubed, cells 1 m).
const TOP = { x: 1.5, y: 1.5, z: 3 };
// Away from the solid (the canvas' lower left corner).
const away = async () => {
  const box = await canvasBox();
  await page.mouse.move(box.x + 8, box.y + box.height - 8);
};

before(async () => {
  env = await startViewer(out);
  ({ page, grpc } = env);
});

after(() => env && env.close());

test('a first visit shows the help; Got it closes it for good; ? opens it again, Esc closes it', async () => {
  const first = await openViewer(env.browser, env.url, { firstVisit: true });
  try {
    const visible = () => first.isVisible('#help');
    assert.equal(await visible(), true, 'shown on the first visit');
    assert.match(await first.textContent('#help'), /\[.*\].*brush radius/s);
    await first.screenshot({ path: path.join(out, '01_help.png') });
    await first.click('#help-close');
    assert.equal(await visible(), false);
    assert.equal(await first.evaluate(() => localStorage.getItem('dynsolid.help.seen')), '1');
    await first.reload();
    await first.waitForFunction(() => window.__dynsolid && window.__dynsolid.conn.open);
    assert.equal(await visible(), false, 'not shown again');
    await first.keyboard.press('?');
    assert.equal(await visible(), true, '? opens it');
    await first.keyboard.press('Escape');
    assert.equal(await visible(), false, 'Esc closes it');
    await first.click('#help-open');
    assert.equal(await visible(), true, 'the panel\'s ? button opens it');
    // A click beside the card closes it.
    await first.mouse.click(1270, 790);
    assert.equal(await visible(), false);
    assert.deepEqual(first.consoleLines.filter((l) => /^(error|pageerror)/.test(l)), []);
  } finally {
    await first.close();
  }
});

test('the scene picker says what each scene is for and its size, from the server (ListScenes)', async () => {
  await until(() => app(() => /control cells/.test(document.getElementById('scene-about').textContent)),
    'the server\'s scene list on the page');
  const about = await page.textContent('#scene-about');
  assert.match(about, /\(27 control cells, 1\.7k cells at level 2; 3\.0 x 3\.0 x 3\.0 m\)$/, about);
  assert.ok(about.length > 60, `a description, not just a size: ${about}`);
  assert.equal(await page.textContent('#scene-select option[value=block3]'), 'block3 · 1.7k cells');
  assert.equal(await page.textContent('#scene-select option[value=chair]'), 'chair · 4.9k cells');
  // A scene the page's own list lacks is added from the server's.
  assert.equal(await page.textContent('#scene-select option[value=clay]'), 'clay · 3.1k cells');
  await page.selectOption('#scene-select', 'chair');
  assert.match(await page.textContent('#scene-about'), /chair .*\(76 control cells, 4\.9k cells at level 2; 0\.50 x 0\.50 x 1\.2 m\)$/);
  await page.selectOption('#scene-select', 'block3');
  await page.click('#create');
  await until(() => app(() => window.__dynsolid.sizing && window.__dynsolid.sizing.done), 'block3 drawn and sized', 60000);
  ref = await app(() => window.__dynsolid.session);
});

test('block3: Extrude lights the control face under the pointer, and only there', async () => {
  await tool('extrude');
  const a = await project(TOP);
  await away();
  await sleep(300);
  assert.equal(await hover(), null, 'nothing lit off the solid');
  const off = await share(page, await canvasShot(page, path.join(out, '02_no_hover.png')), a, 25, GREEN);
  await page.mouse.move(a.x - 20, a.y);
  await page.mouse.move(a.x, a.y, { steps: 2 });
  const h = await until(async () => { const f = await hover(); return f && f.ok ? f : null; }, 'the face under the pointer', 30000);
  await sleep(300);
  const on = await share(page, await canvasShot(page, path.join(out, '03_extrude_hover.png')), a, 25, GREEN);
  assert.ok(off < 0.01, `green without hovering: ${off}`);
  assert.ok(on > 0.5, `green around the pointer: ${on}`);
  // The lit face is the top face of the middle cell: its rest centroid.
  const c = await app((f) => {
    const m = window.__dynsolid.inspect.mesh;
    const s = [0, 0, 0];
    const n = m.face_offsets[f + 1] - m.face_offsets[f];
    for (let k = m.face_offsets[f]; k < m.face_offsets[f + 1]; ++k) {
      for (let i = 0; i < 3; ++i) s[i] += m.rest_positions[3 * m.face_vertices[k] + i] / n;
    }
    return s;
  }, h.face);
  assert.ok(Math.hypot(c[0] - TOP.x, c[1] - TOP.y, c[2] - TOP.z) < 1e-6, `face ${h.face} centred at ${c}`);
  // Off the solid again: the light goes.
  await away();
  await until(async () => (await hover()) === null, 'the light gone');
});

test('an extrude shows "building…" with the seconds until the server answers', async () => {
  const a = await project(TOP);
  const cells = (await stats()).control_cells;
  // Every text the banner shows, as it shows it (the building state may
  // last less than a frame on a quick server).
  await app(() => {
    window.__bannerTexts = [];
    const b = document.getElementById('banner');
    new MutationObserver(() => {
      const t = b.querySelector('.text');
      if (t) window.__bannerTexts.push(t.textContent);
    }).observe(b, { childList: true, subtree: true, characterData: true });
  });
  await page.mouse.click(a.x, a.y);
  await until(async () => (await stats()).control_cells > cells, 'the extruded cell', 60000);
  await until(async () => (await messages()).some((t) => /^extrude face \d+: extruded/.test(t)), 'the summary');
  const texts = await app(() => window.__bannerTexts);
  assert.ok(texts.some((t) => /^extrude face \d+: building… \d+\.\d s$/.test(t)), JSON.stringify(texts));
  assert.ok((await messages()).some((t) => /^extrude face \d+: building…$/.test(t)));
  assert.equal(await app(() => window.__dynsolid.feedback.inProgress), false, 'the building state ended');
});

test('Merge: the first face stays lit in blue; the same face again is lit red with the reason', async () => {
  await tool('merge');
  // The front face (y = 0) of the middle cell of the bottom row... of the
  // side facing the camera in the iso view: x = 1.5, z = 1.5.
  const FRONT = { x: 1.5, y: 0, z: 1.5 };
  await page.click('#view-buttons [data-view=iso]');
  await sleep(300);
  const a = await project(FRONT);
  await page.mouse.move(a.x, a.y, { steps: 2 });
  await until(async () => { const f = await hover(); return f && f.ok ? f : null; }, 'the first face lit');
  await page.mouse.click(a.x, a.y);
  await until(async () => (await messages()).some((t) => /^merge: face \d+ chosen/.test(t)), 'the first face chosen');
  await away();
  await until(async () => (await hover()) === null, 'the pointer off the solid');
  await sleep(300);
  const chosen = await share(page, await canvasShot(page, path.join(out, '04_merge_chosen.png')), a, 20, BLUE);
  assert.ok(chosen > 0.5, `blue at the chosen face: ${chosen}`);
  // The same face again: not one merge takes.
  await page.mouse.move(a.x + 3, a.y, { steps: 2 });
  const f = await until(async () => { const x = await hover(); return x && !x.ok ? x : null; }, 'the refused face');
  assert.match(f.why, /already chosen/);
  assert.match(await hud(), /^merge: the face already chosen/);
  await sleep(300);
  const refused = await share(page, await canvasShot(page, path.join(out, '05_merge_refused.png')), a, 20, RED);
  assert.ok(refused > 0.5, `red at the refused face: ${refused}`);
  // Esc drops the first face: nothing blue is left.
  await away();
  await page.keyboard.press('Escape');
  await sleep(300);
  const after = await share(page, await canvasShot(page, null), a, 20, BLUE);
  assert.ok(after < 0.01, `blue after Esc: ${after}`);
  assert.deepEqual(page.consoleLines.filter((l) => /^(error|pageerror)/.test(l)), []);
});
