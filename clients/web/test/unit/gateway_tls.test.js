// The real gateway (gatewayproc.js) on its own TLS port (--tls_cert,
// --tls_key: HTTPS and WSS), with a throwaway self-signed certificate for
// 127.0.0.1 made by openssl here, in front of a fake dynsolid-server; and
// where it refuses to start: a TLS flag without its pair, a bad file,
// beyond loopback with neither TLS nor an access token. No clock: every
// step waits for the answer it needs.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import crypto from 'node:crypto';
import fs from 'node:fs';
import https from 'node:https';
import os from 'node:os';
import path from 'node:path';
import { fakeServer, startGateway, openPage, call, rawHttp } from './gatewayproc.js';

const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'gateway_tls_'));
const CERT = path.join(dir, 'cert.pem');
const KEY = path.join(dir, 'key.pem');
const made = spawnSync('openssl', ['req', '-x509', '-newkey', 'rsa:2048', '-nodes', '-days', '1',
  '-subj', '/CN=127.0.0.1', '-addext', 'subjectAltName=IP:127.0.0.1', '-keyout', KEY, '-out', CERT], { encoding: 'utf8' });
const skip = made.error && made.error.code === 'ENOENT' ? 'openssl is not installed (scripts/setup.sh installs it)' : false;
if (!skip && made.status !== 0) throw new Error(`openssl could not make a certificate: ${made.error || made.stderr}`);
const ca = skip ? null : fs.readFileSync(CERT);

let fake;
let gw;
before(async () => {
  fake = await fakeServer();
  if (!skip) gw = await startGateway(fake.address, ['--tls_cert', CERT, '--tls_key', KEY]);
});
after(async () => {
  if (gw) await gw.stop();
  fake.stop();
  fs.rmSync(dir, { recursive: true, force: true });
});

// An HTTPS GET on 127.0.0.1: resolves {status, body, fingerprint} (the
// served certificate's SHA-256), rejects when the connection fails.
function httpsGet(port, pathText, options = {}) {
  return new Promise((resolve, reject) => {
    const req = https.get({ host: '127.0.0.1', port, path: pathText, agent: false, ...options }, (res) => {
      const fingerprint = res.socket.getPeerCertificate().fingerprint256;
      let body = '';
      res.setEncoding('utf8');
      res.on('data', (d) => { body += d; });
      res.on('end', () => resolve({ status: res.statusCode, body, fingerprint }));
    });
    req.on('error', reject);
  });
}

// Resolves once the gateway's log matches `pattern` (it may still be on its way).
function logged(g, pattern) {
  return new Promise((resolve) => {
    const check = () => {
      if (!pattern.test(g.log())) return false;
      g.proc.stderr.off('data', check);
      resolve();
      return true;
    };
    if (!check()) g.proc.stderr.on('data', check);
  });
}

// The gateway's exit code and stderr when it refuses to start with `args`.
async function refusal(args) {
  const e = await startGateway(fake.address, args).then(
    async (g) => {
      await g.stop();
      assert.fail(`the gateway started with ${args.join(' ')}`);
    }, (err) => err);
  const m = e.message.match(/^the gateway exited \((\w+)\) before it listened: ([\s\S]*)$/);
  assert.ok(m, e.message);
  assert.doesNotMatch(m[2], /\n\s+at /, 'a stack trace');
  return { code: Number(m[1]), text: m[2] };
}

test('with --tls_cert and --tls_key the gateway serves HTTPS with that certificate; plain HTTP on its port gets no answer', { skip }, async () => {
  assert.match(gw.url, /^https:\/\/127\.0\.0\.1:\d+\/$/);
  const page = await httpsGet(gw.port, '/', { ca });
  assert.equal(page.status, 200);
  assert.match(page.body, /<html/i);
  assert.equal(page.fingerprint, new crypto.X509Certificate(ca).fingerprint256);
  assert.equal((await httpsGet(gw.port, '/%E0%A4%A', { ca })).status, 400);
  // Without the certificate as CA, a client refuses it: it is not a public one.
  await assert.rejects(httpsGet(gw.port, '/'), (e) => e.code === 'DEPTH_ZERO_SELF_SIGNED_CERT');
  const plain = await rawHttp(gw.port, `GET / HTTP/1.1\r\nHost: 127.0.0.1:${gw.port}\r\nConnection: close\r\n\r\n`);
  assert.equal(plain.closed, true, plain.text);
  assert.equal((await httpsGet(gw.port, '/', { ca })).status, 200);
  assert.equal(gw.proc.exitCode, null);
  await logged(gw, /TLS handshake from 127\.0\.0\.1 failed: ERR_SSL_HTTP_REQUEST/);
});

