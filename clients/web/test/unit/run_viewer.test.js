// scripts/run_viewer.sh with a fake dynsolid-server (fake_server_main.js;
// NO_SETUP=1: no build, no npm ci), all on 127.0.0.1: a taken port is named
// and a free one used; a second run on the same OUT is refused; files
// another instance left in OUT are never touched. Waits on the script's
// output and exit, never on the clock.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const SCRIPT = path.resolve(here, '../../../../scripts/run_viewer.sh');
const FAKE_SERVER = path.join(here, 'fake_server_main.js');

function runViewer(env) {
  const proc = spawn('bash', [SCRIPT], {
    env: { ...process.env, NO_SETUP: '1', DYNSOLID_SERVER: FAKE_SERVER, ...env },
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  let out = '';
  let err = '';
  const closed = new Promise((resolve) => proc.once('close', (code) => resolve(code)));
  proc.stderr.on('data', (d) => { err += d; });
  const opened = new Promise((resolve) => {
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/run_viewer: open (\S+)/);
      if (m) resolve(m[1]);
    });
    closed.then(() => resolve(null));
  });
  return { proc, opened, closed, err: () => err };
}

function holdPort() {
  return new Promise((resolve) => {
    const s = net.createServer();
    s.listen(0, '127.0.0.1', () => resolve(s));
  });
}

test('run_viewer.sh: a taken port is named and a free one used; a second run on its OUT is refused; nobody\'s files are touched', async () => {
  const out = fs.mkdtempSync(path.join(os.tmpdir(), 'run_viewer_'));
  // What an instance started by an older script left in OUT, still in use.
  const theirs = ['server.out', 'server.log', 'gateway.out', 'gateway.log'];
  for (const f of theirs) fs.writeFileSync(path.join(out, f), `another instance's ${f}\n`);
  const holder = await holdPort();
  const taken = holder.address().port;
  const first = runViewer({ OUT: out, VIEWER_LISTEN: `127.0.0.1:${taken}` });
  let second = null;
  try {
    const url = await first.opened;
    assert.ok(url, `no URL: ${first.err()}`);
    assert.notEqual(new URL(url).port, String(taken));
    assert.match(url, /#session=s1&token=token1$/);
    assert.match(first.err(), new RegExp(`127\\.0\\.0\\.1:${taken} is taken`));
    assert.doesNotMatch(first.err(), /\n\s+at /, 'no stack trace');
    second = runViewer({ OUT: out, VIEWER_LISTEN: '127.0.0.1:0' });
    assert.equal(await second.closed, 1);
    assert.match(second.err(), /another run_viewer.sh is running on OUT=/);
  } finally {
    first.proc.kill('SIGTERM');
    if (second) second.proc.kill('SIGTERM');
    await first.closed;
    holder.close();
  }
  for (const f of theirs) assert.equal(fs.readFileSync(path.join(out, f), 'utf8'), `another instance's ${f}\n`, f);
  const runs = fs.readdirSync(path.join(out, 'runs'));
  assert.equal(runs.length, 1, 'the refused run made no folder');
  assert.match(fs.readFileSync(path.join(out, 'runs', runs[0], 'gateway.log'), 'utf8'), /the port is taken/);
  fs.rmSync(out, { recursive: true, force: true });
});
