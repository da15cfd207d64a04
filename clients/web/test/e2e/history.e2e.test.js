// The History panel in a real browser against a real server and
// gateway: two pages on one block3 session. Page A pins the top, page B
// extrudes a side face; A's panel lists both, its own as "you", B's greyed
// as another person (never B's client id). A's Undo strikes its pin through
// while B's extrude stays in effect (the server agrees). Revert to scene
// asks first ("Keep it" sends nothing), then takes the session back to its
// 27 cells, listed as A's entry, which A's Undo takes back next; B's page
// lists the revert as another person's. Screenshots go to
// $DYNSOLID_E2E_OUT/history/.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import path from 'node:path';
import { startViewer, openViewer, outDir, until as waitFor, sleep } from './harness.js';

const out = outDir('history');
let env;
let a;      // page A (creates the session)
let b;      // page B (joins by the share link)
let grpc;
let ref;
let cells0;  // block3's control cells
let vertices0;  // and its surface vertices as page A draws them

const said = (p) => p.evaluate(() => window.__dynsolid.metrics.messages.map((m) => m.text).slice(-6));
// Waits like harness.until; a timeout also says what both pages said.
const until = (predicate, what, ms) => waitFor(predicate, what, ms).catch(async (e) => {
  throw new Error(`${e.message}; page A said ${JSON.stringify(await said(a))}` +
    (b ? `; page B said ${JSON.stringify(await said(b))}` : ''));
});
const shot = (p, name) => p.screenshot({ path: path.join(out, `${name}.png`) });
const project = (p, point) => p.evaluate((q) => window.__dynsolid.view.project(q), point);
const tool = (p, name) => p.click(`#tool-buttons [data-tool=${name}]`);
const stats = () => grpc.call('GetStats', ref);
const serverHistory = async () => (await grpc.call('Inspect', { session: ref, history: true })).history;
const clientId = (p) => p.evaluate(() => window.__dynsolid.conn.clientId);
// The panel as the person sees it: each row's text parts and classes.
const panel = (p) => p.evaluate(() => ({
  rows: [...document.querySelectorAll('#history-list li:not(.note)')].map((li) => ({
    serial: Number(li.dataset.serial), what: li.querySelector('.what').textContent,
    who: li.querySelector('.who').textContent, classes: [...li.classList],
    mark: [...li.querySelectorAll('.mark')].map((m) => m.textContent).join(' '), title: li.title })),
  notes: [...document.querySelectorAll('#history-list li.note')].map((li) => li.textContent),
  text: document.getElementById('history').innerText,
  memory: document.getElementById('history-memory').textContent,
  explain: document.getElementById('history-explain').textContent,
}));
// Waits until page `p`'s panel satisfies `check(rows)`; returns the panel.
const panelWhen = (p, check, what) => until(async () => {
  const x = await panel(p);
  return check(x.rows) ? x : null;
}, what, 60000);
const drawn = (p) => until(() => p.evaluate(() => window.__dynsolid.metrics.framesRendered > 2), 'the solid drawn', 60000);

before(async () => {
  env = await startViewer(out);
  ({ page: a, grpc } = env);
  await a.selectOption('#scene-select', 'block3');
  await a.click('#create');
  await drawn(a);
  ref = await a.evaluate(() => window.__dynsolid.session);
  cells0 = (await stats()).control_cells;
  vertices0 = await a.evaluate(() => window.__dynsolid.decoder.vertexCount);
  b = await openViewer(env.browser, a.url());
  await drawn(b);
});

after(async () => {
  if (b && !b.isClosed()) await b.close();
  if (env) await env.close();
});

test('a fresh session: the panel explains undo, lists nothing yet and shows the memory line', async () => {
  const x = await until(async () => {
    const p = await panel(a);
    return p.memory ? p : null;
  }, 'the memory line');
  assert.equal(x.explain, 'Undo takes back your last action; others\' stay.');
  assert.deepEqual(x.rows, []);
  assert.deepEqual(x.notes, ['Nothing done in this session yet.']);
  assert.match(x.memory, /^history: \d+(\.\d)? (B|KiB|MiB) of \d+(\.\d)? (KiB|MiB|GiB)$/);
  assert.equal(await a.isDisabled('#revert'), false);
});

