// The History panel's helpers (history.js): a HistoryInfo as the gateway
// gives it (service.proto; longs as numbers) seen by one page: its own
// entries marked "you", others' under a stable "person N" label (never the
// client id), undone entries flagged, which entry this page's Undo and
// Redo act on next, the memory line, the last rows only, an empty history;
// undo and redo refusals in plain words.
// No browser.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { labelPeople, historyView, memoryLine, sizeText, buttonTitles, MAX_ROWS } from '../../public/js/history.js';
import { revertToScene } from '../../public/js/commands.js';
import { explain } from '../../public/js/explain.js';

const ME = 'web-aaaaaaaaaaaa';
const B = 'web-bbbbbbbbbbbb';
const C = 'web-cccccccccccc';

const entry = (serial, client_id, what, undone = false) => ({ serial, client_id, what, undone });

// B pinned, I extruded and painted, C inflated, I undid my paint; B's pin
// is still in effect.
const HISTORY = {
  entries: [
    entry(1, B, 'pin (3 control points)'),
    entry(2, ME, 'extrude face 85'),
    entry(3, C, 'inflate'),
    entry(4, ME, 'stiffness stroke, 12 dabs', true),
  ],
  people: [
    { client_id: B, undo: [1], redo: [] },
    { client_id: ME, undo: [2], redo: [4] },
    { client_id: C, undo: [3], redo: [] },
  ],
  bytes: 3355443,
  limit_bytes: 268435456,
};

test('my entries say "you", others\' a person number by first appearance; no client id is shown', () => {
  const v = historyView(HISTORY, ME);
  assert.deepEqual(v.rows.map((r) => [r.serial, r.what, r.who, r.mine]), [
    [1, 'pin (3 control points)', 'person 1', false],
    [2, 'extrude face 85', 'you', true],
    [3, 'inflate', 'person 2', false],
    [4, 'stiffness stroke, 12 dabs', 'you', true],
  ]);
  assert.deepEqual(v.rows.map((r) => r.classes[0]), ['other', 'mine', 'other', 'mine']);
  const text = JSON.stringify(v);
  for (const id of [ME, B, C]) assert.ok(!text.includes(id), `${id} shown`);
  // Seen from B's page: B is "you", I am a person.
  const fromB = historyView(HISTORY, B);
  assert.deepEqual(fromB.rows.map((r) => r.who), ['you', 'person 1', 'person 2', 'person 1']);
});

test('a label stays with its person while entries come and go', () => {
  let labels = labelPeople(HISTORY, ME);
  assert.deepEqual([...labels.entries()], [[B, 'person 1'], [C, 'person 2']]);
  // B's pin dropped from the history (memory limit), a newcomer D acts:
  // C stays person 2, D is person 3.
  const later = { entries: [entry(3, C, 'inflate'), entry(5, 'web-dddddddddddd', 'drag')],
    people: [{ client_id: C, undo: [3] }, { client_id: 'web-dddddddddddd', undo: [5] }] };
  labels = labelPeople(later, ME, labels);
  const v = historyView(later, ME, labels);
  assert.deepEqual(v.rows.map((r) => r.who), ['person 2', 'person 3']);
  // A person with no entry yet (only an empty redo list) is numbered after those with entries.
  const people = labelPeople({ entries: [entry(1, C, 'pin')], people: [{ client_id: B }, { client_id: C }] }, ME);
  assert.deepEqual([...people.values()], ['person 1', 'person 2']);
  assert.equal(people.get(C), 'person 1');
});

test('Undo\'s next is the last of my undo list, Redo\'s the last of my redo list; never another\'s', () => {
  const v = historyView(HISTORY, ME);
  assert.equal(v.nextUndo.serial, 2);
  assert.equal(v.nextRedo.serial, 4);
  assert.deepEqual(v.rows.map((r) => [r.nextUndo, r.nextRedo]),
    [[false, false], [true, false], [false, false], [false, true]]);
  assert.ok(v.rows[1].classes.includes('next-undo'));
  assert.ok(v.rows[3].classes.includes('next-redo'));
  assert.equal(v.rows[1].title, 'yours: Undo takes it back next');
  assert.match(v.rows[0].title, /only person 1 can undo it/);
  assert.deepEqual(buttonTitles(v), { undo: 'Ctrl+Z: takes back your "extrude face 85"',
    redo: 'Ctrl+Shift+Z: brings back your "stiffness stroke, 12 dabs"' });
  // Several of mine: the last of the list is next, the earlier ones wait.
  const two = { entries: [entry(1, ME, 'pin'), entry(2, ME, 'extrude face 3')],
    people: [{ client_id: ME, undo: [1, 2], redo: [] }] };
  const w = historyView(two, ME);
  assert.deepEqual(w.rows.map((r) => r.nextUndo), [false, true]);
  assert.equal(w.nextRedo, null);
  assert.equal(buttonTitles(w).redo, 'Ctrl+Shift+Z: you have nothing to redo');
  // A page that has done nothing: no markers at all, though others have.
  const none = historyView(HISTORY, 'web-newcomer');
  assert.ok(none.rows.every((r) => !r.nextUndo && !r.nextRedo && !r.mine));
  assert.deepEqual([none.nextUndo, none.nextRedo], [null, null]);
});

