// The real gateway (gateway/main.js, a child process) in front of a fake
// dynsolid-server (@grpc/grpc-js with the project's service.proto), all on
// 127.0.0.1: the gateway's doors tested without the C++ server. Nothing
// waits on the clock: each step waits for the event it needs.

import { spawn } from 'node:child_process';
import net from 'node:net';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import WebSocket from 'ws';
import { loadService, grpc } from '../../gateway/grpc.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const MAIN = path.resolve(here, '../../gateway/main.js');

// Every gateway started here dies with the test process, whatever ends it.
const children = new Set();
process.on('exit', () => {
  for (const c of children) if (c.exitCode === null && c.signalCode === null) c.kill('SIGKILL');
});

// The file the fake server exports: `size` bytes, byte i = (7 i) mod 251.
export function fakeExportFile(size) {
  const b = Buffer.alloc(size);
  for (let i = 0; i < size; ++i) b[i] = (7 * i) % 251;
  return b;
}

// A fake server: sessions with tokens, every session call checking its token.
// Export (its requests kept in `exports`, each with `cancelled` and
// `whenCancelled` for when the caller goes away): a file of fakeExportFile(10000 + 1000 * level) in
// chunks of chunk_bytes; VTU above level 4 is refused as the real server
// refuses a level over its cell limit; PLY sends its first chunk and then
// waits (for the caller to cancel).
export async function fakeServer() {
  const service = loadService();
  const sessions = new Map();  // id -> {id, token, scene_name}
  const exports = [];
  let next = 1;
  const denied = { code: grpc.status.PERMISSION_DENIED, details: 'wrong token' };
  const check = (ref, cb, ok) => {
    const s = sessions.get(ref && ref.id);
    if (!s) cb({ code: grpc.status.NOT_FOUND, details: 'no such session' });
    else if (s.token !== ref.token) cb(denied);
    else ok(s);
  };
  const impl = {
    CreateSession: ({ request }, cb) => {
      const id = `s${next}`;
      const s = { id, token: `token${next++}`, scene_name: request.builtin_scene || 'scene' };
      sessions.set(id, s);
      cb(null, s);
    },
    GetSession: ({ request }, cb) => check(request, cb, (s) => cb(null, s)),
    ListSessions: (call, cb) => cb(null, { sessions: [...sessions.values()].map(({ id, scene_name }) => ({ id, scene_name })) }),
    CloseSession: ({ request }, cb) => check(request, cb, (s) => {
      sessions.delete(s.id);
      cb(null, {});
    }),
    GetStats: ({ request }, cb) => check(request, cb, () => cb(null, { step: 3 })),
    GetServerInfo: (call, cb) => cb(null, { replica: '', peers: [] }),
    Export: (call) => {
      const r = call.request;
      const seen = { request: r, cancelled: false };
      seen.whenCancelled = new Promise((resolve) => call.on('cancelled', () => {
        seen.cancelled = true;
        resolve();
      }));
      exports.push(seen);
      check(r.session, (e) => call.emit('error', e), (s) => {
        const level = r.level ?? 1;
        const chunk = r.chunk_bytes || (1 << 20);
        if (chunk < 4096 || chunk > (4 << 20)) {
          call.emit('error', { code: grpc.status.INVALID_ARGUMENT,
            details: `request.chunk_bytes: ${r.chunk_bytes} is not 0 or in [4096, 4194304]` });
          return;
        }
        if (r.format === 'VTU' && level > 4) {
          call.emit('error', { code: grpc.status.INVALID_ARGUMENT,
            details: `request.level: ${level} subdivisions of this control mesh (3 cells) give about ` +
              `${3 * 8 ** level} cells, more than the export limit of 2000; ask for a lower level` });
          return;
        }
        const file = fakeExportFile(10000 + 1000 * level);
        const ext = r.format.toLowerCase();
        for (let offset = 0; offset < file.length; offset += chunk) {
          const c = { data: file.subarray(offset, offset + chunk), offset, total_bytes: file.length };
          if (offset === 0) {
            Object.assign(c, { file_name: `${s.scene_name}-step3-level${level}.${ext}`,
              media_type: 'application/octet-stream', step: 3, level, cells: 3 * 8 ** level, surface_faces: 14 });
          }
          call.write(c);
          if (r.format === 'PLY') return;  // never ends: the caller cancels
        }
        call.end();
      });
    },
    Commands: (call) => {
      call.on('data', (r) => check(r.session, (e) => call.write({ client_id: r.client_id, seq: r.seq, code: e.code, message: e.details }),
        () => call.write({ client_id: r.client_id, seq: r.seq, code: 0, applied_step: 1 })));
      call.on('end', () => call.end());
    },
  };
  const server = new grpc.Server();
  server.addService(service.Sessions.service, impl);
  const port = await new Promise((resolve, reject) => {
    server.bindAsync('127.0.0.1:0', grpc.ServerCredentials.createInsecure(), (err, p) => (err ? reject(err) : resolve(p)));
  });
  return { address: `127.0.0.1:${port}`, sessions, exports, stop: () => server.forceShutdown() };
}

