// The History panel: the session's undo history as the server
// keeps it (Inspect with history: true; service.proto HistoryInfo), one row
// per action in session order, newest at the bottom: yours marked "you",
// others' greyed under a short label ("person 1", never their client id),
// undone ones struck through, and which of yours Undo takes back next and
// Redo brings back next. Undo is per person, last first: the rows are not
// buttons. Also the memory the history holds, and Revert to scene (asks
// first). The helpers at the top are pure (tested in Node:
// test/unit/history.test.js); HistoryPanel binds them to the page.

import { revertToScene } from './commands.js';

// Rows shown at most (the newest); the list scrolls.
export const MAX_ROWS = 30;

// How often the panel asks the server while a session is joined, ms.
export const POLL_MS = 1000;

export const EXPLAIN = 'Undo takes back your last action; others\' stay.';
export const REVERT_QUESTION = 'Put the whole session back to its scene? Everyone\'s work is undone; you can undo this.';

// Labels for the other people in `history`, by client id: "person 1",
// "person 2", ... in order of first appearance (entries in session order,
// then people without entries). `known` (a Map from an earlier call) keeps
// everyone's number once given, so a label stays the same while entries
// come and go. Returns a new Map; this page's own id is never in it.
export function labelPeople(history, myId, known = new Map()) {
  const labels = new Map(known);
  const add = (id) => {
    if (id === myId || labels.has(id)) return;
    labels.set(id, id ? `person ${labels.size + 1}` : 'someone');
  };
  for (const e of (history && history.entries) || []) add(e.client_id || '');
  for (const p of (history && history.people) || []) add(p.client_id || '');
  return labels;
}

// Bytes as people read them: "512 B", "3.2 KiB", "3.2 MiB", "256 MiB"
// (one decimal under 10, whole numbers above).
export function sizeText(n) {
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let v = Math.max(0, Number(n) || 0);
  let u = 0;
  while (v >= 1024 && u < units.length - 1) {
    v /= 1024;
    ++u;
  }
  if (u === 0) return `${v} B`;
  const text = v < 10 ? v.toFixed(1) : String(Math.round(v));
  return `${text.replace(/\.0$/, '')} ${units[u]}`;
}

// "history: 3.2 MiB of 256 MiB" (no limit: "history: 3.2 MiB").
export function memoryLine(history) {
  const bytes = Number((history && history.bytes) || 0);
  const limit = Number((history && history.limit_bytes) || 0);
  return limit > 0 ? `history: ${sizeText(bytes)} of ${sizeText(limit)}` : `history: ${sizeText(bytes)}`;
}

// What the panel shows for `history` (a HistoryInfo as the gateway gives
// it, or null) seen by the page whose client id is `myId`. `labels`: from
// labelPeople. Returns
//   rows: the last `max` entries, oldest first, each {serial, what, mine,
//     who ("you" or another person's label), undone, nextUndo, nextRedo,
//     classes (for the row's class attribute), title (a sentence)};
//   earlier: how many older entries are not shown;
//   nextUndo / nextRedo: the entry (row fields) Undo / Redo of this page
//     takes back / brings back next, or null (it may be older than the
//     rows shown);
//   memory: the memory line; empty: no entries at all.
export function historyView(history, myId, labels = labelPeople(history, myId), max = MAX_ROWS) {
  const entries = (history && history.entries) || [];
  const me = ((history && history.people) || []).find((p) => p.client_id === myId) || { undo: [], redo: [] };
  const last = (list) => (list && list.length ? Number(list[list.length - 1]) : null);
  const undoSerial = last(me.undo);
  const redoSerial = last(me.redo);
  const all = entries.map((e) => {
    const serial = Number(e.serial);
    const mine = e.client_id === myId;
    const who = mine ? 'you' : labels.get(e.client_id || '') || 'someone';
    const undone = Boolean(e.undone);
    const nextUndo = mine && serial === undoSerial;
    const nextRedo = mine && serial === redoSerial;
    const classes = [mine ? 'mine' : 'other'];
    if (undone) classes.push('undone');
    if (nextUndo) classes.push('next-undo');
    if (nextRedo) classes.push('next-redo');
    return { serial, what: e.what || 'an action', mine, who, undone, nextUndo, nextRedo, classes,
      title: rowTitle({ mine, who, undone, nextUndo, nextRedo }) };
  });
  const shown = all.slice(Math.max(0, all.length - max));
  return {
    rows: shown,
    earlier: all.length - shown.length,
    nextUndo: all.find((r) => r.nextUndo) || null,
    nextRedo: all.find((r) => r.nextRedo) || null,
    memory: memoryLine(history),
    empty: all.length === 0,
  };
}

function rowTitle({ mine, who, undone, nextUndo, nextRedo }) {
  if (!mine) {
    return undone ? `${who}'s, undone: only ${who} can redo it` : `${who}'s: only ${who} can undo it`;
  }
  if (nextUndo) return 'yours: Undo takes it back next';
  if (nextRedo) return 'yours, undone: Redo brings it back next';
  return undone ? 'yours, undone' : 'yours: Undo reaches it after your later actions';
}

