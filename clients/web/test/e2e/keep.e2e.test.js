// Keeping the work in a real browser against a real server and
// gateway: block3 downloaded through the Download menu as glTF (the file's
// glTF header) and STL (84 + 50 n bytes) with the progress bar at 100 %,
// and the Record button: a non-empty WebM download, or disabled with its
// reason where the browser cannot record (headless Chromium may lack the
// encoder). The gateway takes messages of 64 KiB at most, so each file
// comes in several pieces and the bar moves through them. Files go to
// $DYNSOLID_E2E_OUT/keep/.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { Server, Gateway, launchBrowser, openViewer, grpcClient, outDir, until, sleep } from './harness.js';

const out = outDir('keep');
let env;
let page;
let levels;  // the session's subdivision levels

const said = () => page.evaluate(() => window.__dynsolid.metrics.messages.map((m) => m.text).slice(-4));

// Opens the menu (if closed), picks `level` for `format` and clicks it;
// resolves {name, bytes} of the file the browser was given. A refusal
// (the page's downloads log) fails at once with the page's words.
async function download(format, level) {
  if (await page.isHidden('#download-menu')) await page.click('#download');
  await page.selectOption(`#download-formats select[data-level-for=${format}]`, String(level));
  const before = await page.evaluate(() => (window.__dynsolid.metrics.downloads || []).length);
  const event = page.waitForEvent('download', { timeout: 120000 });
  event.catch(() => {});
  await page.click(`#download-formats button[data-format=${format}]`);
  const outcome = await until(() => page.evaluate((n) => (window.__dynsolid.metrics.downloads || [])[n], before),
    `the ${format} download`, 120000);
  if (!outcome.ok) throw new Error(`the ${format} download failed: ${outcome.message}; the page said ${JSON.stringify(await said())}`);
  const d = await event;
  const file = path.join(out, d.suggestedFilename());
  await d.saveAs(file);
  return { name: d.suggestedFilename(), bytes: fs.readFileSync(file) };
}

// The progress bar and what the page computed from offset/total_bytes.
const progress = () => page.evaluate(() => ({ value: document.getElementById('download-progress').value,
  hidden: document.getElementById('download-progress').hidden,
  seen: window.__dynsolid.metrics.downloadProgress, label: document.getElementById('download-status').textContent }));

// The harness's startViewer with a gateway limited to 64 KiB messages.
async function start() {
  const server = new Server(out);
  const address = await server.start();
  const gateway = new Gateway(out, address, ['--max_message_bytes', String(64 << 10)]);
  const url = await gateway.start();
  const browser = await launchBrowser();
  const grpc = grpcClient(address);
  const viewer = await openViewer(browser, url);
  return { page: viewer, grpc, close: async () => {
    fs.writeFileSync(path.join(out, 'console.txt'), viewer.consoleLines.join('\n'));
    await browser.close();
    grpc.close();
    await gateway.stop();
    await server.kill('SIGTERM');
  } };
}

before(async () => {
  env = await start();
  page = env.page;
  await page.selectOption('#scene-select', 'block3');
  await page.click('#create');
  await until(() => page.evaluate(() => window.__dynsolid.metrics.framesRendered > 2), 'block3 drawn', 60000);
  const ref = await page.evaluate(() => window.__dynsolid.session);
  levels = (await env.grpc.call('GetSession', ref)).stats.levels;
});

after(() => env && env.close());

test('the Download menu offers each format at the session\'s level and two finer ones (a scene file: its own)', async () => {
  assert.equal(await page.isDisabled('#download'), false);
  await page.click('#download');
  const menu = await page.evaluate(() => [...document.querySelectorAll('#download-formats .download-row')].map((r) => ({
    format: r.querySelector('button').dataset.format, text: r.querySelector('button').textContent,
    levels: [...r.querySelectorAll('option')].map((o) => Number(o.value)), chosen: Number(r.querySelector('select').value),
  })));
  assert.deepEqual(menu.map((m) => m.format), ['obj', 'stl', 'ply', 'glb', 'vtu', 'scene']);
  for (const m of menu) {
    // A scene file is saved at the session's level only.
    const want = m.format === 'scene' ? [levels] : [levels, levels + 1, levels + 2].filter((l) => l <= 6);
    assert.deepEqual(m.levels, want, m.format);
    assert.equal(m.chosen, levels);
  }
});

