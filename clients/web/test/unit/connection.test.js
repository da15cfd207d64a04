// The page's connection: unary calls, and commands sent exactly once across
// broken command streams and a lost gateway (same client_id and seq).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Connection, Code } from '../../public/js/connection.js';

class FakeSocket {
  constructor(url) {
    this.url = url;
    this.sent = [];
    FakeSocket.all.push(this);
  }
  send(text) { this.sent.push(JSON.parse(text)); }
  close() { this.onclose && this.onclose(); }
  openNow() { this.onopen(); }
  receive(m) { this.onmessage({ data: typeof m === 'string' ? m : JSON.stringify(m) }); }
}
FakeSocket.all = [];

function setup() {
  FakeSocket.all = [];
  const timers = [];
  let now = 0;
  const conn = new Connection({
    url: 'ws://x/ws', makeSocket: (u) => new FakeSocket(u), now: () => now,
    setTimeout: (f, ms) => timers.push({ f, at: now + ms }), clientId: 'web-test',
  });
  const socket = () => FakeSocket.all[FakeSocket.all.length - 1];
  socket().openNow();
  const runTimers = () => {
    const due = timers.splice(0);
    for (const t of due) t.f();
  };
  return { conn, socket, runTimers, advance: (ms) => { now += ms; } };
}

const SESSION = { id: 's1', token: 't1' };

test('a unary call resolves with the response or rejects with the server\'s code and text', async () => {
  const { conn, socket } = setup();
  const p = conn.call('GetStats', { id: 's1' });
  const m = socket().sent[0];
  assert.equal(m.op, 'call');
  assert.equal(m.method, 'GetStats');
  socket().receive({ op: 'result', id: m.id, ok: true, response: { step: 7 } });
  assert.deepEqual(await p, { step: 7 });
  const q = conn.call('Pick', {});
  socket().receive({ op: 'result', id: socket().sent[1].id, ok: false, code: 3,
    code_name: 'INVALID_ARGUMENT', message: 'direction: must not be zero' });
  await assert.rejects(q, (e) => e.code === 3 && /must not be zero/.test(e.message));
});

test('commands carry increasing seq; replies resolve them; refusals carry the server\'s message', async () => {
  const { conn, socket, advance } = setup();
  conn.setSession(SESSION);
  const a = conn.command({ pause: {} });
  const b = conn.command({ edit: { delete_cells: { cells: [99] } } });
  const sent = socket().sent.filter((m) => m.op === 'command');
  assert.deepEqual(sent.map((m) => m.request.seq), [1, 2]);
  assert.equal(sent[0].request.client_id, 'web-test');
  assert.deepEqual(sent[0].request.session, SESSION);
  advance(12);
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 1, code: 0, applied_step: 5 } });
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 2, code: 3, applied_step: 5,
    message: 'command.edit.delete_cells.cells[0]: 99 outside [0, 27)' } });
  assert.equal((await a).applied_step, 5);
  await assert.rejects(b, /cells\[0\]: 99 outside/);
  assert.equal(conn.latencyMedian(), 12);
});

test('after the command stream breaks, unanswered commands are resent with the same seq, once answered never again', async () => {
  const { conn, socket, runTimers } = setup();
  conn.setSession(SESSION);
  const a = conn.command({ pause: {} });
  const b = conn.command({ resume: {} });
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 1, code: 0, applied_step: 3 } });
  await a;
  socket().sent = [];
  socket().receive({ op: 'commands_end', code: Code.UNAVAILABLE, message: 'server gone' });
  runTimers();
  const resent = socket().sent.filter((m) => m.op === 'command').map((m) => m.request.seq);
  assert.deepEqual(resent, [2]);
  // The server answers the resend (a duplicate if it had applied it).
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 2, code: 0, applied_step: 3, duplicate: true } });
  assert.equal((await b).duplicate, true);
  // A repeated answer for an answered seq is ignored.
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 2, code: 0, applied_step: 3 } });
});

test('a lost gateway: calls fail, the socket reconnects, the watch and pending commands are sent again', () => {
  const { conn, socket, runTimers } = setup();
  conn.setSession(SESSION);
  conn.watch({ session: SESSION, rate_hz: 60 });
  conn.command({ step: { count: 1 } });
  const call = conn.call('GetStats', SESSION);
  const states = [];
  conn.onState = (s) => states.push(s);
  socket().close();
  assert.deepEqual(states, ['closed']);
  runTimers();  // reconnect
  assert.equal(FakeSocket.all.length, 2);
  socket().openNow();
  const ops = socket().sent.map((m) => m.op);
  assert.deepEqual(ops, ['watch', 'command']);
  assert.equal(socket().sent[1].request.seq, 1);
  return assert.rejects(call, (e) => e.code === Code.UNAVAILABLE);
});

test('a rate-limited command (never applied) goes again with the same seq', () => {
  const { conn, socket, runTimers } = setup();
  conn.setSession(SESSION);
  conn.command({ pause: {} });
  socket().sent = [];
  socket().receive({ op: 'reply', reply: { client_id: 'web-test', seq: 1, code: Code.RESOURCE_EXHAUSTED, applied_step: -1 } });
  runTimers();
  assert.deepEqual(socket().sent.map((m) => m.request.seq), [1]);
});

test('frames arrive as bytes, other messages as JSON', () => {
  const { conn, socket } = setup();
  const got = [];
  conn.onFrame = (b) => got.push(b);
  socket().onmessage({ data: new Uint8Array([8, 1]).buffer });
  assert.equal(got.length, 1);
  assert.deepEqual([...got[0]], [8, 1]);
  const errors = [];
  conn.onError = (e) => errors.push(e);
  socket().receive('{not json');
  assert.match(errors[0], /bad JSON/);
});

test('leaving a session fails its pending commands instead of sending them to the next one', async () => {
  const { conn } = setup();
  conn.setSession(SESSION);
  const a = conn.command({ pause: {} });
  conn.setSession({ id: 's2', token: 't2' });
  await assert.rejects(a, /left the session/);
  assert.equal(conn.pending.size, 0);
});

test('a call or command over the gateway\'s message limit (from its hello) is refused here, not sent', async () => {
  const { conn, socket } = setup();
  socket().receive({ op: 'hello', server: 'x', gateway: 'dynsolid-web', max_message_bytes: 200 });
  conn.setSession(SESSION);
  await assert.rejects(conn.call('CreateSession', { scene_text: 'x'.repeat(300) }),
    (e) => e.code === Code.RESOURCE_EXHAUSTED && /more than the gateway takes in one message \(200\)/.test(e.message));
  await assert.rejects(conn.command({ curve: { points: 'y'.repeat(300) } }), /more than the gateway takes/);
  assert.equal(socket().sent.length, 0);
  // What fits still goes.
  conn.call('GetStats', SESSION);
  assert.equal(socket().sent.length, 1);
});
