// The gateway's per-page bridge with a fake WebSocket and a fake gRPC
// client: malformed messages get an error and reach nothing; only the
// listed unary methods pass; a page lists the sessions it created, with
// their tokens, and no others (doors.test.js has more).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { EventEmitter } from 'node:events';
import { Bridge } from '../../gateway/bridge.js';

function fakes() {
  const sent = [];
  const ws = { readyState: 1, bufferedAmount: 0, send: (m) => sent.push(typeof m === 'string' ? JSON.parse(m) : m) };
  const calls = [];
  const streams = [];
  const client = {
    CreateSession: (req, opts, cb) => { calls.push(['CreateSession', req]); cb(null, { id: 'a1', token: 't1', scene_name: 'block3' }); },
    GetServerInfo: (req, opts, cb) => { calls.push(['GetServerInfo', req]); cb(null, { replica: '', peers: [] }); },
    ListSessions: (req, opts, cb) => { calls.push(['ListSessions', req]); cb(null, { sessions: [{ id: 'a1' }, { id: 'b2' }] }); },
    GetStats: (req, opts, cb) => { calls.push(['GetStats', req]); cb({ code: 7, details: 'wrong token' }); },
    Commands: () => {
      const s = new EventEmitter();
      s.written = [];
      s.write = (r) => s.written.push(r);
      s.end = () => { s.ended = true; };
      streams.push(s);
      return s;
    },
  };
  // A server running alone: every session at the first address.
  const router = {
    first: 'x', client: () => client, forSession: () => client,
    learn: () => {}, follow: () => false, forget: () => {},
  };
  const bridge = new Bridge({ ws, service: null, router, address: 'x' });
  const send = (m) => bridge.onMessage(Buffer.from(typeof m === 'string' ? m : JSON.stringify(m)), false);
  return { bridge, sent, calls, streams, send };
}

test('says hello, then refuses what is not a message it takes, calling nothing', () => {
  const { bridge, sent, calls, send } = fakes();
  assert.equal(sent[0].op, 'hello');
  send('{nope');
  send({ op: 'explode' });
  send({ op: 'call', id: 1, method: 'Probe', request: {} });
  send({ op: 'command', request: { command: { pause: {} } } });
  bridge.onMessage(Buffer.from([1, 2, 3]), true);
  assert.match(sent[1].message, /not JSON/);
  assert.match(sent[2].message, /unknown op "explode"/);
  assert.deepEqual([sent[3].ok, sent[3].code_name], [false, 'UNIMPLEMENTED']);
  assert.match(sent[3].message, /does not pass Probe/);
  assert.match(sent[4].message, /session.id is required/);
  assert.match(sent[5].message, /JSON text messages only/);
  assert.equal(calls.length, 0);
});

test('unary calls pass through with their answers and errors; the page\'s own sessions are listed with tokens', () => {
  const { sent, calls, send } = fakes();
  send({ op: 'call', id: 7, method: 'CreateSession', request: { builtin_scene: 'block3' } });
  send({ op: 'call', id: 8, method: 'ListSessions', request: {} });
  send({ op: 'call', id: 9, method: 'GetStats', request: { id: 'a1', token: 'bad' } });
  assert.deepEqual(calls.map((c) => c[0]), ['CreateSession', 'GetServerInfo', 'ListSessions', 'GetStats']);
  assert.deepEqual(sent[1], { op: 'result', id: 7, ok: true, response: { id: 'a1', token: 't1', scene_name: 'block3' } });
  assert.deepEqual(sent[2].response.sessions, [{ id: 'a1', token: 't1' }]);
  assert.deepEqual([sent[3].ok, sent[3].code, sent[3].message], [false, 7, 'wrong token']);
});