test('undone entries are flagged (struck through), mine and others\' alike', () => {
  const h = { ...HISTORY, entries: [...HISTORY.entries, entry(5, C, 'deflate', true)],
    people: [HISTORY.people[0], HISTORY.people[1], { client_id: C, undo: [3], redo: [5] }] };
  const v = historyView(h, ME);
  assert.deepEqual(v.rows.map((r) => r.undone), [false, false, false, true, true]);
  assert.deepEqual(v.rows.map((r) => r.classes.includes('undone')), [false, false, false, true, true]);
  // Another's undone entry is never my Redo's.
  assert.equal(v.rows[4].nextRedo, false);
  assert.match(v.rows[4].title, /undone: only person 2 can redo it/);
});

test('the memory line: bytes held of the limit, in KiB, MiB as people read them', () => {
  assert.equal(memoryLine(HISTORY), 'history: 3.2 MiB of 256 MiB');
  assert.equal(memoryLine({ bytes: 0, limit_bytes: 268435456 }), 'history: 0 B of 256 MiB');
  assert.equal(memoryLine({ bytes: 1536, limit_bytes: 0 }), 'history: 1.5 KiB');
  assert.deepEqual([sizeText(512), sizeText(1024), sizeText(10 * 1024 * 1024 + 1), sizeText(2 ** 30)],
    ['512 B', '1 KiB', '10 MiB', '1 GiB']);
});

test('an empty history: no rows, no markers, the memory line still there', () => {
  for (const h of [{ entries: [], people: [], bytes: 0, limit_bytes: 1048576 }, {}, null]) {
    const v = historyView(h, ME);
    assert.equal(v.empty, true);
    assert.deepEqual(v.rows, []);
    assert.equal(v.earlier, 0);
    assert.deepEqual([v.nextUndo, v.nextRedo], [null, null]);
  }
  assert.equal(historyView({ bytes: 0, limit_bytes: 1048576 }, ME).memory, 'history: 0 B of 1 MiB');
  assert.deepEqual(buttonTitles(historyView(null, ME)),
    { undo: 'Ctrl+Z: you have nothing to undo', redo: 'Ctrl+Shift+Z: you have nothing to redo' });
});

test('only the newest rows are shown, oldest first; the rest are counted; my next undo is known even when older', () => {
  const n = MAX_ROWS + 12;
  const entries = [];
  for (let s = 1; s <= n; ++s) entries.push(entry(s, s === 1 ? ME : B, `pin ${s}`));
  const v = historyView({ entries, people: [{ client_id: ME, undo: [1] }, { client_id: B, undo: [] }] }, ME);
  assert.equal(v.rows.length, MAX_ROWS);
  assert.equal(v.earlier, 12);
  assert.equal(v.rows[0].serial, 13);
  assert.equal(v.rows[v.rows.length - 1].serial, n);
  assert.equal(v.nextUndo.serial, 1);
  assert.equal(v.nextUndo.what, 'pin 1');
});

test('Revert to scene is the revert_to_scene command', () => {
  assert.deepEqual(revertToScene(), { revert_to_scene: {} });
});

test('undo and redo refusals in plain words, the server\'s words kept as details', () => {
  const refused = (message) => explain({ codeName: 'FAILED_PRECONDITION', message });
  const none = refused('command.undo: you have nothing to undo (0 of your actions to undo, 1 to redo; ' +
    'undo takes back only your own actions)');
  assert.deepEqual([none.text, none.hint], ['You have nothing to undo.', 'Undo takes back only your own actions; others\' stay.']);
  assert.match(none.detail, /^refused \(FAILED_PRECONDITION\): command\.undo: you have nothing to undo/);
  assert.equal(refused('command.redo: you have nothing to redo (1 of your actions to undo, 0 to redo; ' +
    'undo takes back only your own actions)').text, 'You have nothing to redo.');
  // An entry named like another tool's refusal is still an undo's.
  const under = refused('command.undo: cannot undo "merge faces 3 and 5" (entry 4): another person (web-0123456789ab): ' +
    '"revert to the scene" (entry 6) came after it and would be taken away too; that has to be undone first. Nothing changed.');
  assert.match(under.text, /^A later change builds on that one/);
  assert.match(refused('command.redo: cannot redo "extrude face 85" (entry 2): you changed the control mesh since; ' +
    'the edit was made on the one before. Nothing changed.').text, /^The session changed since/);
});
