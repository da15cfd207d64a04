#!/usr/bin/env node
// A stand-in for dynsolid-server in tests of scripts/run_viewer.sh: the
// fake server of gatewayproc.js on a free port of 127.0.0.1, announced as
// the real one does ("listening on ADDR"). Its arguments are ignored.

import { fakeServer } from './gatewayproc.js';

const server = await fakeServer();
console.log(`listening on ${server.address}`);
process.on('SIGTERM', () => {
  server.stop();
  process.exit(0);
});