test('glTF (.glb) at the session\'s level: a glTF 2.0 binary with the server\'s file name; the progress bar at 100 %', async () => {
  const { name, bytes } = await download('glb', levels);
  assert.match(name, new RegExp(`^block3-step\\d+-level${levels}\\.glb$`));
  assert.ok(bytes.length > 0);
  assert.equal(bytes.toString('latin1', 0, 4), 'glTF');
  assert.equal(bytes.readUInt32LE(4), 2);                 // version
  assert.equal(bytes.readUInt32LE(8), bytes.length);      // the header's length
  // The JSON chunk: glTF 2.0, normals, and colours (by displacement).
  const json = JSON.parse(bytes.toString('utf8', 20, 20 + bytes.readUInt32LE(12)));
  assert.equal(bytes.toString('latin1', 16, 20), 'JSON');
  assert.equal(json.asset.version, '2.0');
  assert.deepEqual(Object.keys(json.meshes[0].primitives[0].attributes).sort(), ['COLOR_0', 'NORMAL', 'POSITION']);
  const p = await progress();
  assert.equal(p.value, 100);
  assert.equal(p.hidden, false);
  assert.equal(p.seen[p.seen.length - 1], 100, JSON.stringify(p.seen));
  // In pieces of 48912 bytes (exportPieceBytes of 64 KiB messages): the bar moved through them.
  assert.equal(p.seen.length, 1 + Math.ceil(bytes.length / 48912), JSON.stringify(p.seen));
  assert.match(p.label, /^saved block3-step\d+-level\d+\.glb/);
});

test('STL one level finer: 84 + 50 n bytes for its n triangles', async () => {
  const { name, bytes } = await download('stl', levels + 1);
  assert.match(name, new RegExp(`^block3-step\\d+-level${levels + 1}\\.stl$`));
  const n = bytes.readUInt32LE(80);
  assert.ok(n > 0);
  assert.equal(bytes.length, 84 + 50 * n);
  const p = await progress();
  assert.equal(p.value, 100);
  assert.equal(p.seen[p.seen.length - 1], 100);
  assert.ok(p.seen.length > 3 && p.seen.some((x) => x > 0 && x < 100), JSON.stringify(p.seen));
});

test('a refused export is said in plain words with the server\'s text', async () => {
  // Beyond the menu's choices: level 7, through the page's own connection.
  const err = await page.evaluate(async () => {
    const a = window.__dynsolid;
    try {
      await a.conn.exportDesign({ session: { id: a.session.id }, format: 'STL', level: 7 });
      return null;
    } catch (e) {
      a.showError(e);
      return { code: e.codeName, message: e.message };
    }
  });
  assert.equal(err.code, 'INVALID_ARGUMENT');
  assert.match(err.message, /level/);
  const banner = await page.textContent('#banner');
  assert.match(banner, /That level is too fine to export for this solid\./);
});

test('Record: a non-empty WebM download, or disabled with its reason', async (t) => {
  const disabled = await page.isDisabled('#record');
  if (disabled) {
    const why = await page.getAttribute('#record', 'title');
    assert.match(why, /cannot record/);
    assert.equal(await page.isVisible('#record-why'), true);
    assert.equal(await page.textContent('#record-why'), why);
    t.diagnostic(`Record is disabled in this browser: ${why}`);
    return;
  }
  assert.equal(await page.textContent('#record'), 'Record');
  await page.click('#record');
  assert.equal(await page.textContent('#record'), 'Stop');
  await sleep(2000);
  const [d] = await Promise.all([page.waitForEvent('download', { timeout: 30000 }), page.click('#record')]);
  const name = d.suggestedFilename();
  assert.match(name, /^block3-\d{8}-\d{6}\.webm$/);
  const file = path.join(out, name);
  await d.saveAs(file);
  const bytes = fs.readFileSync(file);
  assert.ok(bytes.length > 0);
  assert.equal(bytes.readUInt32BE(0), 0x1a45dfa3);  // EBML: a Matroska/WebM file
  assert.equal(await page.textContent('#record'), 'Record');
  t.diagnostic(`recorded ${name}: ${bytes.length} bytes`);
});