// The Undo and Redo buttons' tooltips for a view (historyView).
export function buttonTitles(view) {
  return {
    undo: view && view.nextUndo ? `Ctrl+Z: takes back your "${view.nextUndo.what}"` : 'Ctrl+Z: you have nothing to undo',
    redo: view && view.nextRedo ? `Ctrl+Shift+Z: brings back your "${view.nextRedo.what}"`
      : 'Ctrl+Shift+Z: you have nothing to redo',
  };
}

const $ = (id) => document.getElementById(id);

// The panel on the page (`app`: App): polls Inspect {history: true} about
// once a second while a session is joined, and soon after each of this
// page's command replies; Revert to scene with its confirmation.
export class HistoryPanel {
  constructor(app) {
    this.app = app;
    this.labels = new Map();
    this.key = null;        // what is drawn (to redraw only on change)
    this.busy = false;
    this.soonTimer = null;
    this.view = null;
    this.scrolled = false;
    $('history-explain').textContent = EXPLAIN;
    $('revert-question').textContent = REVERT_QUESTION;
    $('revert').onclick = () => this.askRevert(true);
    $('revert-no').onclick = () => this.askRevert(false);
    $('revert-yes').onclick = () => {
      this.askRevert(false);
      this.revert();
    };
    // After a reply to one of this page's commands (a drag's moves aside).
    const previous = app.conn.onReply;
    app.conn.onReply = (reply, command) => {
      previous(reply, command);
      if (!command || !command.move_drag) this.soon();
    };
    setInterval(() => this.refresh(), POLL_MS);
    this.setSession(null);
  }

  // A session joined (the Session message) or left (null).
  setSession(info) {
    this.labels = new Map();
    this.key = null;
    this.view = null;
    this.scrolled = false;  // the list put at its newest rows once
    $('revert').disabled = !info;
    if (!info) this.askRevert(false);
    this.draw(null);
    if (info) this.soon();
  }

  askRevert(show) {
    $('revert-confirm').hidden = !show || !this.app.session;
  }

  // A refresh shortly (several requests in a row make one).
  soon() {
    if (this.soonTimer) return;
    this.soonTimer = setTimeout(() => {
      this.soonTimer = null;
      this.refresh();
    }, 100);
  }

  async refresh() {
    const app = this.app;
    if (!app.session || !app.conn.open || app.reconnecting || this.busy) return;
    if (typeof document !== 'undefined' && document.hidden) return;
    this.busy = true;
    const session = app.session;
    try {
      const r = await app.conn.call('Inspect', { session, history: true });
      if (app.session !== session) return;  // left or joined another meanwhile
      this.draw(r.history || { entries: [], people: [], bytes: 0, limit_bytes: 0 });
    } catch (err) {
      // The stats poll and the watch report a lost server.
    } finally {
      this.busy = false;
    }
  }

  draw(history) {
    const myId = this.app.conn.clientId;
    const key = JSON.stringify(history);
    if (key === this.key) return;
    this.key = key;
    const list = $('history-list');
    const memory = $('history-memory');
    if (!history) {
      list.textContent = '';
      list.appendChild(note('Join a session to see what was done in it.'));
      memory.textContent = '';
      this.setButtons(null);
      return;
    }
    this.labels = labelPeople(history, myId, this.labels);
    const view = historyView(history, myId, this.labels);
    this.view = view;
    const atBottom = list.scrollTop + list.clientHeight >= list.scrollHeight - 4;
    list.textContent = '';
    if (view.empty) list.appendChild(note('Nothing done in this session yet.'));
    if (view.earlier > 0) list.appendChild(note(`${view.earlier} earlier ${view.earlier === 1 ? 'entry' : 'entries'} not shown`));
    for (const row of view.rows) {
      const li = document.createElement('li');
      li.className = row.classes.join(' ');
      li.dataset.serial = String(row.serial);
      li.title = `${row.what}: ${row.title}`;  // the whole name, when the row cuts it
      li.append(span('serial', String(row.serial)), span('what', row.what), span('who', row.who));
      if (row.nextUndo) li.appendChild(span('mark', 'undo next'));
      if (row.nextRedo) li.appendChild(span('mark', 'redo next'));
      list.appendChild(li);
    }
    // Newest at the bottom, in sight, unless the person scrolled up to read.
    if (atBottom || !this.scrolled) list.scrollTop = list.scrollHeight;
    this.scrolled = true;
    memory.textContent = view.memory;
    this.setButtons(view);
  }

  setButtons(view) {
    const t = buttonTitles(view);
    $('undo').title = t.undo;
    $('redo').title = t.redo;
  }

  async revert() {
    const app = this.app;
    if (!app.session) return;
    app.feedback.progress('revert to the scene: building…');
    try {
      await app.conn.command(revertToScene());
      app.message('The session is back to its scene. Undo puts the work back.');
    } catch (err) {
      app.showError(err);
    } finally {
      app.feedback.stopProgress();
      this.soon();
    }
  }
}

function span(className, text) {
  const s = document.createElement('span');
  s.className = className;
  s.textContent = text;
  return s;
}

function note(text) {
  const li = document.createElement('li');
  li.className = 'note';
  li.textContent = text;
  return li;
}
