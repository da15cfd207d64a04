// The gateway's doors (gateway/guard.js): which WebSocket
// upgrades are taken (Origin, loopback, access token), which request paths
// can be read, and the token bucket of the rate limit, on a fake clock.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { upgradeRefusal, parseOriginList, requestPath, isLoopback, TokenBucket, exposureRefusal, exposureWarning }
  from '../../gateway/guard.js';

// `tls`: the upgrade came on the gateway's TLS port (--tls_cert: WSS).
const req = ({ origin, host = '127.0.0.1:8080', from = '127.0.0.1', url = '/ws', tls = false }) => ({
  url, headers: { ...(origin === undefined ? {} : { origin }), host },
  socket: { remoteAddress: from, ...(tls ? { encrypted: true } : {}) },
});

test('upgrades: same origin on an address or localhost, listed origins, no Origin from loopback only', () => {
  const ok = (r, doors) => assert.equal(upgradeRefusal(req(r), doors), null, JSON.stringify(r));
  const no = (r, pattern, doors) => assert.match(upgradeRefusal(req(r), doors) || 'taken', pattern, JSON.stringify(r));
  ok({ origin: 'http://127.0.0.1:8080' });
  ok({ origin: 'http://localhost:8080', host: 'localhost:8080' });
  ok({ origin: 'http://[::1]:8080', host: '[::1]:8080', from: '::1' });
  ok({ origin: 'http://192.168.1.5:8080', host: '192.168.1.5:8080', from: '192.168.1.9' });
  no({ origin: 'http://evil.example' }, /Origin http:\/\/evil.example is not this gateway's/);
  no({ origin: 'http://127.0.0.1:9999' }, /not this gateway's/);
  no({ origin: 'null' }, /not this gateway's/);
  // A DNS rebinding: evil.example resolved to this machine; Host and Origin agree.
  no({ origin: 'http://evil.example:8080', host: 'evil.example:8080' }, /host name.*--allow_origin/);
  const allow = { allowOrigins: parseOriginList('http://viewer.lan:8080, https://tools.example') };
  ok({ origin: 'http://viewer.lan:8080', host: 'viewer.lan:8080' }, allow);
  ok({ origin: 'https://tools.example' }, allow);
  no({ origin: 'http://tools.example' }, /not this gateway's/, allow);
  ok({ from: '127.0.0.1' });
  ok({ from: '::ffff:127.0.0.1' });
  no({ from: '10.0.0.7' }, /without an Origin header is taken from loopback only/);
  assert.throws(() => parseOriginList('http://ok:1,not an origin'), /"not an origin" is not an origin/);
  assert.deepEqual([isLoopback('127.3.2.1'), isLoopback('::1'), isLoopback('128.0.0.1'), isLoopback(undefined)],
    [true, true, false, false]);
});

test('same origin is scheme, host and port: https on the TLS port (WSS), http on the plain one', () => {
  const ok = (r) => assert.equal(upgradeRefusal(req(r)), null, JSON.stringify(r));
  const no = (r, pattern) => assert.match(upgradeRefusal(req(r)) || 'taken', pattern, JSON.stringify(r));
  ok({ origin: 'https://127.0.0.1:8080', tls: true });
  ok({ origin: 'https://localhost:8443', host: 'localhost:8443', tls: true });
  ok({ origin: 'https://[::1]:8443', host: '[::1]:8443', from: '::1', tls: true });
  // The default port: the browser drops it from Origin, a client may write it in Host.
  ok({ origin: 'https://127.0.0.1', host: '127.0.0.1:443', tls: true });
  ok({ origin: 'http://127.0.0.1', host: '127.0.0.1:80' });
  no({ origin: 'http://127.0.0.1', host: '127.0.0.1:443', tls: true }, /not this gateway's \(https:\/\/127.0.0.1:443\)/);
  // Same host:port, other scheme: another origin.
  no({ origin: 'http://127.0.0.1:8080', tls: true }, /Origin http:\/\/127.0.0.1:8080 is not this gateway's \(https:\/\/127.0.0.1:8080\)/);
  no({ origin: 'https://127.0.0.1:8080' }, /Origin https:\/\/127.0.0.1:8080 is not this gateway's \(http:\/\/127.0.0.1:8080\)/);
  // A WebSocket URL is never a page's origin.
  no({ origin: 'wss://127.0.0.1:8080', tls: true }, /not this gateway's/);
  no({ origin: 'ws://127.0.0.1:8080' }, /not this gateway's/);
  no({ origin: 'https://evil.example', tls: true }, /Origin https:\/\/evil.example is not this gateway's/);
  no({ origin: 'https://evil.example:8080', host: 'evil.example:8080', tls: true }, /host name/);
  // No Origin: loopback only, with or without TLS.
  ok({ tls: true });
  no({ from: '10.0.0.7', tls: true }, /loopback only/);
  assert.throws(() => parseOriginList('wss://127.0.0.1:8080'), /is not an origin/);
  const allow = { allowOrigins: parseOriginList('https://viewer.lan') };
  assert.equal(upgradeRefusal(req({ origin: 'https://viewer.lan', host: 'viewer.lan', tls: true }), allow), null);
});

test('listening beyond loopback needs TLS or an access token; without a token or without TLS it is said', () => {
  for (const address of ['127.0.0.1', '127.0.0.2', '::1', '::ffff:127.0.0.1']) {
    assert.equal(exposureRefusal(address), null, address);
    assert.equal(exposureWarning(address), null, address);
  }
  for (const address of ['0.0.0.0', '::', '', '192.168.1.5', 'fe80::1']) {
    assert.match(exposureRefusal(address), /beyond loopback with neither TLS nor an access token.*plain-text control/, address);
    assert.equal(exposureRefusal(address, { tls: true }), null, address);
    assert.equal(exposureRefusal(address, { accessToken: 'a-long-enough-secret' }), null, address);
    assert.match(exposureWarning(address, { tls: true }), /without --access_token_file/);
    assert.match(exposureWarning(address, { accessToken: 'a-long-enough-secret' }), /without --tls_cert.*plain text/);
    assert.equal(exposureWarning(address, { tls: true, accessToken: 'a-long-enough-secret' }), null);
  }
  assert.match(exposureRefusal('0.0.0.0'), /every interface/);
  assert.match(exposureRefusal('192.168.1.5'), /on 192\.168\.1\.5 /);
});

test('upgrades with an access token: taken only with ?access=TOKEN, whatever the origin', () => {
  const doors = { accessToken: 'a-long-enough-secret' };
  assert.match(upgradeRefusal(req({ origin: 'http://127.0.0.1:8080' }), doors), /access token/);
  assert.match(upgradeRefusal(req({ url: '/ws?access=wrong' }), doors), /access token/);
  assert.equal(upgradeRefusal(req({ url: '/ws?access=a-long-enough-secret' }), doors), null);
});

test('request paths: bad percent-encoding and NUL bytes are not paths', () => {
  assert.equal(requestPath('/js/app.js?x=1'), '/js/app.js');
  assert.equal(requestPath('/a%20b'), '/a b');
  assert.equal(requestPath('/%E0%A4%A'), null);
  assert.equal(requestPath('/%00'), null);
  assert.equal(requestPath('http://['), null);
});

test('a token bucket: a burst at once, then the rate, on a fake clock', () => {
  let now = 0;
  const b = new TokenBucket({ rate: 10, burst: 3, now: () => now });
  assert.deepEqual([b.take(), b.take(), b.take(), b.take()], [true, true, true, false]);
  now += 100;  // one more token
  assert.deepEqual([b.take(), b.take()], [true, false]);
  now += 10000;  // never more than the burst
  assert.deepEqual([b.take(), b.take(), b.take(), b.take()], [true, true, true, false]);
});
