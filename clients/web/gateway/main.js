#!/usr/bin/env node
// dynsolid-web gateway: serves the viewer page (and three.js, from this
// folder's node_modules: nothing is fetched from elsewhere) and bridges each
// page's WebSocket to dynsolid-server's gRPC service.
//
//   node gateway/main.js --server 127.0.0.1:50051 [--listen 127.0.0.1:8080]
//                        [--tls_ca ROOTS.pem] [--allow_origin ORIGINS]
//                        [--access_token_file FILE]
//                        [--tls_cert CERT.pem --tls_key KEY.pem] [limits]
//
// Prints "listening on http://HOST:PORT/" (https:// with --tls_cert) on
// stdout once it serves (port 0: a free one). What it lets in: guard.js and
// README.md "Doors".

import http from 'node:http';
import https from 'node:https';
import tls from 'node:tls';
import crypto from 'node:crypto';
import net from 'node:net';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { WebSocketServer } from 'ws';
import { loadService, DEFAULT_PROTO_ROOT, grpc } from './grpc.js';
import { Router } from './router.js';
import { Bridge, DEFAULT_LIMITS } from './bridge.js';
import { upgradeRefusal, parseOriginList, requestPath, exposureRefusal, exposureWarning } from './guard.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..');

const USAGE = `usage: node gateway/main.js [--server HOST:PORT] [--listen HOST:PORT] [flags]
  --server HOST:PORT             dynsolid-server (default 127.0.0.1:50051)
  --listen HOST:PORT             where pages connect (default 127.0.0.1:8080; port 0: a free one).
                                 Beyond loopback it needs --access_token_file or --tls_cert/--tls_key
                                 (better both): with neither it refuses to start
  --tls_cert CERT.pem            serve pages over HTTPS and WSS with this certificate (PEM, may
  --tls_key KEY.pem              hold the chain) and its unencrypted private key; both or neither
                                 (default neither: plain HTTP and WS)
  --access_token_file FILE       pages must carry ?access=<the file's first line, 16+ characters>
                                 (default none)
  --allow_origin ORIGINS         comma-separated origins (http(s)://host:port) whose pages may
                                 connect besides the gateway's own (default none)
  --tls_ca ROOTS.pem             call the servers over TLS with these roots (default plaintext)
  --proto DIR                    the .proto files (default ${DEFAULT_PROTO_ROOT})
  --create SCENE [--levels N]    open a session on a built-in scene and print its URL (default none)
  --max_message_bytes N          a page's largest message (default ${DEFAULT_LIMITS.maxMessageBytes})
  --max_messages_per_second N    a page's sustained message rate (default ${DEFAULT_LIMITS.rate})
  --message_burst N              messages a page may send at once above it (default ${DEFAULT_LIMITS.burst})`;

function fail(message) {
  console.error(`gateway: ${message}`);
  process.exit(2);
}

function parseArgs(argv) {
  const args = { server: '127.0.0.1:50051', listen: '127.0.0.1:8080', proto: DEFAULT_PROTO_ROOT,
    create: '', levels: '', tls_ca: '', tls_cert: '', tls_key: '', allow_origin: '', access_token_file: '',
    max_message_bytes: String(DEFAULT_LIMITS.maxMessageBytes),
    max_messages_per_second: String(DEFAULT_LIMITS.rate), message_burst: String(DEFAULT_LIMITS.burst) };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    const eq = a.indexOf('=');
    const key = a.replace(/^--/, '').slice(0, eq > 0 ? eq - 2 : undefined);
    if (!a.startsWith('--') || !(key in args)) {
      if (a === '--help' || a === '-h') {
        console.log(USAGE);
        process.exit(0);
      }
      fail(`unknown argument ${a} (--help lists the flags)`);
    }
    args[key] = eq > 0 ? a.slice(eq + 1) : argv[++i];
    if (args[key] === undefined) fail(`${a} needs a value`);
  }
  return args;
}

function positive(args, key) {
  const n = Number(args[key]);
  if (!Number.isInteger(n) || n < 1) fail(`--${key} must be a whole number above 0 (got ${args[key]})`);
  return n;
}

// --listen as [host, port]; refused when the port is not 0-65535.
function listenAddress(text) {
  const colon = text.lastIndexOf(':');
  const host = text.slice(0, colon).replace(/^\[|\]$/g, '');
  const port = Number(text.slice(colon + 1));
  if (colon < 0 || !Number.isInteger(port) || port < 0 || port > 65535) {
    fail(`--listen ${text}: want HOST:PORT with PORT 0-65535`);
  }
  return [host, port];
}

// What the doors take (guard.js), from the flags.
function doorsOf(args) {
  let allowOrigins;
  try {
    allowOrigins = parseOriginList(args.allow_origin);
  } catch (e) {
    fail(e.message);
  }
  let accessToken = '';
  if (args.access_token_file) {
    try {
      accessToken = fs.readFileSync(args.access_token_file, 'utf8').split('\n')[0].trim();
    } catch (e) {
      fail(`cannot read --access_token_file ${args.access_token_file}: ${e.message}`);
    }
    if (accessToken.length < 16) fail('the access token must be at least 16 characters');
  }
  const limits = { maxMessageBytes: positive(args, 'max_message_bytes'),
    rate: positive(args, 'max_messages_per_second'), burst: positive(args, 'message_burst') };
  return { allowOrigins, accessToken, limits };
}

