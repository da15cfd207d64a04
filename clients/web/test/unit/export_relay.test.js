// The gateway's Export relay (gateway/bridge.js "export"): the real gateway
// process in front of the fake server of gatewayproc.js, whose Export sends
// a known file in chunks. A page exports only its own sessions (the gateway
// adds the token it holds); the file arrives in order, offsets contiguous,
// every message under --max_message_bytes; the server's refusals reach the
// page with its words; cancelling, or closing the page, cancels the gRPC
// call on the server. No clock: every step waits for the event it needs.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { fakeAndGateway, stopFakeAndGateway, fakeExportFile, startGateway, openPage, call } from './gatewayproc.js';
import { exportPieceBytes } from '../../gateway/bridge.js';

let fake;
let gw;
before(async () => ({ fake, gw } = await fakeAndGateway()));
after(() => stopFakeAndGateway({ fake, gw }));

// A page with a session of its own: {page, session}.
async function pageWithSession(url) {
  const page = await openPage(url);
  assert.equal((await page.next()).op, 'hello');
  const session = (await call(page, 1, 'CreateSession', { builtin_scene: 'block3' })).response;
  return { page, session };
}

// The export messages with this id up to its export_end: {start, chunks,
// end, sizes (each message's JSON length)}.
async function collect(page, id) {
  const out = { start: null, chunks: [], end: null, sizes: [], order: [] };
  for (;;) {
    const m = await page.next();
    if (m.id !== id || !String(m.op).startsWith('export_')) continue;
    out.order.push(m.op);
    out.sizes.push(Buffer.byteLength(JSON.stringify(m)));
    if (m.op === 'export_start') out.start = m;
    if (m.op === 'export_chunk') out.chunks.push(m);
    if (m.op === 'export_end') {
      out.end = m;
      return out;
    }
  }
}

// The file the chunks make, checking each starts where the last ended.
function assemble(chunks, total) {
  let next = 0;
  const parts = [];
  for (const c of chunks) {
    assert.equal(c.offset, next, `chunk at ${c.offset}, expected ${next}`);
    assert.equal(c.total_bytes, total);
    const b = Buffer.from(c.data, 'base64');
    parts.push(b);
    next += b.length;
  }
  assert.equal(next, total);
  return Buffer.concat(parts);
}

test('the design arrives as export_start, chunks in order with contiguous offsets, export_end; the gateway adds the page\'s token', async () => {
  const { page, session } = await pageWithSession(gw.url);
  page.send({ op: 'export', id: 1, request: { session: { id: session.id }, format: 'GLB', level: 2, color_field: 'displacement' } });
  const r = await collect(page, 1);
  assert.equal(r.order[0], 'export_start');
  assert.deepEqual([r.start.file_name, r.start.total_bytes, r.start.level, r.start.step, r.start.cells],
    ['block3-step3-level2.glb', 12000, 2, 3, 192]);
  assert.deepEqual(assemble(r.chunks, 12000), fakeExportFile(12000));
  assert.deepEqual([r.end.ok, r.end.total_bytes], [true, 12000]);
  const seen = fake.exports[fake.exports.length - 1].request;
  assert.deepEqual([seen.session.id, seen.session.token, seen.format, seen.level, seen.color_field, seen.chunk_bytes],
    [session.id, session.token, 'GLB', 2, 'displacement', 1 << 20]);
  // No level: the server's default (the session's own).
  page.send({ op: 'export', id: 'stl-a', request: { session: { id: session.id }, format: 'STL' } });
  const d = await collect(page, 'stl-a');
  assert.equal(d.end.ok, true);
  assert.equal(fake.exports[fake.exports.length - 1].request.level, undefined);
  assert.equal(d.start.file_name, 'block3-step3-level1.stl');
  page.ws.close();
});

