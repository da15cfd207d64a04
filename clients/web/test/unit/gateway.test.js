// The real gateway process (gateway/main.js) in front of a fake
// dynsolid-server, on 127.0.0.1 (gatewayproc.js): the gateway's doors as
// a browser or a script meets them. No C++ server, no clock: every step
// waits for the answer it needs.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fakeAndGateway, stopFakeAndGateway, startGateway, openPage, call, get, rawHttp } from './gatewayproc.js';

let fake;
let gw;
before(async () => ({ fake, gw } = await fakeAndGateway()));
after(() => stopFakeAndGateway({ fake, gw }));

const host = () => `127.0.0.1:${gw.port}`;

test('a WebSocket from another origin is refused with 403 and why; the own origin and loopback tools are taken', async () => {
  const evil = await openPage(gw.url, { headers: { Origin: 'http://evil.example' } });
  assert.equal(evil.refused, 403);
  assert.match(evil.body, /Origin http:\/\/evil.example is not this gateway's/);
  const rebound = await openPage(gw.url, { headers: { Origin: `http://evil.example:${gw.port}`, Host: `evil.example:${gw.port}` } });
  assert.equal(rebound.refused, 403);
  assert.match(rebound.body, /host name/);
  for (const headers of [{ Origin: `http://${host()}` }, {}]) {
    const p = await openPage(gw.url, { headers });
    assert.equal(p.refused, undefined, JSON.stringify(headers));
    assert.equal((await p.next()).op, 'hello');
    p.ws.close();
  }
});

test('--allow_origin takes the origins it lists, and only those', async () => {
  const listed = await startGateway(fake.address, ['--allow_origin', 'http://viewer.lan:8080,https://tools.example']);
  try {
    for (const origin of ['http://viewer.lan:8080', 'https://tools.example']) {
      const p = await openPage(listed.url, { headers: { Origin: origin } });
      assert.equal(p.refused, undefined, origin);
      p.ws.close();
    }
    assert.equal((await openPage(listed.url, { headers: { Origin: 'http://viewer.lan:8081' } })).refused, 403);
  } finally {
    await listed.stop();
  }
});

test('malformed URLs get 400 and the gateway stays up', async () => {
  for (const bad of ['/%E0%A4%A', '/%00', '/js/%ff%fe']) {
    const r = await get(gw.port, bad);
    assert.equal(r.status, 400, `${bad}: ${r.text}`);
    assert.match(r.text, /malformed URL/);
  }
  const upgrade = await rawHttp(gw.port, `GET /%E0%A4%A HTTP/1.1\r\nHost: ${host()}\r\nConnection: Upgrade\r\n` +
    'Upgrade: websocket\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n');
  assert.equal(upgrade.status, 400, upgrade.text);
  assert.equal((await get(gw.port, '/')).status, 200);
  assert.equal(gw.proc.exitCode, null);
});

test('a page\'s session list holds only its own sessions: another page gets neither them nor their tokens', async () => {
  const a = await openPage(gw.url);
  const b = await openPage(gw.url);
  const s = (await call(a, 1, 'CreateSession', { builtin_scene: 'block3' })).response;
  assert.deepEqual((await call(a, 2, 'ListSessions', {})).response.sessions.map((e) => [e.id, e.token]), [[s.id, s.token]]);
  const listed = (await call(b, 1, 'ListSessions', {})).response.sessions;
  assert.equal(JSON.stringify(listed).includes(s.token), false, JSON.stringify(listed));
  assert.deepEqual(listed, []);
  // Joined with the share link's token: now b's too.
  assert.equal((await call(b, 2, 'GetSession', { id: s.id, token: s.token })).ok, true);
  assert.deepEqual((await call(b, 3, 'ListSessions', {})).response.sessions.map((e) => [e.id, e.token]), [[s.id, s.token]]);
  a.ws.close();
  b.ws.close();
});

test('a message over --max_message_bytes closes the connection with 1009; the hello names the limit', async () => {
  const small = await startGateway(fake.address, ['--max_message_bytes', '1000']);
  try {
    const p = await openPage(small.url);
    const hello = await p.next();
    assert.equal(hello.max_message_bytes, 1000);
    p.send({ op: 'call', id: 1, method: 'ListSessions', request: {} });
    assert.equal((await p.next()).ok, true);
    p.send({ op: 'call', id: 2, method: 'CreateSession', request: { scene_text: 'x'.repeat(2000) } });
    assert.equal((await p.closed).code, 1009);
    assert.equal((await get(small.port, '/')).status, 200);
  } finally {
    await small.stop();
  }
});

test('with --access_token_file a page needs ?access=TOKEN', async () => {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'gateway_token_'));
  const file = path.join(dir, 'token');
  fs.writeFileSync(file, 'abcdefghijklmnop0123\n');
  const locked = await startGateway(fake.address, ['--access_token_file', file]);
  try {
    const without = await openPage(locked.url);
    assert.equal(without.refused, 403);
    assert.match(without.body, /access token/);
    const p = await openPage(locked.url, { path: 'ws?access=abcdefghijklmnop0123' });
    assert.equal((await p.next()).op, 'hello');
    p.ws.close();
  } finally {
    await locked.stop();
    fs.rmSync(dir, { recursive: true, force: true });
  }
});

test('a taken port or one outside 0-65535 is said plainly, without a stack trace', async () => {
  const taken = await startGateway(fake.address, ['--listen', host()]).then(
    () => assert.fail('a second gateway listened on a taken port'), (e) => e.message);
  assert.match(taken, /cannot listen on 127\.0\.0\.1:\d+: the port is taken/);
  assert.doesNotMatch(taken, /\n\s+at /);
  const range = await startGateway(fake.address, ['--listen', '127.0.0.1:99999']).then(
    () => assert.fail('listened on port 99999'), (e) => e.message);
  assert.match(range, /--listen 127.0.0.1:99999: want HOST:PORT with PORT 0-65535/);
});
