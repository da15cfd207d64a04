// The gateway against real servers, without a browser: a page's WebSocket
// messages (as the page sends them) through the gateway to
//  - a server serving TLS (the gateway given its roots with --tls_ca), and
//  - two replicas on 127.0.0.1 and 127.0.0.2 (docs/deploy.md): a session
//    placed on the second is reached through the first; its calls, watch
//    and commands follow it, and the session list shows both replicas'.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import net from 'node:net';
import path from 'node:path';
import WebSocket from 'ws';
import { Server, Gateway, outDir, until } from './harness.js';

// A page's connection: JSON calls by id, binary frames counted, replies and
// stream ends kept.
async function page(url) {
  const ws = new WebSocket(url.replace(/^http/, 'ws') + 'ws');
  const pending = new Map();
  const seen = { frames: 0, replies: [], ends: [] };
  let next = 1;
  ws.on('message', (data, binary) => {
    if (binary) {
      seen.frames += 1;
      return;
    }
    const m = JSON.parse(data.toString());
    if (m.op === 'result' && pending.has(m.id)) {
      pending.get(m.id)(m);
      pending.delete(m.id);
    } else if (m.op === 'reply') {
      seen.replies.push(m.reply);
    } else if (m.op === 'commands_end' || m.op === 'watch_end') {
      seen.ends.push(m);
    }
  });
  await new Promise((resolve, reject) => {
    ws.once('open', resolve);
    ws.once('error', reject);
  });
  const call = (method, request) => new Promise((resolve) => {
    const id = next++;
    pending.set(id, resolve);
    ws.send(JSON.stringify({ op: 'call', id, method, request }));
  });
  const send = (m) => ws.send(JSON.stringify(m));
  return { call, send, seen, close: () => ws.close() };
}

async function ok(p, method, request) {
  const r = await p.call(method, request);
  assert.ok(r.ok, `${method}: ${r.code_name} ${r.message}`);
  return r.response;
}

// A port free on both loopback addresses.
async function freePort(hosts) {
  for (let attempt = 0; attempt < 50; ++attempt) {
    const port = 20000 + Math.floor(Math.random() * 30000);
    let free = true;
    for (const host of hosts) {
      free = free && await new Promise((resolve) => {
        const s = net.createServer();
        s.once('error', () => resolve(false));
        s.listen(port, host, () => s.close(() => resolve(true)));
      });
    }
    if (free) return port;
  }
  throw new Error('no free port');
}

test('the gateway calls a TLS server when given its roots', async () => {
  const dir = outDir('gateway-tls');
  const cert = path.join(dir, 'cert.pem');
  const key = path.join(dir, 'key.pem');
  execFileSync('openssl', ['req', '-x509', '-newkey', 'rsa:2048', '-nodes', '-keyout', key, '-out', cert,
    '-days', '1', '-subj', '/CN=localhost', '-addext', 'subjectAltName=DNS:localhost,IP:127.0.0.1'],
  { stdio: 'ignore' });
  const server = new Server(dir, { extra: ['--tls_cert', cert, '--tls_key', key] });
  const address = await server.start();
  const gateway = new Gateway(dir, address, ['--tls_ca', cert]);
  const url = await gateway.start();
  const p = await page(url);
  try {
    const s = await ok(p, 'CreateSession', { builtin_scene: 'block3', levels_override: 1, start_paused: true });
    const listed = await ok(p, 'ListSessions', {});
    assert.deepEqual(listed.sessions.map((e) => e.id), [s.id]);
    const stats = await ok(p, 'GetStats', { id: s.id, token: s.token });
    assert.equal(stats.step, 0);
  } finally {
    p.close();
    await gateway.stop();
    await server.kill('SIGTERM');
  }
});