// --tls_cert and --tls_key as https.createServer's {cert, key}, or null
// without them. Both or neither. Each file is read and checked here, so a
// missing, unreadable or invalid one, or a key that is not the
// certificate's, is said at start with its path and why (exit 2).
function tlsOf(args, log) {
  const { tls_cert: certFile, tls_key: keyFile } = args;
  if (!certFile && !keyFile) return null;
  if (!keyFile) fail(`--tls_cert ${certFile} needs --tls_key KEY.pem (the certificate's private key) as well`);
  if (!certFile) fail(`--tls_key ${keyFile} needs --tls_cert CERT.pem (its certificate) as well`);
  const read = (flag, file) => {
    try {
      return fs.readFileSync(file);
    } catch (e) {
      return fail(`cannot read --${flag} ${file}: ${e.message}`);
    }
  };
  const cert = read('tls_cert', certFile);
  const key = read('tls_key', keyFile);
  let certificate;
  let privateKey;
  try {
    certificate = new crypto.X509Certificate(cert);
  } catch (e) {
    fail(`--tls_cert ${certFile} is not a PEM certificate: ${e.message}`);
  }
  try {
    privateKey = crypto.createPrivateKey(key);
  } catch (e) {
    if (/-----BEGIN [A-Z ]*ENCRYPTED/.test(key.toString('latin1'))) {
      fail(`--tls_key ${keyFile} is encrypted; give the gateway an unencrypted copy (openssl pkey -in ${keyFile} -out KEY.pem)`);
    }
    fail(`--tls_key ${keyFile} is not a PEM private key: ${e.message}`);
  }
  if (!certificate.checkPrivateKey(privateKey)) {
    fail(`--tls_key ${keyFile} is not the private key of --tls_cert ${certFile}`);
  }
  try {
    tls.createSecureContext({ cert, key });
  } catch (e) {
    fail(`--tls_cert ${certFile} with --tls_key ${keyFile}: ${e.message}`);
  }
  if (Date.parse(certificate.validTo) < Date.now()) {
    log(`--tls_cert ${certFile} expired on ${certificate.validTo}: browsers will refuse it`);
  }
  return { cert, key };
}

// URL prefix -> folder. Only these are served; nothing outside them.
const STATIC = [
  ['/vendor/three/', path.join(root, 'node_modules/three/build/')],
  ['/vendor/three-addons/', path.join(root, 'node_modules/three/examples/jsm/')],
  ['/', path.join(root, 'public/')],
];
const TYPES = {
  '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8', '.png': 'image/png', '.svg': 'image/svg+xml',
  '.json': 'application/json', '.textproto': 'text/plain; charset=utf-8',
};

function answer(res, status, text) {
  res.writeHead(status, { 'content-type': 'text/plain; charset=utf-8' });
  res.end(`${text}\n`);
}

function serveStatic(req, res) {
  let pathname = requestPath(req.url);
  if (pathname === null) {
    answer(res, 400, 'malformed URL (bad percent-encoding)');
    return;
  }
  if (pathname === '/') pathname = '/index.html';
  if (pathname === '/favicon.ico') {
    res.writeHead(204);
    res.end();
    return;
  }
  for (const [prefix, dir] of STATIC) {
    if (!pathname.startsWith(prefix)) continue;
    const file = path.resolve(dir, pathname.slice(prefix.length));
    if (!file.startsWith(dir)) break;  // ../ out of the folder
    fs.readFile(file, (err, data) => {
      if (err) {
        answer(res, 404, `not found: ${pathname}`);
        return;
      }
      res.writeHead(200, { 'content-type': TYPES[path.extname(file)] || 'application/octet-stream' });
      res.end(data);
    });
    return;
  }
  answer(res, 404, `not found: ${pathname}`);
}

// An upgrade not taken: an HTTP answer on the raw socket, then closed.
function refuseUpgrade(socket, status, text) {
  const body = `${text}\n`;
  socket.end(`HTTP/1.1 ${status} ${http.STATUS_CODES[status]}\r\n` +
    `content-type: text/plain; charset=utf-8\r\ncontent-length: ${Buffer.byteLength(body)}\r\n` +
    `connection: close\r\n\r\n${body}`);
}

function serveSafely(req, res, log) {
  try {
    serveStatic(req, res);
  } catch (e) {
    log(`request ${JSON.stringify(req.url)} failed: ${e.message}`);
    if (!res.headersSent) answer(res, 500, 'the gateway could not answer this request');
  }
}

