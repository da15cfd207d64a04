#!/usr/bin/env node
// dynsolid-web gateway: serves the viewer page (and three.js, from this
// folder's node_modules: nothing is fetched from elsewhere) and bridges each
// page's WebSocket to dynsolid-server's gRPC service.
//
//   node gateway/main.js --server 127.0.0.1:50051 [--listen 127.0.0.1:8080]
//                        [--tls_ca ROOTS.pem]
//
// Prints "listening on http://HOST:PORT/" on stdout once it serves (port 0:
// a free one).

import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { WebSocketServer } from 'ws';
import { loadService, DEFAULT_PROTO_ROOT, grpc } from './grpc.js';
import { Router } from './router.js';
import { Bridge } from './bridge.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..');

function parseArgs(argv) {
  const args = { server: '127.0.0.1:50051', listen: '127.0.0.1:8080', proto: DEFAULT_PROTO_ROOT,
    create: '', levels: '', tls_ca: '' };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    const eq = a.indexOf('=');
    const key = a.replace(/^--/, '').slice(0, eq > 0 ? eq - 2 : undefined);
    if (!a.startsWith('--') || !(key in args)) {
      if (a === '--help' || a === '-h') {
        console.log('usage: node gateway/main.js --server HOST:PORT [--listen HOST:PORT] [--proto DIR]\n' +
          '         [--tls_ca ROOTS.pem]          call the servers over TLS with these roots\n' +
          '         [--create SCENE [--levels N]]   open a session on a built-in scene and print its URL');
        process.exit(0);
      }
      console.error(`gateway: unknown argument ${a} (--server, --listen, --proto, --tls_ca, --create, --levels)`);
      process.exit(2);
    }
    args[key] = eq > 0 ? a.slice(eq + 1) : argv[++i];
    if (args[key] === undefined) {
      console.error(`gateway: ${a} needs a value`);
      process.exit(2);
    }
  }
  return args;
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

function serveStatic(req, res) {
  const url = new URL(req.url, 'http://x');
  let pathname = decodeURIComponent(url.pathname);
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
        res.writeHead(404, { 'content-type': 'text/plain' });
        res.end(`not found: ${pathname}\n`);
        return;
      }
      res.writeHead(200, { 'content-type': TYPES[path.extname(file)] || 'application/octet-stream' });
      res.end(data);
    });
    return;
  }
  res.writeHead(404, { 'content-type': 'text/plain' });
  res.end(`not found: ${pathname}\n`);
}

// --create: a session on a built-in scene, its URL printed (the server may
// still be starting: try for a minute).
function createSession(router, tokens, args, base, log, attempt = 0) {
  const request = { builtin_scene: args.create };
  if (args.levels !== '') request.levels_override = Number(args.levels);
  router.client().CreateSession(request, { deadline: new Date(Date.now() + 600000) }, (err, s) => {
    if (err) {
      if (err.code === 14 && attempt < 60) {
        setTimeout(() => createSession(router, tokens, args, base, log, attempt + 1), 1000);
        return;
      }
      log(`could not create ${args.create}: ${err.details || err.message}`);
      process.exitCode = 1;
      return;
    }
    tokens.set(s.id, s.token);
    router.learn(s);
    console.log(`session ${s.id} (${s.scene_name}): ${base}#session=${s.id}&token=${s.token}`);
  });
}

function main() {
  const args = parseArgs(process.argv.slice(2));
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
  // Sessions created through this gateway: id -> token. Its pages may join
  // them from the list (docs/viewer.md "Access").
  const tokens = new Map();
  const log = (...m) => console.error(new Date().toISOString(), 'gateway:', ...m);
  const [host, portText] = [args.listen.slice(0, args.listen.lastIndexOf(':')),
    args.listen.slice(args.listen.lastIndexOf(':') + 1)];
  const server = http.createServer(serveStatic);
  const wss = new WebSocketServer({ noServer: true, maxPayload: 8 << 20 });
  server.on('upgrade', (req, socket, head) => {
    if (new URL(req.url, 'http://x').pathname !== '/ws') {
      socket.destroy();
      return;
    }
    wss.handleUpgrade(req, socket, head, (ws) => {
      const bridge = new Bridge({ ws, service, router, tokens, address: args.server });
      log(`page connected from ${req.socket.remoteAddress}`);
      ws.on('message', (data, isBinary) => bridge.onMessage(data, isBinary));
      ws.on('close', () => {
        bridge.close();
        log('page disconnected');
      });
      ws.on('error', () => bridge.close());
    });
  });
  server.listen(Number(portText), host, () => {
    const a = server.address();
    const base = `http://${a.address}:${a.port}/`;
    console.log(`listening on ${base}`);
    log(`serving the viewer, dynsolid-server at ${args.server}`);
    if (args.create) createSession(router, tokens, args, base, log);
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
