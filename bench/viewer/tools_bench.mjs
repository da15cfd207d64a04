// The viewer's tools benchmark (viewer_bench.mjs beside it measures the
// draw rate, first picture and drag round trip): on
// block3 and the chair at 1280x800 in headless Chromium with SwiftShader
// (software WebGL, as the e2e tests), against a real dynsolid-server and
// the gateway on loopback:
//
//  - press to first visible change, per tool: from the pointerdown the page
//    sees to the end of the first drawn frame whose pixels around the press
//    differ from the frame before it (at least 1 % of a 96 x 96 px square
//    changed by more than 24 levels, summed over R, G and B), p50 and p90
//    over REPS presses;
//  - frame time: the intervals between drawn frames while the solid moves
//    (an inflate held for 3 s), p50 and p90.
//
// Prints its figures; asserts nothing on time (the machine is shared).
//
//   node bench/viewer/tools_bench.mjs [--reps N] [--scenes block3,chair] [--out DIR]
//
// Environment as the e2e harness (clients/web/test/e2e/harness.js):
// DYNSOLID_SERVER, DYNSOLID_CHROMIUM.

import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { parseArgs } from 'node:util';
import { startViewer, until, sleep } from '../../clients/web/test/e2e/harness.js';

const { values: args } = parseArgs({ options: {
  reps: { type: 'string', default: '5' },
  scenes: { type: 'string', default: 'block3,chair' },
  out: { type: 'string', default: '' },
} });
const REPS = Math.max(1, Number(args.reps));
const out = args.out || fs.mkdtempSync(path.join(os.tmpdir(), 'tools_bench_'));
fs.mkdirSync(out, { recursive: true });

// Where each scene's tools press (world points on the solid, facing the
// iso camera): block3's middle top face and its front; the chair's seat.
const SCENES = {
  block3: { point: { x: 1.5, y: 1.5, z: 3 }, side: { x: 1.5, y: 0, z: 1.5 } },
  chair: { point: { x: 0.25, y: 0.2, z: 0.5 }, side: { x: 0.25, y: 0.45, z: 0.95 } },
};

// Tools measured, and how: 'hold' (pressed until the change shows), 'drag'
// (pressed, then the pointer moves 40 px up), 'click'; the session goes
// back to its scene after each press; `field`: the field shown before (so
// that painting's switch of the shown field is not what changes the
// pixels).
const TOOLS = [
  { tool: 'drag', how: 'drag' },
  { tool: 'inflate', how: 'hold' },
  { tool: 'deflate', how: 'hold' },
  { tool: 'stiffness', how: 'click', field: 'stiffness' },
  { tool: 'mass', how: 'click', field: 'mass' },
  { tool: 'material', how: 'click', field: 'stiffness' },
  { tool: 'pin', how: 'click', then: 'unpin' },
  { tool: 'extrude', how: 'click' },
  { tool: 'subdivide', how: 'click' },
  { tool: 'delete', how: 'click', at: 'side' },
  { tool: 'sharp', how: 'click' },
];
const WAIT_MS = 6000;  // a press with no visible change by then counts as none

const pct = (xs, q) => {
  if (!xs.length) return NaN;
  const s = [...xs].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor(q * (s.length - 1) + 0.5))];
};
const ms = (v) => (Number.isFinite(v) ? `${v.toFixed(0)} ms` : '–');