// Whether a WebSocket upgrade may go on (guard.js); answered and closed if not.
function admit(req, socket, doors, log) {
  socket.on('error', () => {});
  const pathname = requestPath(req.url);
  if (pathname === null) {
    refuseUpgrade(socket, 400, 'malformed URL (bad percent-encoding)');
    return false;
  }
  if (pathname !== '/ws') {
    refuseUpgrade(socket, 404, 'the WebSocket is at /ws');
    return false;
  }
  const why = upgradeRefusal(req, doors);
  if (why) {
    log(`refused a WebSocket from ${req.socket.remoteAddress}: ${why}`);
    refuseUpgrade(socket, 403, `refused: ${why}`);
    return false;
  }
  return true;
}

function bridgePage(ws, req, log, bridge) {
  log(`page connected from ${req.socket.remoteAddress}`);
  ws.on('message', (data, isBinary) => bridge.onMessage(data, isBinary));
  ws.on('close', () => {
    bridge.close();
    log('page disconnected');
  });
  ws.on('error', (e) => {
    log(`page connection closed: ${e.message}`);
    bridge.close();
  });
}

// --create: a session on a built-in scene, its URL printed (the server may
// still be starting: try for a minute).
function createSession(router, args, base, log, attempt = 0) {
  const request = { builtin_scene: args.create };
  if (args.levels !== '') request.levels_override = Number(args.levels);
  router.client().CreateSession(request, { deadline: new Date(Date.now() + 600000) }, (err, s) => {
    if (err) {
      if (err.code === 14 && attempt < 60) {
        setTimeout(() => createSession(router, args, base, log, attempt + 1), 1000);
        return;
      }
      log(`could not create ${args.create}: ${err.details || err.message}`);
      process.exitCode = 1;
      return;
    }
    router.learn(s);
    console.log(`session ${s.id} (${s.scene_name}): ${base}#session=${s.id}&token=${s.token}`);
  });
}

function main() {
  const args = parseArgs(process.argv.slice(2));
  // The flags about this gateway's own doors first: a mistake there is said
  // before anything is loaded.
  const doors = doorsOf(args);
  const log = (...m) => console.error(new Date().toISOString(), 'gateway:', ...m);
  const tlsOptions = tlsOf(args, log);
  const exposure = { tls: tlsOptions !== null, accessToken: doors.accessToken };
  const [host, port] = listenAddress(args.listen);
  // Beyond loopback without TLS or a token: refused before binding when the
  // address says so, and after binding for a name (what it resolved to).
  if (host === '' || net.isIP(host)) {
    const why = exposureRefusal(host, exposure);
    if (why) fail(why);
  }
  const service = loadService(args.proto);
  // Sessions on other replicas are reached where they live (router.js).
  let credentials;
  if (args.tls_ca) {
    try {
      credentials = grpc.credentials.createSsl(fs.readFileSync(args.tls_ca));
    } catch (e) {
      console.error(`gateway: cannot read --tls_ca ${args.tls_ca}: ${e.message}`);
      process.exit(2);
    }
  }
  const router = new Router(service, args.server, credentials);
  const handler = (req, res) => serveSafely(req, res, log);
  const server = tlsOptions ? https.createServer(tlsOptions, handler) : http.createServer(handler);
  // A failed handshake (plain HTTP on the TLS port, a browser refusing the
  // certificate): said in the log, the connection dropped.
  server.on('tlsClientError', (e, socket) => {
    log(`TLS handshake from ${socket.remoteAddress} failed: ${e.code || e.message}`);
    socket.destroy();
  });
  const wss = new WebSocketServer({ noServer: true, maxPayload: doors.limits.maxMessageBytes });
  server.on('upgrade', (req, socket, head) => {
    if (!admit(req, socket, doors, log)) return;
    wss.handleUpgrade(req, socket, head, (ws) => bridgePage(ws, req, log,
      new Bridge({ ws, service, router, address: args.server, limits: doors.limits })));
  });
  server.on('error', (e) => {
    const why = e.code === 'EADDRINUSE' ? 'the port is taken (EADDRINUSE)' : e.message;
    console.error(`gateway: cannot listen on ${args.listen}: ${why}`);
    process.exit(1);
  });
  server.listen(port, host, () => {
    const a = server.address();
    const why = exposureRefusal(a.address, exposure);
    if (why) fail(why);
    const name = a.family === 'IPv6' ? `[${a.address}]` : a.address;
    const base = `${tlsOptions ? 'https' : 'http'}://${name}:${a.port}/`;
    const open = doors.accessToken ? `${base}?access=${encodeURIComponent(doors.accessToken)}` : base;
    console.log(`listening on ${base}`);
    if (doors.accessToken) console.log(`open ${open}`);
    log(`serving the viewer, dynsolid-server at ${args.server}`);
    const warning = exposureWarning(a.address, exposure);
    if (warning) log(`${warning} (${base})`);
    if (args.create) createSession(router, args, open, log);
  });
  const stop = () => {
    log('stopping');
    for (const ws of wss.clients) ws.close(1001, 'gateway stopping');
    server.close(() => process.exit(0));
    setTimeout(() => process.exit(0), 1000).unref();
  };
  process.on('SIGTERM', stop);
  process.on('SIGINT', stop);
}

main();
