#!/usr/bin/env node
// The viewer's benchmark: in headless Chromium on this machine
// (WebGL on SwiftShader: no GPU), against a real dynsolid-server and the
// gateway:
//   1. frame time drawing block3 at 2 levels while it moves (requestAnimationFrame
//      intervals, frames drawn per second; the ceiling is the display rate);
//   2. time from joining a session to its first picture (fresh pages);
//   3. a drag's round trip: pointer move -> move_drag applied at step s ->
//      the first frame drawn at a step after s, p50 and p99.
// Figures are printed and written as JSON; nothing is asserted.
//
//   bash scripts/build.sh dynsolid-server && bash scripts/setup_web.sh
//   node bench/viewer/viewer_bench.mjs [--seconds 10] [--joins 5] [--out bench/reports/viewer/latest.json]

import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { execFileSync } from 'node:child_process';
import { Server, Gateway, launchBrowser, openViewer, until, sleep, REPO }
  from '../../clients/web/test/e2e/harness.js';

const args = { seconds: 10, joins: 5, out: '', levels: 2 };
for (let i = 2; i < process.argv.length; i += 2) {
  const k = process.argv[i].replace(/^--/, '');
  if (!(k in args)) throw new Error(`unknown argument ${process.argv[i]} (--seconds, --joins, --out, --levels)`);
  args[k] = k === 'out' ? process.argv[i + 1] : Number(process.argv[i + 1]);
}

const pct = (values, p) => {
  if (!values.length) return null;
  const s = [...values].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor((p / 100) * s.length))];
};
const fmt = (v) => (v === null || v === undefined ? 'n/a' : v.toFixed(1));

function machine() {
  const cpu = os.cpus()[0] ? os.cpus()[0].model : 'unknown';
  const flags = fs.existsSync('/proc/cpuinfo') ? fs.readFileSync('/proc/cpuinfo', 'utf8') : '';
  const simd = /avx512f/.test(flags) ? 'AVX-512' : /avx2/.test(flags) ? 'AVX2' : 'no AVX2';
  let chromium = 'unknown';
  try {
    chromium = execFileSync(process.env.DYNSOLID_CHROMIUM || '/usr/bin/chromium', ['--version'],
      { encoding: 'utf8' }).trim();
  } catch (e) { /* reported as unknown */ }
  return { cpu, simd, cores: os.cpus().length, chromium, node: process.version };
}