// The in-page probe: after every drawn frame, the pixels of a square
// around the press compared with the frame drawn before the press.
async function installProbe(page) {
  await page.evaluate(() => {
    const app = window.__dynsolid;
    const view = app.view;
    const gl = view.renderer.getContext();
    const S = 96;
    const probe = { armed: null, result: null };
    window.__probe = probe;
    const read = (x, y) => {
      const canvas = view.canvas;
      const r = canvas.getBoundingClientRect();
      const sx = canvas.width / r.width;
      const px = Math.round((x - r.left) * sx - S / 2);
      const py = Math.round(canvas.height - (y - r.top) * sx - S / 2);
      const buf = new Uint8Array(S * S * 4);
      gl.readPixels(px, py, S, S, gl.RGBA, gl.UNSIGNED_BYTE, buf);
      return buf;
    };
    const changed = (a, b) => {
      let n = 0;
      for (let i = 0; i < a.length; i += 4) {
        if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 24) n++;
      }
      return n / (a.length / 4);
    };
    const render = view.render.bind(view);
    view.render = (force) => {
      const drew = render(force);
      const p = probe.armed;
      if (drew && p && p.t0 !== null && probe.result === null) {
        const share = changed(p.base, read(p.x, p.y));
        if (share >= 0.01) probe.result = { ms: performance.now() - p.t0, share };
      }
      return drew;
    };
    // Arms at (x, y): the current picture is the baseline; the clock starts
    // at the next pointerdown.
    probe.arm = (x, y) => {
      view.render(true);
      probe.result = null;
      probe.armed = { x, y, base: read(x, y), t0: null };
    };
    probe.quiet = (x, y, forMs) => new Promise((resolve) => {
      view.render(true);
      const base = read(x, y);
      setTimeout(() => { view.render(true); resolve(changed(base, read(x, y))); }, forMs);
    });
    window.addEventListener('pointerdown', () => {
      if (probe.armed && probe.armed.t0 === null) probe.armed.t0 = performance.now();
    }, true);
  });
}

async function waitQuiet(page, a) {
  for (let i = 0; i < 15; ++i) {
    const moved = await page.evaluate(({ x, y }) => window.__probe.quiet(x, y, 300), a);
    if (moved < 0.002) return true;
  }
  return false;
}

async function measurePress(page, t, a) {
  await page.mouse.move(a.x, a.y);
  await waitQuiet(page, a);
  await page.evaluate(({ x, y }) => window.__probe.arm(x, y), a);
  await page.mouse.down();
  if (t.how === 'drag') await page.mouse.move(a.x, a.y - 40, { steps: 4 });
  if (t.how === 'click') await page.mouse.up();
  const result = await until(() => page.evaluate(() => window.__probe.result), 'a visible change', WAIT_MS, 20)
    .catch(() => null);
  if (t.how !== 'click') {
    await sleep(150);
    await page.mouse.up();
  }
  await page.evaluate(() => { window.__probe.armed = null; });
  return result;
}

// The session back to its scene after each press, then a second to settle.
// (Undo is each person's own and takes an action back from the solid as
// it is now: it would not stand up a chair that a drag tipped over.)
async function revertAndSettle(page, grpc, ref) {
  const before = (await grpc.call('GetStats', ref)).topology_version;
  await page.evaluate(() => window.__dynsolid.conn.command({ revert_to_scene: {} }));
  const after = (await grpc.call('GetStats', ref)).topology_version;
  if (after !== before) {
    await until(() => page.evaluate((v) => window.__dynsolid.decoder.topologyVersion >= v, after), 'the revert drawn', 30000);
  }
  await sleep(1000);
}

