// The gateway's routing across replicas: the redirect a server sends (an
// RpcStatus in grpc-status-details-bin, written here by hand from
// service.proto), and a page's calls, watch and commands following it.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { EventEmitter } from 'node:events';
import { Bridge } from '../../gateway/bridge.js';
import { Router, parseRedirect } from '../../gateway/router.js';
import { Writer } from './pbwriter.js';

const utf8 = new TextEncoder();
const str = (w, field, s) => w.bytes(field, utf8.encode(s));

// FAILED_PRECONDITION with RpcStatus{code, message, details: [Any(SessionRedirect)]}.
function redirectError(id, replica, address, typeUrl = 'type.googleapis.com/dynsolid.SessionRedirect') {
  const redirect = new Writer();
  str(redirect, 1, id);
  str(redirect, 2, replica);
  str(redirect, 3, address);
  const any = new Writer();
  str(any, 1, typeUrl);
  any.message(2, redirect);
  const status = new Writer().uint(1, 9);
  str(status, 2, `session ${id} lives on replica ${replica} at ${address}`);
  status.message(3, any);
  const bytes = Buffer.from(status.finish());
  return {
    code: 9,
    details: `session ${id} lives on replica ${replica} at ${address}`,
    metadata: { get: (key) => (key === 'grpc-status-details-bin' ? [bytes] : []) },
  };
}

test('a redirect is read from the status details; anything else is not one', () => {
  assert.deepEqual(parseRedirect(redirectError('r1.ab', 'r1', '127.0.0.2:50051')),
    { session_id: 'r1.ab', replica: 'r1', address: '127.0.0.2:50051' });
  assert.equal(parseRedirect({ code: 9, details: 'x', metadata: { get: () => [] } }), null);
  assert.equal(parseRedirect({ ...redirectError('a', 'r1', 'h:1'), code: 5 }), null);
  assert.equal(parseRedirect(redirectError('a', 'r1', 'h:1', 'type.googleapis.com/other.Thing')), null);
  const broken = redirectError('a', 'r1', 'h:1');
  const bytes = broken.metadata.get('grpc-status-details-bin')[0].subarray(0, 9);
  broken.metadata = { get: () => [bytes] };
  assert.equal(parseRedirect(broken), null);
});

// Two replicas as fake clients: "a" (the gateway's --server) redirects
// every call on session r1.x to "b", which answers.
function twoReplicas() {
  const calls = [];
  const streams = [];
  const replica = (name, owns) => ({
    GetStats: (req, opts, cb) => {
      calls.push([name, 'GetStats', req.id]);
      if (req.id === owns) cb(null, { step: 5 });
      else cb(redirectError('r1.x', 'r1', 'b'));
    },
    Commands: () => {
      const s = new EventEmitter();
      s.replica = name;
      s.written = [];
      s.write = (r) => s.written.push(r);
      s.end = () => {};
      streams.push(s);
      return s;
    },
  });
  const router = new Router(null, 'a');
  router.clients.set('a', replica('a', 'r0.y'));
  router.clients.set('b', replica('b', 'r1.x'));
  const sent = [];
  const ws = { readyState: 1, bufferedAmount: 0, send: (m) => sent.push(JSON.parse(m)) };
  const bridge = new Bridge({ ws, service: null, router, address: 'a' });
  const send = (m) => bridge.onMessage(Buffer.from(JSON.stringify(m)), false);
  return { router, calls, streams, sent, send };
}

test('a unary call on a session elsewhere is asked again where it lives, and later calls go there first', () => {
  const { calls, sent, send } = twoReplicas();
  send({ op: 'call', id: 1, method: 'GetStats', request: { id: 'r1.x', token: 't' } });
  assert.deepEqual(calls, [['a', 'GetStats', 'r1.x'], ['b', 'GetStats', 'r1.x']]);
  assert.deepEqual(sent[sent.length - 1], { op: 'result', id: 1, ok: true, response: { step: 5 } });
  send({ op: 'call', id: 2, method: 'GetStats', request: { id: 'r1.x', token: 't' } });
  assert.deepEqual(calls[2], ['b', 'GetStats', 'r1.x']);
});

test('a redirected command stream ends OK for the page, which resends; the new stream opens at the owner', () => {
  const { streams, sent, send } = twoReplicas();
  const req = (seq) => ({ op: 'command', request: { session: { id: 'r1.x', token: 't' }, client_id: 'c', seq, command: { pause: {} } } });
  send(req(1));
  assert.equal(streams[0].replica, 'a');
  streams[0].emit('error', redirectError('r1.x', 'r1', 'b'));
  assert.deepEqual(sent[sent.length - 1].op, 'commands_end');
  assert.equal(sent[sent.length - 1].code, 0);
  send(req(1));  // the page's resend: same seq
  assert.equal(streams[1].replica, 'b');
  assert.deepEqual(streams[1].written.map((r) => r.seq), [1]);
});
