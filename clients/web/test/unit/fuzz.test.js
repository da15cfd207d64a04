// A fuzz pass over the gateway's message handling: random and
// mutated page messages into a Bridge whose fake server serializes each
// request with the real service.proto (as @grpc/grpc-js does, so a request
// it cannot encode fails as it would). Seeded: the same messages each run.
// Nothing may throw, every call gets its result, everything else that is
// not a message gets an error.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { EventEmitter } from 'node:events';
import { Bridge } from '../../gateway/bridge.js';
import { loadService } from '../../gateway/grpc.js';

const service = loadService();
const methods = service.definition['dynsolid.Sessions'];

function rng(seed) {
  let x = seed >>> 0 || 1;
  return () => {
    x ^= x << 13; x >>>= 0;
    x ^= x >>> 17;
    x ^= x << 5; x >>>= 0;
    return x / 4294967296;
  };
}

// A fake server: requests serialized for real; answers empty.
function fakeClient() {
  const stream = (serialize) => {
    const s = new EventEmitter();
    s.write = (r) => {
      try {
        serialize(r);
      } catch (e) {
        queueMicrotask(() => s.emit('error', { code: 13, details: e.message }));
      }
    };
    s.end = () => {};
    s.cancel = () => {};
    s.pause = () => {};
    s.resume = () => {};
    return s;
  };
  const client = {
    Commands: () => stream(methods.Commands.requestSerialize),
    makeServerStreamRequest: (path, serialize, deserialize, request) => {
      const s = stream(serialize);
      s.write(request);
      return s;
    },
  };
  for (const name of ['CreateSession', 'GetSession', 'ListSessions', 'CloseSession', 'GetStats', 'Inspect', 'Pick', 'Section', 'ListScenes', 'GetServerInfo']) {
    client[name] = (request, options, cb) => {
      try {
        methods[name].requestSerialize(request);
      } catch (e) {
        cb({ code: 13, details: e.message });
        return;
      }
      cb(null, name === 'ListSessions' ? { sessions: [{ id: 's1' }] } : { id: 's1', token: 't1', peers: [] });
    };
  }
  return client;
}

const CORPUS = [
  { op: 'call', id: 1, method: 'CreateSession', request: { builtin_scene: 'block3', levels_override: 1 } },
  { op: 'call', id: 2, method: 'GetSession', request: { id: 's1', token: 't1' } },
  { op: 'call', id: 3, method: 'ListSessions', request: {} },
  { op: 'call', id: 4, method: 'CloseSession', request: { id: 's1', token: 't1' } },
  { op: 'call', id: 5, method: 'Inspect', request: { session: { id: 's1', token: 't1' }, control_mesh: true } },
  { op: 'call', id: 6, method: 'Pick', request: { session: { id: 's1', token: 't1' }, origin: { x: 0, y: 0, z: 5 }, direction: { x: 0, y: 0, z: -1 } } },
  { op: 'watch', request: { session: { id: 's1', token: 't1' }, rate_hz: 30 } },
  { op: 'unwatch' },
  { op: 'command', request: { session: { id: 's1', token: 't1' }, client_id: 'c', seq: 1, command: { step: { count: 2 } } } },
  { op: 'command', request: { session: { id: 's1', token: 't1' }, client_id: 'c', seq: 2, command: { pause: {} } } },
];

function randomValue(r, depth = 0) {
  const k = Math.floor(r() * (depth > 3 ? 6 : 8));
  switch (k) {
    case 0: return null;
    case 1: return Math.floor(r() * 1e6) - 5e5;
    case 2: return [1e308, -0, 2 ** 53 + 1, 0.5, -1][Math.floor(r() * 5)];
    case 3: return ['', 's1', '__proto__', 'constructor', 'toString', '\u0000', 'é'.repeat(50)][Math.floor(r() * 7)];
    case 4: return r() < 0.5;
    case 5: return {};
    case 6: return Array.from({ length: Math.floor(r() * 3) }, () => randomValue(r, depth + 1));
    default: {
      const o = {};
      for (const key of ['op', 'id', 'method', 'request', 'session', 'token', 'command', 'seq', '__proto__']) {
        if (r() < 0.3) o[key] = randomValue(r, depth + 1);
      }
      return o;
    }
  }
}

// One field somewhere in a copy of `m` replaced by a random value.
function mutateValue(r, m) {
  const copy = JSON.parse(JSON.stringify(m));
  let node = copy;
  for (;;) {
    const keys = node && typeof node === 'object' ? Object.keys(node) : [];
    if (!keys.length) break;
    const key = keys[Math.floor(r() * keys.length)];
    if (r() < 0.5 && node[key] && typeof node[key] === 'object') {
      node = node[key];
      continue;
    }
    node[key] = randomValue(r);
    break;
  }
  return JSON.stringify(copy);
}

// Text damage: a cut, a flipped character, an insertion.
function mutateText(r, text) {
  const at = Math.floor(r() * text.length);
  switch (Math.floor(r() * 3)) {
    case 0: return text.slice(0, at);
    case 1: return text.slice(0, at) + String.fromCharCode(Math.floor(r() * 128)) + text.slice(at + 1);
    default: return text.slice(0, at) + ['{', '}', '"', '[', ',', ':', '\\u'][Math.floor(r() * 7)] + text.slice(at);
  }
}

function nextMessage(r) {
  const base = CORPUS[Math.floor(r() * CORPUS.length)];
  const k = r();
  if (k < 0.45) return mutateValue(r, base);
  if (k < 0.8) return mutateText(r, JSON.stringify(base));
  return JSON.stringify(randomValue(r));
}

test('5000 random and mutated messages: nothing throws, every call gets its result, every non-message an error', async () => {
  const r = rng(39);
  const client = fakeClient();
  const router = { first: 'x', client: () => client, forSession: () => client, learn: () => {}, follow: () => false, forget: () => {} };
  const sent = [];
  const ws = { readyState: 1, bufferedAmount: 0, send: (m) => sent.push(typeof m === 'string' ? JSON.parse(m) : m) };
  // tokens: what the old Bridge needed, so that this test runs on it too.
  const bridge = new Bridge({ ws, service, router, tokens: new Map(), address: 'x', limits: { rate: 1e9, burst: 1e9 } });
  for (let i = 0; i < 5000; ++i) {
    const text = nextMessage(r);
    const before = sent.length;
    assert.doesNotThrow(() => bridge.onMessage(Buffer.from(text), false), text);
    let m;
    try {
      m = JSON.parse(text);
    } catch {
      m = undefined;
    }
    const answers = sent.slice(before);
    const isMessage = m !== null && typeof m === 'object' && !Array.isArray(m);
    if (!isMessage) {
      assert.deepEqual(answers.map((a) => a.op), ['error'], text);
    } else if (m.op === 'call') {
      const results = answers.filter((a) => a.op === 'result' && JSON.stringify(a.id) === JSON.stringify(m.id));
      assert.equal(results.length, 1, `${text} -> ${JSON.stringify(answers)}`);
    }
  }
  await new Promise((resolve) => setImmediate(resolve));  // stream errors, emitted later
  bridge.close();
});
