// A page's bridge (gateway/bridge.js) against a hostile page, in process: its
// session list holds only its own sessions, malformed messages are
// answered, and the per-connection rate limit refuses clearly (a fake
// clock). The old gateway shared one token map between its pages; these
// pages get one too, as the old main.js gave them.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Bridge } from '../../gateway/bridge.js';

// A page's bridge on a fake WebSocket and a fake server with sessions and
// tokens (one gateway: pages share the router, as in main.js).
function pages() {
  const sessions = new Map();
  let next = 1;
  const denied = (cb) => cb({ code: 7, details: 'wrong token' });
  const client = {
    CreateSession: (r, o, cb) => {
      const s = { id: `s${next}`, token: `t${next++}` };
      sessions.set(s.id, s);
      cb(null, { ...s });
    },
    GetSession: (r, o, cb) => (sessions.get(r.id)?.token === r.token ? cb(null, { ...sessions.get(r.id) }) : denied(cb)),
    CloseSession: (r, o, cb) => (sessions.get(r.id)?.token === r.token ? (sessions.delete(r.id), cb(null, {})) : denied(cb)),
    GetServerInfo: (r, o, cb) => cb(null, { peers: [] }),
    ListSessions: (r, o, cb) => cb(null, { sessions: [...sessions.values()].map(({ id }) => ({ id })) }),
  };
  const router = { first: 'x', client: () => client, forSession: () => client, learn: () => {}, follow: () => false, forget: () => {} };
  const tokens = new Map();  // what the old gateway shared between its pages
  const open = (limits = {}) => {
    const sent = [];
    const ws = { readyState: 1, bufferedAmount: 0, send: (m) => sent.push(JSON.parse(m)) };
    const bridge = new Bridge({ ws, service: null, router, tokens, address: 'x', limits });
    const send = (m) => bridge.onMessage(Buffer.from(typeof m === 'string' ? m : JSON.stringify(m)), false);
    const result = (id, method, request) => {
      send({ op: 'call', id, method, request });
      return sent.filter((m) => m.op === 'result' && m.id === id).pop();
    };
    return { sent, send, result };
  };
  return { open };
}

test('a page lists only the sessions it created or joined with their token; no other page\'s token', () => {
  const { open } = pages();
  const a = open();
  const b = open();
  const created = a.result(1, 'CreateSession', {}).response;
  assert.deepEqual(a.result(2, 'ListSessions', {}).response.sessions, [{ id: created.id, token: created.token }]);
  // Page b did not create it: it is not in b's list, token or not.
  assert.deepEqual(b.result(1, 'ListSessions', {}).response.sessions, []);
  // A wrong token does not join it; the right one (a share link) does.
  assert.equal(b.result(2, 'GetSession', { id: created.id, token: 'guess' }).ok, false);
  assert.deepEqual(b.result(3, 'ListSessions', {}).response.sessions, []);
  assert.equal(b.result(4, 'GetSession', { id: created.id, token: created.token }).ok, true);
  assert.deepEqual(b.result(5, 'ListSessions', {}).response.sessions, [{ id: created.id, token: created.token }]);
  // Closed: gone from the list of the page that closed it.
  assert.equal(b.result(6, 'CloseSession', { id: created.id, token: created.token }).ok, true);
  assert.deepEqual(b.result(7, 'ListSessions', {}).response.sessions, []);
});

test('malformed messages get an error or a failed result, and nothing throws', () => {
  const { open } = pages();
  const p = open();
  const bad = ['null', '[1,2]', '"text"', '42', '{"op":"call","id":3,"method":"GetSession","request":"x"}',
    '{"op":"call","id":4,"method":"GetSession","request":[1]}', '{"op":"watch","request":7}',
    '{"op":"command","request":null}', '{"op":"command","request":{"session":5}}'];
  for (const m of bad) assert.doesNotThrow(() => p.send(m), m);
  const answers = p.sent.slice(1);
  assert.equal(answers.length, bad.length);
  assert.deepEqual(answers.slice(0, 4).map((m) => m.op), ['error', 'error', 'error', 'error']);
  assert.match(answers[0].message, /JSON object/);
  assert.deepEqual([answers[4].id, answers[4].ok, answers[4].code_name], [3, false, 'INVALID_ARGUMENT']);
  assert.match(answers[4].message, /request must be a JSON object/);
  assert.deepEqual([answers[5].id, answers[5].code_name], [4, 'INVALID_ARGUMENT']);
  assert.match(answers[6].message, /watch: request must be a JSON object/);
});

test('over the rate: calls get RESOURCE_EXHAUSTED, commands a not-applied reply; later they pass again', () => {
  let now = 0;
  const { open } = pages();
  const p = open({ rate: 10, burst: 2, now: () => now });
  assert.equal(p.sent[0].max_messages_per_second, 10);
  assert.equal(p.result(1, 'ListSessions', {}).ok, true);
  assert.equal(p.result(2, 'ListSessions', {}).ok, true);
  const refused = p.result(3, 'ListSessions', {});
  assert.deepEqual([refused.ok, refused.code_name], [false, 'RESOURCE_EXHAUSTED']);
  assert.match(refused.message, /rate limit \(10 messages\/s, bursts of 2\)/);
  p.send({ op: 'command', request: { session: { id: 's1', token: 't' }, client_id: 'c', seq: 9, command: { pause: {} } } });
  const reply = p.sent[p.sent.length - 1];
  assert.deepEqual([reply.op, reply.reply.seq, reply.reply.code, reply.reply.applied_step], ['reply', 9, 8, -1]);
  p.send({ op: 'unwatch' });
  assert.match(p.sent[p.sent.length - 1].message, /^unwatch: over this connection's rate limit/);
  now += 100;
  assert.equal(p.result(4, 'ListSessions', {}).ok, true);
});
