// End-to-end harness: a real dynsolid-server, the real gateway and Debian's
// Chromium driven by playwright-core (no browser download), all on
// loopback. Used by the end-to-end tests and bench/viewer_bench.mjs.
//
// Environment: DYNSOLID_SERVER (the dynsolid-server binary; default
// build/release/server/dynsolid-server), DYNSOLID_CHROMIUM (default
// /usr/bin/chromium), DYNSOLID_E2E_OUT (screenshots; default a temp dir).

import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';
import { loadService, makeClient } from '../../gateway/grpc.js';

const here = path.dirname(fileURLToPath(import.meta.url));
export const WEB_ROOT = path.resolve(here, '../..');
export const REPO = path.resolve(WEB_ROOT, '../..');

export function serverBinary() {
  const bin = process.env.DYNSOLID_SERVER || path.join(REPO, 'build/release/server/dynsolid-server');
  if (!fs.existsSync(bin)) throw new Error(`no dynsolid-server at ${bin} (build it, or set DYNSOLID_SERVER)`);
  return bin;
}

export function outDir(name) {
  const base = process.env.DYNSOLID_E2E_OUT || fs.mkdtempSync(path.join(os.tmpdir(), 'dynsolid_e2e_'));
  const dir = path.join(base, name);
  fs.mkdirSync(dir, { recursive: true });
  return dir;
}

// Every process started here dies with the test process, whatever ends it.
const children = new Set();
process.on('exit', () => {
  for (const c of children) if (c.exitCode === null && c.signalCode === null) c.kill('SIGKILL');
});

// Starts a process and waits for a stdout line matching `ready`; returns
// {proc, match, log()}.
function startProcess(cmd, args, ready, logFile, timeoutMs = 60000) {
  return new Promise((resolve, reject) => {
    const proc = spawn(cmd, args, { stdio: ['ignore', 'pipe', 'pipe'] });
    children.add(proc);
    proc.on('exit', () => children.delete(proc));
    const log = fs.createWriteStream(logFile, { flags: 'a' });
    let out = '';
    const timer = setTimeout(() => {
      proc.kill('SIGKILL');
      reject(new Error(`${path.basename(cmd)} did not start in ${timeoutMs} ms (see ${logFile})`));
    }, timeoutMs);
    proc.stderr.on('data', (d) => log.write(d));
    proc.stdout.on('data', (d) => {
      log.write(d);
      out += d.toString();
      const m = out.match(ready);
      if (m && timer) {
        clearTimeout(timer);
        resolve({ proc, match: m });
      }
    });
    proc.on('exit', (code, signal) => {
      clearTimeout(timer);
      reject(new Error(`${path.basename(cmd)} exited (${code ?? signal}) before it was ready (see ${logFile})`));
    });
  });
}

export class Server {
  // `extra`: more dynsolid-server flags (TLS, replicas); `listen`: the
  // address to bind (default a free port on 127.0.0.1).
  constructor(dir, { extra = [], listen = null, log = 'server.log' } = {}) {
    this.dir = dir;
    this.extra = extra;
    this.listen = listen;
    this.logName = log;
    this.data = path.join(dir, 'data');
    // A new server starts empty (a run never recovers an earlier run's
    // sessions); start() again on the same object keeps the data (restarts).
    fs.rmSync(this.data, { recursive: true, force: true });
    fs.mkdirSync(this.data, { recursive: true });
    this.address = null;
    this.proc = null;
  }

  // Starts (or restarts, on the same address and data dir) the server.
  async start() {
    const listen = this.address || this.listen || '127.0.0.1:0';
    // Snapshots often, so a restart replays few steps. Streaming threads at
    // normal priority: here the browser shares the machine's cores with the
    // server, and its software WebGL would starve SCHED_IDLE threads (the
    // server's default, for a server whose viewers sit elsewhere).
    const { proc, match } = await startProcess(serverBinary(), ['--listen', listen, '--data_dir', this.data,
      '--snapshot_every_steps', '500', '--stream_idle=false', '--stream_nice=0', ...this.extra],
      /listening on (\S+)/, path.join(this.dir, this.logName));
    this.proc = proc;
    this.address = match[1];
    proc.removeAllListeners('exit');
    return this.address;
  }

  kill(signal = 'SIGKILL') {
    return new Promise((resolve) => {
      if (!this.proc || this.proc.exitCode !== null || this.proc.signalCode !== null) {
        resolve();
        return;
      }
      this.proc.once('exit', () => resolve());
      this.proc.kill(signal);
    });
  }
}

export class Gateway {
  // `extra`: more gateway flags (--tls_ca).
  constructor(dir, serverAddress, extra = []) {
    this.dir = dir;
    this.serverAddress = serverAddress;
    this.extra = extra;
  }

  async start() {
    const { proc, match } = await startProcess(process.execPath,
      [path.join(WEB_ROOT, 'gateway/main.js'), '--server', this.serverAddress, '--listen', '127.0.0.1:0',
        ...this.extra],
      /listening on (\S+)/, path.join(this.dir, 'gateway.log'));
    this.proc = proc;
    proc.removeAllListeners('exit');
    this.url = match[1];
    return this.url;
  }

