// Keeping the work on the page: the Download menu's choices and
// request, the connection putting a download together from the gateway's
// pieces (and refusing pieces out of place), refusals in plain words, and
// the Record button's checks (no MediaRecorder, no WebM codec) and file
// name. No browser: keep.js's pure helpers and connection.js with a fake
// socket.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Connection, Code } from '../../public/js/connection.js';
import { FORMATS, levelChoices, exportRequest, percent, recordSupport, recordingName } from '../../public/js/keep.js';
import { explain } from '../../public/js/explain.js';

class FakeSocket {
  constructor() {
    this.sent = [];
  }
  send(text) { this.sent.push(JSON.parse(text)); }
  close() { this.onclose && this.onclose(); }
  receive(m) { this.onmessage({ data: JSON.stringify(m) }); }
}

function connected() {
  let socket;
  const conn = new Connection({ url: 'ws://x/ws', makeSocket: () => (socket = new FakeSocket()),
    setTimeout: () => {}, clientId: 'web-test' });
  socket.onopen();
  return { conn, socket };
}

test('the menu offers OBJ, STL, PLY, glTF coloured by displacement and VTU, at the session\'s level up to two finer', () => {
  assert.deepEqual(FORMATS.map((f) => f.format), ['OBJ', 'STL', 'PLY', 'GLB', 'VTU', 'SCENE']);
  // A scene file is saved at the session's level only.
  const scene = FORMATS.find((f) => f.format === 'SCENE');
  assert.equal(scene.ext, 'textproto');
  assert.deepEqual(levelChoices(2, scene).map((c) => c.level), [2]);
  assert.equal(FORMATS.find((f) => f.format === 'GLB').color_field, 'displacement');
  assert.deepEqual(levelChoices(2).map((c) => c.level), [2, 3, 4]);
  assert.deepEqual(levelChoices(2).map((c) => c.text), ['level 2 (session)', 'level 3 (finer)', 'level 4 (finer)']);
  assert.deepEqual(levelChoices(5).map((c) => c.level), [5, 6]);
  assert.deepEqual(levelChoices(undefined).map((c) => c.level), [0, 1, 2]);
  assert.deepEqual(exportRequest('s1', FORMATS[3], 3),
    { session: { id: 's1' }, format: 'GLB', level: 3, color_field: 'displacement' });
  assert.deepEqual([percent(0, 200), percent(99, 200), percent(200, 200), percent(0, 0)], [0, 49, 100, 100]);
});

test('a download is put together from its pieces, with progress; one out of place is refused and cancelled', async () => {
  const { conn, socket } = connected();
  const progress = [];
  const task = conn.exportDesign({ session: { id: 's1' }, format: 'STL', level: 1 }, (p) => progress.push(p.received));
  const sent = socket.sent[socket.sent.length - 1];
  assert.deepEqual([sent.op, sent.request.format], ['export', 'STL']);
  const id = sent.id;
  socket.receive({ op: 'export_start', id, file_name: 'block3-step9-level1.stl', media_type: 'model/stl', step: 9,
    level: 1, cells: 216, surface_faces: 216, total_bytes: 6 });
  socket.receive({ op: 'export_chunk', id, offset: 0, total_bytes: 6, data: Buffer.from('abcd').toString('base64') });
  socket.receive({ op: 'export_chunk', id, offset: 4, total_bytes: 6, data: Buffer.from('ef').toString('base64') });
  socket.receive({ op: 'export_end', id, ok: true, total_bytes: 6 });
  const file = await task;
  assert.equal(Buffer.from(file.bytes).toString(), 'abcdef');
  assert.deepEqual([file.file_name, file.step, file.level], ['block3-step9-level1.stl', 9, 1]);
  assert.deepEqual(progress, [0, 4, 6]);

  const bad = conn.exportDesign({ session: { id: 's1' }, format: 'OBJ' });
  const badId = socket.sent[socket.sent.length - 1].id;
  socket.receive({ op: 'export_start', id: badId, file_name: 'x.obj', total_bytes: 4 });
  socket.receive({ op: 'export_chunk', id: badId, offset: 2, total_bytes: 4, data: 'AA==' });
  await assert.rejects(bad, (e) => e.code === Code.INTERNAL && /out of order/.test(e.message));
  assert.deepEqual(socket.sent[socket.sent.length - 1], { op: 'export_cancel', id: badId });
});

test('a refusal rejects with the server\'s code and words, said in plain words; cancel asks the gateway; a lost gateway fails the download', async () => {
  const { conn, socket } = connected();
  const task = conn.exportDesign({ session: { id: 's1' }, format: 'VTU', level: 6 });
  const id = socket.sent[socket.sent.length - 1].id;
  const words = 'request.level: 6 subdivisions of this control mesh (27 cells) give about 7077888 cells, ' +
    'more than the export limit of 2000000; ask for a lower level';
  socket.receive({ op: 'export_end', id, ok: false, code: 3, code_name: 'INVALID_ARGUMENT', message: words });
  const err = await task.then(() => assert.fail('resolved'), (e) => e);
  assert.equal(err.message, words);
  const e = explain(err);
  assert.equal(e.text, 'That level is too fine to export for this solid.');
  assert.match(e.hint, /lower level/);
  assert.equal(e.detail, `refused (INVALID_ARGUMENT): ${words}`);
  assert.equal(explain({ codeName: 'UNIMPLEMENTED', message: 'this dynsolid-server has no Export (an older build): 12 UNIMPLEMENTED: ' }).text,
    'This server cannot make downloads yet.');

  const long = conn.exportDesign({ session: { id: 's1' }, format: 'PLY' });
  long.cancel();
  const longId = socket.sent[socket.sent.length - 2].id;
  assert.deepEqual(socket.sent[socket.sent.length - 1], { op: 'export_cancel', id: longId });
  socket.receive({ op: 'export_end', id: longId, ok: false, code: 1, code_name: 'CANCELLED', message: 'cancelled by the page' });
  assert.equal(explain(await long.catch((x) => x)).text, 'The download was cancelled.');

  const lost = conn.exportDesign({ session: { id: 's1' }, format: 'OBJ' });
  socket.close();
  const why = await lost.catch((x) => x);
  assert.equal(why.code, Code.UNAVAILABLE);
  assert.match(explain(why).text, /broke during the download/);
});

test('Record says why it cannot: no captureStream, no MediaRecorder, no WebM codec; otherwise the best WebM type', () => {
  const canvas = { captureStream: () => ({}) };
  assert.match(recordSupport({ MediaRecorder: undefined, canvas }).why, /no MediaRecorder/);
  assert.match(recordSupport({ MediaRecorder: function R() {}, canvas: {} }).why, /no captureStream/);
  const none = function R() {};
  none.isTypeSupported = () => false;
  assert.deepEqual(recordSupport({ MediaRecorder: none, canvas }),
    { ok: false, why: 'This browser cannot record WebM video: it has no VP8 or VP9 encoder.' });
  const vp8 = function R() {};
  vp8.isTypeSupported = (t) => t !== 'video/webm;codecs=vp9';
  assert.deepEqual(recordSupport({ MediaRecorder: vp8, canvas }), { ok: true, mimeType: 'video/webm;codecs=vp8' });
  assert.equal(recordingName('block3', new Date(2026, 10, 28, 9, 5, 7)), 'block3-20261128-090507.webm');
  assert.equal(recordingName('my chair/2', new Date(2026, 0, 2, 3, 4, 5)), 'my_chair_2-20260102-030405.webm');
});