test('one command stream per session: switching sessions half-closes the old one; replies come back', () => {
  const { sent, streams, send } = fakes();
  const req = (id, seq) => ({ op: 'command', request: { session: { id, token: 't' }, client_id: 'c', seq, command: { pause: {} } } });
  send(req('a1', 1));
  send(req('a1', 2));
  assert.equal(streams.length, 1);
  assert.deepEqual(streams[0].written.map((r) => r.seq), [1, 2]);
  streams[0].emit('data', { client_id: 'c', seq: 1, code: 0 });
  assert.deepEqual(sent[sent.length - 1], { op: 'reply', reply: { client_id: 'c', seq: 1, code: 0 } });
  send(req('b2', 3));
  assert.equal(streams[0].ended, true);
  assert.equal(streams.length, 2);
  // A broken stream is reported (the page resends); a stale one is not.
  streams[0].emit('error', { code: 14, details: 'gone' });
  assert.notEqual(sent[sent.length - 1].op, 'commands_end');
  streams[1].emit('error', { code: 14, details: 'server gone' });
  assert.deepEqual(sent[sent.length - 1], { op: 'commands_end', code: 14, code_name: 'UNAVAILABLE', message: 'server gone' });
});

test('export: a chunk out of place ends the export with INTERNAL and cancels the call; over the rate it gets export_end', async () => {
  const { loadService } = await import('../../gateway/grpc.js');
  const sent = [];
  const ws = { readyState: 1, bufferedAmount: 0, send: (m) => sent.push(JSON.parse(m)) };
  const stream = new EventEmitter();
  stream.cancel = () => { stream.cancelled = true; };
  const client = {
    CreateSession: (r, o, cb) => cb(null, { id: 'a1', token: 't1' }),
    makeServerStreamRequest: (path, ser, deser, request) => {
      stream.request = request;
      return stream;
    },
  };
  const router = { first: 'x', client: () => client, forSession: () => client, learn: () => {}, follow: () => false, forget: () => {} };
  let now = 0;
  const bridge = new Bridge({ ws, service: loadService(), router, address: 'x', limits: { rate: 1, burst: 3, now: () => now } });
  const send = (m) => bridge.onMessage(Buffer.from(JSON.stringify(m)), false);
  send({ op: 'call', id: 1, method: 'CreateSession', request: {} });
  send({ op: 'export', id: 9, request: { session: { id: 'a1', token: 'ignored' }, format: 'STL', chunk_bytes: 5 } });
  assert.deepEqual([stream.request.session, stream.request.chunk_bytes], [{ id: 'a1', token: 't1' }, 1 << 20]);
  stream.emit('data', { data: Buffer.from('abcd'), offset: 0, total_bytes: 10, file_name: 'f.stl' });
  stream.emit('data', { data: Buffer.from('xy'), offset: 6, total_bytes: 10 });
  assert.deepEqual(sent.slice(2).map((m) => m.op), ['export_start', 'export_chunk', 'export_end']);
  assert.equal(Buffer.from(sent[3].data, 'base64').toString(), 'abcd');
  assert.deepEqual([sent[4].ok, sent[4].code_name], [false, 'INTERNAL']);
  assert.match(sent[4].message, /bytes 6-8 of 10 where 4 of 10 was next/);
  assert.equal(stream.cancelled, true);
  // A server from before Export: UNIMPLEMENTED with no words, said plainly.
  send({ op: 'export', id: 11, request: { session: { id: 'a1' }, format: 'STL' } });
  stream.emit('error', { code: 12, details: '' , message: '12 UNIMPLEMENTED: ' });
  const old = sent[sent.length - 1];
  assert.deepEqual([old.op, old.id, old.code_name], ['export_end', 11, 'UNIMPLEMENTED']);
  assert.match(old.message, /^this dynsolid-server has no Export \(an older build\): 12 UNIMPLEMENTED/);
  send({ op: 'export', id: 10, request: { session: { id: 'a1' }, format: 'STL' } });
  const refused = sent[sent.length - 1];
  assert.deepEqual([refused.op, refused.id, refused.code_name], ['export_end', 10, 'RESOURCE_EXHAUSTED']);
});