test('with a small --max_message_bytes every message stays under it: the server is asked for smaller chunks, and they are split', async () => {
  for (const limit of [6000, 2000]) {
    const small = await startGateway(fake.address, ['--max_message_bytes', String(limit)]);
    try {
      const { page, session } = await pageWithSession(small.url);
      page.send({ op: 'export', id: 7, request: { session: { id: session.id }, format: 'OBJ', level: 3 } });
      const r = await collect(page, 7);
      assert.equal(r.end.ok, true, JSON.stringify(r.end));
      assert.ok(Math.max(...r.sizes) <= limit, `largest message ${Math.max(...r.sizes)} > ${limit}`);
      assert.deepEqual(assemble(r.chunks, 13000), fakeExportFile(13000));
      // Asked for what fits one message, or the server's smallest chunk
      // (then each is split in pieces that fit).
      const piece = exportPieceBytes(limit);
      const chunk = Math.max(4096, piece);
      assert.equal(fake.exports[fake.exports.length - 1].request.chunk_bytes, chunk);
      let pieces = 0;
      for (let at = 0; at < 13000; at += chunk) pieces += Math.ceil(Math.min(chunk, 13000 - at) / piece);
      assert.equal(r.chunks.length, pieces);
      assert.ok(limit > 5000 ? pieces === Math.ceil(13000 / chunk) : pieces > Math.ceil(13000 / chunk));
      page.ws.close();
    } finally {
      await small.stop();
    }
  }
});

test('a refusal reaches the page as export_end with the server\'s words; another page\'s session is refused before the server', async () => {
  const { page, session } = await pageWithSession(gw.url);
  page.send({ op: 'export', id: 2, request: { session: { id: session.id }, format: 'VTU', level: 6 } });
  const r = await collect(page, 2);
  assert.deepEqual(r.order, ['export_end']);
  assert.deepEqual([r.end.ok, r.end.code, r.end.code_name], [false, 3, 'INVALID_ARGUMENT']);
  assert.match(r.end.message, /^request\.level: 6 subdivisions .* more than the export limit of 2000; ask for a lower level$/);
  // Page b neither created nor joined it: refused, even naming its token.
  const b = await openPage(gw.url);
  await b.next();
  const before = fake.exports.length;
  b.send({ op: 'export', id: 1, request: { session: { id: session.id, token: session.token }, format: 'STL' } });
  const refused = (await collect(b, 1)).end;
  assert.deepEqual([refused.ok, refused.code_name], [false, 'PERMISSION_DENIED']);
  assert.match(refused.message, /not one this page created or joined/);
  assert.equal(fake.exports.length, before);
  // Joined with the link: now it may.
  assert.equal((await call(b, 2, 'GetSession', { id: session.id, token: session.token })).ok, true);
  b.send({ op: 'export', id: 3, request: { session: { id: session.id }, format: 'STL', level: 0 } });
  assert.equal((await collect(b, 3)).end.ok, true);
  // A bad id is an error, not an export.
  b.send({ op: 'export', id: { x: 1 }, request: { session: { id: session.id }, format: 'STL' } });
  let m;
  do m = await b.next(); while (m.op !== 'error');
  assert.match(m.message, /export: id must be/);
  page.ws.close();
  b.ws.close();
});

test('export_cancel cancels the server\'s call; so does closing the page', async () => {
  const { page, session } = await pageWithSession(gw.url);
  // PLY: the fake sends the first chunk and waits.
  page.send({ op: 'export', id: 4, request: { session: { id: session.id }, format: 'PLY', level: 0 } });
  let m;
  do m = await page.next(); while (m.op !== 'export_chunk');
  assert.deepEqual([m.id, m.offset, m.total_bytes], [4, 0, 10000]);
  const seen = fake.exports[fake.exports.length - 1];
  assert.equal(seen.cancelled, false);
  page.send({ op: 'export_cancel', id: 4 });
  do m = await page.next(); while (m.op !== 'export_end');
  assert.deepEqual([m.id, m.ok, m.code_name, m.message], [4, false, 'CANCELLED', 'cancelled by the page']);
  await seen.whenCancelled;
  assert.equal(seen.cancelled, true);
  // Again, and the page goes away mid-export.
  page.send({ op: 'export', id: 5, request: { session: { id: session.id }, format: 'PLY', level: 0 } });
  do m = await page.next(); while (m.op !== 'export_chunk');
  const second = fake.exports[fake.exports.length - 1];
  page.ws.close();
  await second.whenCancelled;
  assert.equal(second.cancelled, true);
});

test('at most two exports at once per page', async () => {
  const { page, session } = await pageWithSession(gw.url);
  for (const id of [1, 2]) {
    page.send({ op: 'export', id, request: { session: { id: session.id }, format: 'PLY', level: 0 } });
    let m;
    do m = await page.next(); while (!(m.op === 'export_chunk' && m.id === id));
  }
  page.send({ op: 'export', id: 3, request: { session: { id: session.id }, format: 'STL' } });
  const third = (await collect(page, 3)).end;
  assert.deepEqual([third.ok, third.code_name], [false, 'RESOURCE_EXHAUSTED']);
  assert.match(third.message, /2 exports are already running/);
  page.ws.close();
});