test('A pins, B extrudes: A\'s panel lists both, its own as "you", B\'s greyed as another person', async () => {
  await tool(a, 'pin');
  const top = await project(a, { x: 1.5, y: 1.5, z: 3 });
  await a.mouse.click(top.x, top.y + 3);
  await panelWhen(a, (rows) => rows.length === 1, 'A\'s pin in A\'s panel');
  await tool(b, 'extrude');
  const side = await project(b, { x: 3, y: 1.5, z: 1.5 });
  await b.mouse.click(side.x, side.y);
  const x = await panelWhen(a, (rows) => rows.length === 2, 'B\'s extrude in A\'s panel');
  assert.equal((await stats()).control_cells, cells0 + 1);
  const [pin, extrude] = x.rows;
  assert.match(pin.what, /^pin/);
  assert.equal(pin.who, 'you');
  assert.ok(pin.classes.includes('mine') && pin.classes.includes('next-undo'), pin.classes.join());
  assert.equal(pin.mark, 'undo next');
  assert.match(pin.title, /^pin.*: yours: Undo takes it back next$/);
  assert.match(extrude.what, /^extrude face \d+$/);
  assert.equal(extrude.who, 'person 1');
  assert.ok(extrude.classes.includes('other') && !extrude.classes.includes('next-undo'), extrude.classes.join());
  assert.ok(pin.serial < extrude.serial, 'newest at the bottom');
  // Never a raw client id on the page; the server's ids are behind the labels.
  assert.ok(!x.text.includes(await clientId(b)) && !x.text.includes(await clientId(a)), x.text);
  const h = await serverHistory();
  assert.deepEqual(h.entries.map((e) => e.client_id), [await clientId(a), await clientId(b)]);
  // B's page: the other way round.
  const y = await panelWhen(b, (rows) => rows.length === 2, 'both in B\'s panel');
  assert.deepEqual(y.rows.map((r) => r.who), ['person 1', 'you']);
  assert.match(await a.getAttribute('#undo', 'title'), /takes back your "pin/);
});

test('A\'s Undo takes back A\'s pin only: struck through on the panel, B\'s extrude still in effect', async () => {
  await tool(a, 'view');
  await a.click('#undo');
  const x = await panelWhen(a, (rows) => rows.length === 2 && rows[0].classes.includes('undone'), 'the pin undone');
  const [pin, extrude] = x.rows;
  assert.ok(pin.classes.includes('next-redo') && !pin.classes.includes('next-undo'), pin.classes.join());
  assert.equal(pin.mark, 'redo next');
  assert.ok(!extrude.classes.includes('undone'), extrude.classes.join());
  // The page draws the struck-through row as such.
  const style = await a.evaluate(() => getComputedStyle(
    document.querySelector('#history-list li.undone .what')).textDecorationLine);
  assert.equal(style, 'line-through');
  // The server agrees: the pin is gone, the extruded cell stays.
  const h = await serverHistory();
  assert.deepEqual(h.entries.map((e) => e.undone), [true, false]);
  assert.equal((await stats()).control_cells, cells0 + 1);
  await until(async () => (await said(a)).some((m) => /^undo: pin/.test(m)), 'the undo message');
  await sleep(300);
  await shot(a, '01_undone');
});

test('Revert to scene asks first; "Keep it" sends nothing; "Revert" puts the session back, listed as A\'s, undoable', async () => {
  const entries = (await serverHistory()).entries.length;
  await a.click('#revert');
  assert.equal(await a.isVisible('#revert-confirm'), true);
  assert.equal(await a.textContent('#revert-question'),
    'Put the whole session back to its scene? Everyone\'s work is undone; you can undo this.');
  await shot(a, '02_revert_asks');
  await a.click('#revert-no');
  assert.equal(await a.isVisible('#revert-confirm'), false);
  await sleep(500);
  assert.equal((await serverHistory()).entries.length, entries, 'nothing sent');

  await a.click('#revert');
  await a.click('#revert-yes');
  assert.equal(await a.isVisible('#revert-confirm'), false);
  const x = await panelWhen(a, (rows) => rows.some((r) => r.what === 'revert to the scene'), 'the revert in A\'s panel');
  const last = x.rows[x.rows.length - 1];
  assert.equal(last.what, 'revert to the scene');
  assert.equal(last.who, 'you');
  assert.ok(last.classes.includes('next-undo'), last.classes.join());
  // B's extrude is still listed (the revert is an entry of its own).
  assert.ok(x.rows.some((r) => /^extrude face/.test(r.what) && r.who === 'person 1'));
  assert.equal((await stats()).control_cells, cells0);
  await until(async () => (await said(a)).some((m) => /back to its scene/.test(m)), 'the revert\'s message');
  const y = await panelWhen(b, (rows) => rows.some((r) => r.what === 'revert to the scene'), 'the revert in B\'s panel');
  assert.equal(y.rows[y.rows.length - 1].who, 'person 1');
  assert.ok(y.rows[y.rows.length - 1].classes.includes('other'));
  await until(() => a.evaluate((n) => window.__dynsolid.decoder.vertexCount === n, vertices0), 'A drawing block3 as created');
  await sleep(500);
  await shot(a, '03_reverted');
  // "You can undo this": A's Undo puts B's extruded cell back.
  await a.click('#undo');
  await until(async () => (await stats()).control_cells === cells0 + 1, 'the revert undone');
  await panelWhen(a, (rows) => rows[rows.length - 1].classes.includes('undone'), 'the revert struck through');
});