// Starts the gateway with `args`; resolves {url, port, proc, out(), stop()}
// once it prints "listening on", rejects if it exits first.
export function startGateway(serverAddress, args = []) {
  const proc = spawn(process.execPath, [MAIN, '--server', serverAddress, '--listen', '127.0.0.1:0', ...args],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  children.add(proc);
  proc.once('exit', () => children.delete(proc));
  let out = '';
  let err = '';
  proc.stderr.on('data', (d) => { err += d; });
  const exited = new Promise((resolve) => proc.once('close', (code, signal) => resolve(code ?? signal)));
  const stop = async () => {
    if (proc.exitCode === null && proc.signalCode === null) proc.kill('SIGKILL');
    await exited;
  };
  return new Promise((resolve, reject) => {
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/listening on (https?:\/\/[^/\s]+\/)/);
      if (m) resolve({ url: m[1], port: Number(new URL(m[1]).port), proc, exited, stop, log: () => err });
    });
    exited.then((code) => reject(new Error(`the gateway exited (${code}) before it listened: ${err}`)));
  });
}

// A fake server and a default gateway in front of it: {fake, gw}.
export async function fakeAndGateway() {
  const fake = await fakeServer();
  return { fake, gw: await startGateway(fake.address) };
}

// Stops what fakeAndGateway started: the gateway, then the fake server.
export async function stopFakeAndGateway({ fake, gw }) {
  await gw.stop();
  fake.stop();
}

// Raw HTTP on a fresh socket: resolves {status, text} or {closed: true} if
// the connection ended without an answer.
export function rawHttp(port, request) {
  return new Promise((resolve) => {
    const s = net.connect(port, '127.0.0.1', () => s.write(request));
    let data = '';
    s.on('data', (d) => { data += d; });
    const done = () => {
      const m = data.match(/^HTTP\/1\.1 (\d+)/);
      resolve(m ? { status: Number(m[1]), text: data } : { closed: true, text: data });
    };
    s.on('end', done);
    s.on('error', done);
  });
}

export function get(port, pathText) {
  return rawHttp(port, `GET ${pathText} HTTP/1.1\r\nHost: 127.0.0.1:${port}\r\nConnection: close\r\n\r\n`);
}

// A page's WebSocket with `headers` (Origin, Host); wss:// for an https://
// gateway, trusting `ca`. Resolves {ws, messages, next()} once open, or
// {refused: status, body} when the upgrade is answered with an HTTP error.
export function openPage(url, { headers = {}, path: wsPath = 'ws', ca } = {}) {
  const ws = new WebSocket(url.replace(/^http/, 'ws') + wsPath, { headers, ...(ca ? { ca } : {}) });
  const messages = [];
  const waiters = [];
  ws.on('message', (data, binary) => {
    const m = binary ? data : JSON.parse(data.toString());
    const w = waiters.shift();
    if (w) w(m);
    else messages.push(m);
  });
  const next = () => new Promise((resolve) => {
    if (messages.length) resolve(messages.shift());
    else waiters.push(resolve);
  });
  const closed = new Promise((resolve) => ws.once('close', (code, reason) => resolve({ code, reason: reason.toString() })));
  return new Promise((resolve, reject) => {
    ws.once('open', () => resolve({ ws, next, closed, send: (m) => ws.send(typeof m === 'string' ? m : JSON.stringify(m)) }));
    ws.once('unexpected-response', (req, res) => {
      let body = '';
      res.on('data', (d) => { body += d; });
      res.on('end', () => resolve({ refused: res.statusCode, body }));
    });
    ws.once('error', reject);
  });
}

// A page's unary call: the result message with this id.
export async function call(page, id, method, request) {
  page.send({ op: 'call', id, method, request });
  for (;;) {
    const m = await page.next();
    if (m.op === 'result' && m.id === id) return m;
  }
}