test('WSS: a page of the same https origin is taken and bridged; another origin, or http:// on the same port, gets 403', { skip }, async () => {
  const own = `https://127.0.0.1:${gw.port}`;
  const p = await openPage(gw.url, { headers: { Origin: own }, ca });
  assert.equal(p.refused, undefined);
  assert.equal((await p.next()).op, 'hello');
  const s = (await call(p, 1, 'CreateSession', { builtin_scene: 'block3' })).response;
  assert.deepEqual((await call(p, 2, 'ListSessions', {})).response.sessions.map((e) => e.id), [s.id]);
  p.ws.close();
  const evil = await openPage(gw.url, { headers: { Origin: 'https://evil.example' }, ca });
  assert.equal(evil.refused, 403);
  assert.match(evil.body, /Origin https:\/\/evil\.example is not this gateway's \(https:\/\/127\.0\.0\.1:\d+\)/);
  const otherScheme = await openPage(gw.url, { headers: { Origin: `http://127.0.0.1:${gw.port}` }, ca });
  assert.equal(otherScheme.refused, 403);
  // A plain ws:// upgrade on the TLS port is no upgrade at all.
  await assert.rejects(openPage(gw.url.replace(/^https/, 'http')));
});

test('a TLS flag without its pair, or a missing, invalid or mismatched file, is refused at start with the path and why (exit 2)', { skip }, async () => {
  const missing = path.join(dir, 'missing.pem');
  const junk = path.join(dir, 'junk.pem');
  fs.writeFileSync(junk, 'not a certificate\n');
  const other = path.join(dir, 'other_key.pem');
  fs.writeFileSync(other, crypto.generateKeyPairSync('ec', { namedCurve: 'P-256' }).privateKey.export({ type: 'pkcs8', format: 'pem' }));
  const cases = [
    [['--tls_cert', CERT], /^gateway: --tls_cert \S+cert\.pem needs --tls_key KEY\.pem/],
    [['--tls_key', KEY], /^gateway: --tls_key \S+key\.pem needs --tls_cert CERT\.pem/],
    [['--tls_cert', missing, '--tls_key', KEY],
      `gateway: cannot read --tls_cert ${missing}: ENOENT: no such file or directory, open '${missing}'`],
    [['--tls_cert', CERT, '--tls_key', dir], `gateway: cannot read --tls_key ${dir}: EISDIR: `],
    [['--tls_cert', junk, '--tls_key', KEY], `gateway: --tls_cert ${junk} is not a PEM certificate: `],
    [['--tls_cert', CERT, '--tls_key', CERT], `gateway: --tls_key ${CERT} is not a PEM private key: `],
    [['--tls_cert', CERT, '--tls_key', other], `gateway: --tls_key ${other} is not the private key of --tls_cert ${CERT}`],
  ];
  const results = await Promise.all(cases.map(([args]) => refusal(args)));
  results.forEach((r, i) => {
    const [args, want] = cases[i];
    assert.equal(r.code, 2, args.join(' '));
    if (typeof want === 'string') assert.ok(r.text.startsWith(want), `${args.join(' ')}: ${r.text}`);
    else assert.match(r.text, want, args.join(' '));
  });
});

test('beyond loopback with neither TLS nor an access token the gateway refuses to start and says why; loopback is unchanged', async () => {
  const listens = ['0.0.0.0:0', '[::]:0'];
  const results = await Promise.all(listens.map((listen) => refusal(['--listen', listen])));
  for (const [i, r] of results.entries()) {
    const listen = listens[i];
    assert.equal(r.code, 2, listen);
    assert.match(r.text, /refusing to listen on every interface beyond loopback with neither TLS nor an access token: a page from another machine would get unauthenticated plain-text control/, listen);
    assert.match(r.text, /--access_token_file FILE \(and --tls_cert FILE --tls_key FILE\)/);
  }
  // A name is judged by the address it bound to: localhost is loopback.
  const local = await startGateway(fake.address, ['--listen', 'localhost:0']);
  try {
    assert.doesNotMatch(local.log(), /beyond loopback/);
  } finally {
    await local.stop();
  }
});