const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'dynsolid_viewer_bench_'));
const server = new Server(dir);
const gateway = new Gateway(dir, await server.start());
const url = await gateway.start();
const browser = await launchBrowser();
const result = { machine: machine(), scene: 'block3', levels: args.levels };
try {
  const page = await openViewer(browser, url);
  await page.fill('#levels', String(args.levels));
  await page.click('#create');
  await until(() => page.evaluate(() => window.__dynsolid.metrics.framesRendered > 5), 'frames', 60000);
  const shareUrl = page.url();
  const info = await page.evaluate(() => ({ vertices: window.__dynsolid.decoder.vertexCount,
    quads: window.__dynsolid.decoder.quads.length / 4, canvas: [window.__dynsolid.view.canvas.width, window.__dynsolid.view.canvas.height] }));
  Object.assign(result, info);

  // 1. Drawing while the solid moves: inflate the top so every frame changes.
  await page.click('#tool-buttons [data-tool=inflate]');
  const top = await page.evaluate(() => window.__dynsolid.view.project({ x: 1.5, y: 1.5, z: 3 }));
  await page.mouse.move(top.x, top.y + 4);
  await page.mouse.down();
  await page.evaluate(() => {
    const m = window.__dynsolid.metrics;
    m.frameTimes.length = 0;
    window.__benchStart = { rendered: m.framesRendered, received: m.framesReceived, skipped: m.skipped, t: performance.now() };
  });
  await sleep(args.seconds * 1000);
  const draw = await page.evaluate(() => {
    const m = window.__dynsolid.metrics;
    const s = window.__benchStart;
    const dt = (performance.now() - s.t) / 1000;
    return { frameTimes: [...m.frameTimes], rendered: (m.framesRendered - s.rendered) / dt,
      received: (m.framesReceived - s.received) / dt, skipped: m.skipped - s.skipped };
  });
  await page.mouse.up();
  // The ceiling: frames drawn per second when every animation frame draws,
  // block3 as it is and an empty scene (clear and composite only) at the
  // same canvas size.
  const ceiling = await page.evaluate(async () => {
    const v = window.__dynsolid.view;
    const rate = async () => {
      const t0 = performance.now();
      let n = 0;
      await new Promise((done) => {
        const f = () => {
          v.needsRender = true;
          n++;
          if (performance.now() - t0 < 3000) requestAnimationFrame(f);
          else done();
        };
        requestAnimationFrame(f);
      });
      return n / 3;
    };
    const solid = await rate();
    v.mesh.visible = false;
    v.grid.visible = false;
    const empty = await rate();
    v.mesh.visible = true;
    v.grid.visible = true;
    return { solid, empty, software: v.software, material: v.surfaceMaterial.type };
  });
  result.ceiling = ceiling;
  result.draw = {
    rafFps: 1000 / pct(draw.frameTimes, 50), frameMsP50: pct(draw.frameTimes, 50), frameMsP99: pct(draw.frameTimes, 99),
    surfaceFramesDrawnPerSecond: draw.rendered, framesReceivedPerSecond: draw.received, skippedByServer: draw.skipped,
  };

  // 3. Drag round trips: the pointer circles above the top for `seconds`.
  await page.click('#tool-buttons [data-tool=drag]');
  await page.evaluate(() => { window.__dynsolid.metrics.dragRoundTrips.length = 0; });
  await page.mouse.move(top.x, top.y + 4);
  await page.mouse.down();
  const t0 = Date.now();
  for (let i = 0; Date.now() - t0 < args.seconds * 1000; ++i) {
    const a = (i / 60) * 2 * Math.PI;
    await page.mouse.move(top.x + 40 * Math.cos(a), top.y - 40 + 30 * Math.sin(a));
    await sleep(16);
  }
  await page.mouse.up();
  await sleep(500);
  const rts = await page.evaluate(() => [...window.__dynsolid.metrics.dragRoundTrips]);
  result.drag = { samples: rts.length, p50: pct(rts, 50), p99: pct(rts, 99), max: rts.length ? Math.max(...rts) : null };
  await page.close();

  // 2. Joining: fresh pages opening the share link.
  const joins = [];
  for (let i = 0; i < args.joins; ++i) {
    const p = await openViewer(browser, shareUrl);
    const ms = await until(() => p.evaluate(() => window.__dynsolid.metrics.firstPictureMs), 'the first picture', 30000, 20);
    const nav = await p.evaluate(() => performance.now());
    joins.push({ joinToPictureMs: ms, pageLoadToNowMs: nav });
    await p.close();
  }
  result.join = { samples: joins.length, p50: pct(joins.map((j) => j.joinToPictureMs), 50),
    max: Math.max(...joins.map((j) => j.joinToPictureMs)) };
} finally {
  await browser.close();
  await gateway.stop();
  await server.kill('SIGTERM');
}

const m = result.machine;
console.log(`viewer benchmark on ${m.cpu} (${m.cores} cores, ${m.simd}), ${m.chromium} headless, SwiftShader WebGL`);
console.log(`block3 at ${result.levels} levels: ${result.vertices} surface vertices, ${result.quads} quads, canvas ${result.canvas.join('x')}`);
console.log(`draw: ${fmt(result.draw.rafFps)} frames/s (requestAnimationFrame; frame time p50 ${fmt(result.draw.frameMsP50)} ms, p99 ${fmt(result.draw.frameMsP99)} ms); ` +
  `${fmt(result.draw.surfaceFramesDrawnPerSecond)} new surfaces drawn/s of ${fmt(result.draw.framesReceivedPerSecond)} received/s (server skipped ${result.draw.skippedByServer} for this page)`);
console.log(`ceiling (every animation frame draws): block3 ${fmt(result.ceiling.solid)} frames/s, an empty scene ${fmt(result.ceiling.empty)} frames/s ` +
  `(${result.ceiling.software ? 'software WebGL' : 'GPU'}, ${result.ceiling.material})`);
console.log(`first picture after joining: p50 ${fmt(result.join.p50)} ms, max ${fmt(result.join.max)} ms over ${result.join.samples} joins (target 1000 ms)`);
console.log(`drag round trip (pointer move -> first frame showing it): p50 ${fmt(result.drag.p50)} ms, p99 ${fmt(result.drag.p99)} ms over ${result.drag.samples} moves`);
if (args.out) {
  fs.mkdirSync(path.dirname(path.resolve(REPO, args.out)), { recursive: true });
  fs.writeFileSync(path.resolve(REPO, args.out), `${JSON.stringify(result, null, 2)}\n`);
  console.log(`wrote ${args.out}`);
}
fs.rmSync(dir, { recursive: true, force: true });