  stop() {
    return new Promise((resolve) => {
      if (!this.proc || this.proc.exitCode !== null) {
        resolve();
        return;
      }
      this.proc.once('exit', () => resolve());
      this.proc.kill('SIGTERM');
    });
  }
}

export async function launchBrowser() {
  const executablePath = process.env.DYNSOLID_CHROMIUM || '/usr/bin/chromium';
  if (!fs.existsSync(executablePath)) {
    throw new Error(`no Chromium at ${executablePath} (scripts/setup_web.sh installs Debian's chromium)`);
  }
  return chromium.launch({
    executablePath,
    // WebGL without a GPU: SwiftShader through ANGLE.
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
      '--no-sandbox'],
  });
}

// A page of the viewer, with its console and errors collected. The help
// overlay a first visit shows is marked seen unless `firstVisit` (it would
// cover the view the tests press on).
export async function openViewer(browser, url, { width = 1280, height = 800, firstVisit = false } = {}) {
  const page = await browser.newPage({ viewport: { width, height } });
  if (!firstVisit) await page.addInitScript(() => localStorage.setItem('dynsolid.help.seen', '1'));
  page.consoleLines = [];
  page.on('console', (m) => page.consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => page.consoleLines.push(`pageerror: ${e.message}`));
  await page.goto(url);
  await page.waitForFunction(() => window.__dynsolid && window.__dynsolid.conn.open, null, { timeout: 20000 });
  return page;
}

// A gRPC client of the server for the tests' own checks (GetStats, Inspect).
export function grpcClient(address) {
  const service = loadService();
  const client = makeClient(service, address);
  const call = (method, request) => new Promise((resolve, reject) => {
    client[method](request, { deadline: new Date(Date.now() + 30000) }, (err, r) => (err ? reject(err) : resolve(r)));
  });
  return { client, call, close: () => client.close() };
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Waits until `predicate()` (async) is truthy; returns its value.
export async function until(predicate, what, timeoutMs = 30000, everyMs = 100) {
  const end = Date.now() + timeoutMs;
  let last;
  for (;;) {
    try {
      last = await predicate();
      if (last) return last;
    } catch (e) {
      last = e;
    }
    if (Date.now() > end) throw new Error(`timed out waiting for ${what} (last: ${last && last.message ? last.message : JSON.stringify(last)})`);
    await sleep(everyMs);
  }
}

// A server, a gateway, Chromium and one viewer page, with a gRPC client of
// the server; close() writes the page's console to `dir` and stops all.
// What the e2e tests ask of a page: app(fn, arg) runs fn in it; messages()
// the texts it said (its metrics); until(...) waits like `until` above and,
// when it gives up, says the page's last six messages. `pageOf()` gives the
// test's page at call time (tests open theirs in `before`).
// Also: shotTo(dir)(name) saves a screenshot as dir/name.png; project(point)
// the client point of a world point; tool(name) clicks a tool's button;
// banner() and hud() their texts ('' when hidden); canvasBox() the canvas'
// box; pullUp(a, from, step, hold) presses `from` px below client point
// `a`, moves up `step` px ten times, 30 ms apart, awaits hold() and lets go
// (whatever hold does).
export function pageHelpers(pageOf) {
  const app = (fn, arg) => pageOf().evaluate(fn, arg);
  const messages = () => app(() => window.__dynsolid.metrics.messages.map((m) => m.text));
  const untilSaid = (predicate, what, ms) => until(predicate, what, ms).catch(async (e) => {
    throw new Error(`${e.message}; the page said ${JSON.stringify((await messages()).slice(-6))}`);
  });
  const shotTo = (dir) => (name) => pageOf().screenshot({ path: path.join(dir, `${name}.png`) });
  const project = (point) => app((q) => window.__dynsolid.view.project(q), point);
  const tool = (name) => pageOf().click(`#tool-buttons [data-tool=${name}]`);
  const shown = (id) => app((i) => (document.getElementById(i).hidden ? ''
    : document.getElementById(i).textContent), id);
  const canvasBox = () => pageOf().locator('#view canvas').boundingBox();
  const pullUp = async (a, from, step, hold) => {
    const mouse = pageOf().mouse;
    await mouse.move(a.x, a.y + from);
    await mouse.down();
    try {
      for (let i = 1; i <= 10; ++i) {
        await mouse.move(a.x, a.y + from - step * i);
        await sleep(30);
      }
      await hold();
    } finally {
      await mouse.up();
    }
  };
  return {
    app, messages, until: untilSaid, shotTo, project, tool, canvasBox, pullUp,
    banner: () => shown('banner'), hud: () => shown('hud'),
  };
}

export async function startViewer(dir) {
  const env = { server: new Server(dir) };
  const address = await env.server.start();
  env.gateway = new Gateway(dir, address);
  env.url = await env.gateway.start();
  env.browser = await launchBrowser();
  env.page = await openViewer(env.browser, env.url);
  env.grpc = grpcClient(address);
  env.close = async () => {
    fs.writeFileSync(path.join(dir, 'console.txt'), env.page.consoleLines.join('\n'));
    await env.browser.close();
    env.grpc.close();
    await env.gateway.stop();
    await env.server.kill('SIGTERM');
  };
  return env;
}