async function benchScene(env, scene) {
  const { page, grpc } = env;
  await page.selectOption('#scene-select', scene);
  await page.click('#create');
  await until(() => page.evaluate((name) => {
    const app = window.__dynsolid;
    return app.session && app.info && app.info.scene_name === name && app.sizing && app.sizing.done;
  }, scene), `${scene} joined and sized`, 120000);
  const ref = await page.evaluate(() => window.__dynsolid.session);
  await page.click('#view-buttons [data-view=iso]');
  // The solid settles on its floor; meanwhile the simulation's pace: how
  // much simulated time a second of wall time brings on this machine.
  const s0 = await grpc.call('GetStats', ref);
  const w0 = Date.now();
  await sleep(2000);
  const s1 = await grpc.call('GetStats', ref);
  const realTime = ((Number(s1.step) - Number(s0.step)) * s1.time_step) / ((Date.now() - w0) / 1000);
  console.log(`  ${scene.padEnd(7)} simulation at ${realTime.toFixed(2)} x real time`);
  await page.screenshot({ path: path.join(out, `${scene}_before.png`) });
  const results = { realTime };
  for (const t of TOOLS) {
    await page.click(`#tool-buttons [data-tool=${t.tool}]`);
    await page.selectOption('#field', t.field || '');
    await page.evaluate(() => document.activeElement && document.activeElement.blur());
    const where = SCENES[scene][t.at || 'point'];
    const times = [];
    const thenTimes = [];
    let none = 0;
    let thenNone = 0;
    for (let i = 0; i < REPS; ++i) {
      await page.click('#view-buttons [data-view=iso]');
      const a = await page.evaluate((q) => window.__dynsolid.view.project(q), where);
      const r = await measurePress(page, t, a);
      if (r) times.push(r.ms);
      else none++;
      if (t.then) {
        await page.click(`#tool-buttons [data-tool=${t.then}]`);
        const r2 = await measurePress(page, { how: 'click' }, a);
        if (r2) thenTimes.push(r2.ms);
        else thenNone++;
        await page.click(`#tool-buttons [data-tool=${t.tool}]`);
      }
      await revertAndSettle(page, grpc, ref);
    }
    results[t.tool] = { times, none };
    if (t.then) results[t.then] = { times: thenTimes, none: thenNone };
    const line = (name, x) => console.log(`  ${scene.padEnd(7)} ${name.padEnd(10)} press→visible p50 ${ms(pct(x.times, 0.5)).padStart(7)}  p90 ${ms(pct(x.times, 0.9)).padStart(7)}  (${x.times.length} seen${x.none ? `, ${x.none} with no visible change in ${WAIT_MS / 1000} s` : ''})`);
    line(t.tool, results[t.tool]);
    if (t.then) line(t.then, results[t.then]);
  }
  // Frame time while the solid moves: an inflate held for 3 s.
  await page.click('#tool-buttons [data-tool=inflate]');
  await page.selectOption('#field', '');
  await page.click('#view-buttons [data-view=iso]');
  const a = await page.evaluate((q) => window.__dynsolid.view.project(q), SCENES[scene].point);
  await page.mouse.move(a.x, a.y);
  await page.evaluate(() => { window.__dynsolid.metrics.frameTimes.length = 0; });
  await page.mouse.down();
  await sleep(3000);
  const frames = await page.evaluate(() => [...window.__dynsolid.metrics.frameTimes]);
  await page.mouse.up();
  results.frames = { p50: pct(frames, 0.5), p90: pct(frames, 0.9), n: frames.length };
  console.log(`  ${scene.padEnd(7)} frame time p50 ${ms(results.frames.p50)}, p90 ${ms(results.frames.p90)} (${frames.length} frames in 3 s, inflate held)`);
  await page.screenshot({ path: path.join(out, `${scene}.png`) });
  await page.click('#leave');
  return results;
}

const env = await startViewer(out);
const all = {};
try {
  await installProbe(env.page);
  const info = await env.page.evaluate(() => {
    const gl = document.createElement('canvas').getContext('webgl');
    const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
    return { renderer: gl ? gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER) : 'none',
      size: `${innerWidth}x${innerHeight}`, software: window.__dynsolid.view.software };
  });
  console.log(`tools bench: ${info.size}, WebGL ${info.renderer}, ${os.cpus().length} cores (${os.cpus()[0].model}), load ${os.loadavg().map((v) => v.toFixed(1)).join(' ')}, ${REPS} presses per tool`);
  for (const scene of args.scenes.split(',')) all[scene] = await benchScene(env, scene);
  const errors = env.page.consoleLines.filter((l) => /^(error|pageerror)/.test(l));
  if (errors.length) console.log(`console errors: ${errors.join(' | ')}`);
  fs.writeFileSync(path.join(out, 'tools_bench.json'), JSON.stringify({ info, reps: REPS, results: all },
    (k, v) => (typeof v === 'number' ? Math.round(v * 10) / 10 : v), 1));
  console.log(`figures and screenshots in ${out}`);
} finally {
  await env.close();
}