test('through one replica, a session on another is created, listed, watched and commanded', async () => {
  const hosts = ['127.0.0.1', '127.0.0.2'];
  const port = await freePort(hosts);
  const peers = hosts.map((h, i) => `r${i}=${h}:${port}`).join(',');
  const servers = hosts.map((h, i) => new Server(outDir(`gateway-r${i}`), {
    listen: `${h}:${port}`, extra: ['--replica', `r${i}`, '--peers', peers, '--sim_threads', '1'],
  }));
  for (const s of servers) await s.start();
  const dir = outDir('gateway-replicas');
  fs.mkdirSync(dir, { recursive: true });
  const gateway = new Gateway(dir, servers[0].address);
  const url = await gateway.start();
  const p = await page(url);
  const pages = [p];
  let fresh = null;
  let third = null;
  try {
    // Placement: the first stays on r0 (a tie), the second goes to r1.
    const a = await ok(p, 'CreateSession', { builtin_scene: 'block3', levels_override: 1 });
    const b = await ok(p, 'CreateSession', { builtin_scene: 'block3', levels_override: 1, start_paused: true });
    assert.deepEqual([a.replica, b.replica], ['r0', 'r1']);
    assert.equal(b.address, `127.0.0.2:${port}`);
    assert.ok(b.id.startsWith('r1.'));
    // The list merges both replicas'.
    const listed = await ok(p, 'ListSessions', {});
    assert.deepEqual(listed.sessions.map((e) => e.id).sort(), [a.id, b.id].sort());
    // Calls, a watch and commands on r1's session, all through r0's gateway.
    const ref = { id: b.id, token: b.token };
    await ok(p, 'GetStats', ref);
    await ok(p, 'Inspect', { session: ref, control_mesh: true });
    p.send({ op: 'watch', request: { session: ref, rate_hz: 30 } });
    p.send({ op: 'command', request: { session: ref, client_id: 'page', seq: 1, command: { step: { count: 20 } } } });
    await until(() => p.seen.replies.some((r) => r.seq === 1), 'the step command\'s reply');
    assert.equal(p.seen.replies.find((r) => r.seq === 1).code, 0);
    await until(() => p.seen.frames > 0, 'frames of the session on r1');
    const stats = await until(async () => {
      const st = await ok(p, 'GetStats', ref);
      return st.step === 20 ? st : null;
    }, 'the 20 steps on r1');
    assert.equal(stats.step, 20);
    assert.equal(p.seen.ends.filter((e) => e.code !== 0).length, 0, JSON.stringify(p.seen.ends));

    // A second gateway that has not seen the session: r0 redirects every
    // call, and the gateway follows. A redirected command stream ends "OK"
    // and the page sends its unanswered command again (same seq).
    fresh = new Gateway(dir, servers[0].address);
    const p2 = await page(await fresh.start());
    pages.push(p2);
    const step5 = { op: 'command', request: { session: ref, client_id: 'page2', seq: 1, command: { step: { count: 5 } } } };
    p2.send(step5);  // its first message: the gateway knows nothing yet
    await until(() => p2.seen.ends.some((e) => e.op === 'commands_end') || p2.seen.replies.length > 0,
      'the redirected command stream');
    const end = p2.seen.ends.find((e) => e.op === 'commands_end');
    assert.ok(end && end.code === 0 && /lives on replica r1/.test(end.message), JSON.stringify(p2.seen));
    p2.send(step5);
    await until(() => p2.seen.replies.some((r) => r.seq === 1), 'the resent command\'s reply');
    assert.equal(p2.seen.replies.find((r) => r.seq === 1).code, 0);
    p2.send({ op: 'watch', request: { session: ref, rate_hz: 30 } });
    await until(() => p2.seen.frames > 0, 'frames through the second gateway');
    await until(async () => (await ok(p2, 'GetStats', ref)).step === 25, 'the 5 more steps on r1');

    // And a watch as a fresh gateway's first call: redirected, followed.
    third = new Gateway(dir, servers[0].address);
    const p3 = await page(await third.start());
    pages.push(p3);
    p3.send({ op: 'watch', request: { session: ref, rate_hz: 30 } });
    await until(() => p3.seen.frames > 0, 'frames of a watch redirected to r1');
    assert.equal(p3.seen.ends.length, 0, JSON.stringify(p3.seen.ends));
  } finally {
    for (const q of pages) q.close();
    if (fresh) await fresh.stop();
    if (third) await third.stop();
    await gateway.stop();
    for (const s of servers) await s.kill('SIGTERM');
  }
});
