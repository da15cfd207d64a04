// The viewer page: sessions, the live surface, tools, status. Talks only to
// the gateway (connection.js), never to anything else: every script and
// asset comes from the gateway, so the page works without internet.

import { Connection, Code } from './connection.js';
import { SurfaceDecoder, FrameError } from './surface.js';
import { View } from './view.js';
import { Tools, PARAMS } from './tools.js';
import * as C from './commands.js';
import { FIELDS, formatValue } from './colormap.js';
import { explain } from './explain.js';
import { Feedback } from './feedback.js';
import { bindKeys, wheelNudge } from './keys.js';
import { statusText } from './status.js';
import * as S from './sizing.js';
import { Keep } from './keep.js';
import { CutAway } from './cutaway.js';
import { HistoryPanel } from './history.js';
import { FaceHover } from './hover.js';
import { Help } from './help.js';
import { ScenePicker } from './scenes.js';

const $ = (id) => document.getElementById(id);

class App {
  constructor() {
    // The gateway's access token, when it has one, comes in the page's URL
    // (?access=...) and goes with the WebSocket.
    const access = new URLSearchParams(location.search).get('access');
    const wsUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws` +
      (access ? `?access=${encodeURIComponent(access)}` : '');
    this.conn = new Connection({ url: wsUrl });
    this.decoder = new SurfaceDecoder();
    this.view = new View($('view'));
    this.tools = new Tools(this);
    this.faceHover = new FaceHover(this);  // Extrude and Merge: the face under the pointer
    this.session = null;        // {id, token}
    this.info = null;           // the Session message
    this.stats = null;
    this.scale = 1;
    this.field = '';
    this.dirty = false;
    this.inspect = { loads: [], constraints: [], mesh: null, meshVersion: -1, positions: null };
    this.reconnecting = false;
    this.metrics = {
      framesReceived: 0, framesRendered: 0, keyframes: 0, skipped: 0, frameErrors: 0,
      joinedAt: null, firstPictureMs: null, frameTimes: [], dragRoundTrips: [], lastError: null,
      messages: [], watchEnds: 0, reconnects: 0, presses: [],
    };
    this.fps = 0;
    this.feedback = new Feedback(this.metrics.messages);
    this.sizing = null;         // {mesh: 'pending' | mesh | null, done, values}
    this.pointer = null;        // the last pointer position over the canvas (client px)
    this.bindUi();
    this.keep = new Keep(this);  // Download and Record (keep.js)
    this.cutaway = new CutAway(this);  // the cut-away (cutaway.js)
    this.historyPanel = new HistoryPanel(this);  // the undo history and Revert to scene (history.js)
    this.bindConnection();
    this.bindPointer();
    this.view.attachControls();
    requestAnimationFrame((t) => this.frame(t));
    setInterval(() => this.poll(), 500);
    setInterval(() => this.pollOverlays(), 250);
    window.__dynsolid = this;   // for the end-to-end tests and the benchmark
  }

  // ---- UI ----

  bindUi() {
    this.scenes = new ScenePicker($('scene-select'), $('scene-about'));  // sizes as built here
    $('create').onclick = () => this.create({ builtin_scene: $('scene-select').value });
    $('scene-file').onchange = async (e) => {
      const file = e.target.files[0];
      e.target.value = '';
      if (!file) return;
      const text = await file.text();
      this.create({ scene_text: text }, file.name);
    };
    $('refresh').onclick = () => this.refreshSessions();
    $('leave').onclick = () => this.leave();
    $('close-session').onclick = () => this.askClose(true);
    $('close-no').onclick = () => this.askClose(false);
    $('close-yes').onclick = () => {
      this.askClose(false);
      this.closeSession();
    };
    for (const b of document.querySelectorAll('#tool-buttons button')) {
      b.onclick = () => this.tools.setTool(b.dataset.tool);
    }
    $('undo').onclick = () => this.send(C.undo(), 'undo');
    $('redo').onclick = () => this.send(C.redo(), 'redo');
    $('bake').onclick = () => this.tools.edit(C.bake(), 'bake').catch((err) => this.showError(err));
    $('pause').onclick = () => this.send(C.pause());
    $('resume').onclick = () => this.send(C.resume());
    $('step').onclick = () => this.send(C.step(1));
    for (const b of document.querySelectorAll('#view-buttons button')) {
      b.onclick = () => this.look(b.dataset.view);
    }
    $('field').onchange = () => this.setField($('field').value);
    $('show-control').onchange = () => this.pollOverlays(true);
    $('show-loads').onchange = () => this.refreshMarkers();
    this.help = new Help();  // the shortcuts, on the first visit and with ?
    bindKeys(this);
    this.onToolChanged();
  }

  onToolChanged() {
    for (const b of document.querySelectorAll('#tool-buttons button')) {
      b.classList.toggle('active', b.dataset.tool === this.tools.tool);
    }
    const box = $('params');
    box.textContent = '';
    for (const [key, label, , step] of PARAMS[this.tools.tool] || []) {
      const l = document.createElement('label');
      l.textContent = label;
      const input = Array.isArray(step) ? this.choiceParam(key, step) : this.numberParam(key, label, step);
      input.dataset.param = key;
      l.appendChild(input);
      box.appendChild(l);
    }
    if (this.tools.tool === 'sharp') this.controlMesh().catch(() => {});
    this.view.showCursor(null);
    this.faceHover.clear();
  }

  numberParam(key, label, step) {
    const input = document.createElement('input');
    input.type = 'number';
    input.step = String(step === 1 ? 1 : S.stepFor(this.tools.params[key]));
    input.value = String(this.tools.params[key]);
    input.onchange = () => {
      const v = Number(input.value);
      if (!Number.isFinite(v)) {
        this.showError(new Error(`${label}: not a number`));
        input.value = String(this.tools.params[key]);
        return;
      }
      this.tools.params[key] = v;
      this.tools.touched.add(key);
    };
    return input;
  }

  // A select of [value, text] options (the material brush's preset).
  choiceParam(key, options) {
    const select = document.createElement('select');
    for (const [value, text] of options) select.add(new Option(text, value));
    select.value = this.tools.params[key];
    select.onchange = () => {
      this.tools.params[key] = select.value;
      this.tools.touched.add(key);
    };
    return select;
  }

  banner(text, kind = 'info', ms = 6000, detail = '') {
    this.feedback.banner(text, kind, ms, detail);
  }

  message(text) {
    this.banner(text, 'info', 4000);
  }

  // A refusal in plain words (explain.js), the server's text as details.
  showError(err) {
    const e = explain(err);
    this.metrics.lastError = e.detail || e.text;
    this.banner(e.hint ? `${e.text} ${e.hint}` : e.text, 'error', 10000, e.detail);
  }

  // A tool's press that found no solid: said next to the pointer (the
  // camera stays where it was).
  noSolid(x, y) {
    this.feedback.hud('no solid here', x, y, 1500);
    this.metrics.messages.push({ kind: 'hud', text: 'no solid here' });
    if (this.metrics.messages.length > 50) this.metrics.messages.shift();
  }

  // `[`/`]`, shift, the wheel with a modifier: the tool's size or strength,
  // shown next to the pointer and in the panel.
  nudge(which, steps) {
    const a = this.tools.nudge(which, steps);
    if (!a) return;
    const input = document.querySelector(`#params [data-param=${a.key}]`);
    if (input) input.value = String(a.value);
    const label = PARAMS[this.tools.tool].find((p) => p[0] === a.key)[1];
    const p = this.pointer || { x: 400, y: 300 };
    this.feedback.hud(`${label}: ${formatValue(a.value)}`, p.x, p.y);
    if (this.pointer) this.tools.showCursorAt(p.x, p.y);
  }

  // A view preset (front, side, top, iso) or 'frame'.
  look(preset) {
    this.view.look(preset);
  }

  // Shows the field a brush paints (the Field select follows).
  showField(name) {
    if (!name || this.field === name) return;
    $('field').value = name;
    this.setField(name);
  }

  askClose(show) {
    $('close-confirm').hidden = !show || !this.session;
  }

  // ---- sessions ----

  async refreshSessions() {
    let list;
    try {
      list = await this.conn.call('ListSessions', {});
    } catch (err) {
      this.showError(err);
      return;
    }
    const ul = $('session-list');
    ul.textContent = '';
    for (const s of list.sessions || []) {
      const li = document.createElement('li');
      if (this.session && s.id === this.session.id) li.className = 'current';
      const name = document.createElement('span');
      name.textContent = `${s.scene_name} ${s.id.slice(0, 8)}`;
      li.appendChild(name);
      const join = document.createElement('button');
      join.textContent = s.token ? 'Join' : 'Join (link)';
      join.disabled = !s.token;
      join.title = s.token ? '' : 'created elsewhere: open its share link to join';
      join.onclick = () => this.join({ id: s.id, token: s.token });
      li.appendChild(join);
      ul.appendChild(li);
    }
  }

  async create(source, label) {
    const request = { ...source, start_paused: $('start-paused').checked };
    const levels = $('levels').value.trim();
    if (levels !== '') request.levels_override = Number(levels);
    if ($('model-select').value) request.model_override = $('model-select').value;
    this.feedback.progress(`creating ${label || source.builtin_scene || 'scene'}: building the solid…`);
    try {
      const s = await this.conn.call('CreateSession', request);
      // The picker's size for this scene: as built without a levels override.
      if (source.builtin_scene && levels === '') this.scenes.remember(source.builtin_scene, s.stats);
      this.created = `created ${s.scene_name}: ${s.stats.cells} cells, ${s.stats.boundary_faces} surface quads`;
      await this.join({ id: s.id, token: s.token });
    } catch (err) {
      this.showError(err);
    }
    this.refreshSessions();
  }

  async join(ref) {
    let info;
    this.feedback.progress('joining: asking the server…');
    try {
      info = await this.conn.call('GetSession', ref);
    } catch (err) {
      this.showError(err);
      return;
    }
    this.feedback.progress(`joining ${info.scene_name}: loading the surface…`);
    this.session = { id: ref.id, token: ref.token };
    this.info = info;
    this.conn.setSession(this.session);
    this.decoder.reset();
    this.view.framed = false;
    this.inspect = { loads: [], constraints: [], mesh: null, meshVersion: -1, positions: null };
    this.metrics.joinedAt = performance.now();
    this.metrics.firstPictureMs = null;
    this.startSizing();
    this.watch();
    history.replaceState(null, '', `#session=${ref.id}&token=${ref.token}`);
    $('share').textContent = `share: ${location.href}`;
    $('share').title = location.href;
    $('bake').disabled = false;
    this.keep.setSession(info);
    this.historyPanel.setSession(info);
    this.refreshSessions();
  }

  leave() {
    this.session = null;
    this.info = null;
    this.conn.unwatch();
    this.conn.setSession(null);
    history.replaceState(null, '', '#');
    $('share').textContent = '';
    $('bake').disabled = true;
    this.keep.setSession(null);
    this.view.setSection(null);
    this.historyPanel.setSession(null);
    this.askClose(false);
  }

  async closeSession() {
    if (!this.session) return;
    const ref = this.session;
    this.leave();
    try {
      await this.conn.call('CloseSession', ref);
      this.message(`closed session ${ref.id}`);
    } catch (err) {
      this.showError(err);
    }
    this.refreshSessions();
  }

  watch() {
    const request = { session: this.session, rate_hz: 60 };
    if (this.field) request[this.field] = true;
    // The stiffness field until the tools are sized (sizing.js).
    if (this.sizing && !this.sizing.done) request.stiffness = true;
    this.conn.watch(request);
  }

  // ---- tools sized to the solid ----

  // After joining: the control mesh (its cell size) and, with the first
  // keyframe, the surface bounds and the stiffness field.
  startSizing() {
    this.tools.touched.clear();
    this.sizing = { mesh: 'pending', done: false, values: null };
    const sizing = this.sizing;
    this.inspectOverlays({ mesh: true, positions: true, loads: false })
      .then((r) => { sizing.mesh = r.control_mesh || null; }, () => { sizing.mesh = null; })
      .then(() => this.trySizing());
  }

  trySizing() {
    const z = this.sizing;
    if (!z || z.done || z.mesh === 'pending' || !this.decoder.hasKeyframe) return;
    const b = S.bounds(this.decoder.positions);
    if (!b) return;
    const cell = S.cellSize(z.mesh) || S.cellSizeFromCount(b, (this.info.stats || {}).control_cells || 1);
    const range = S.valueRange(this.decoder.fields.stiffness);
    const values = S.sizeTools({ size: b.size, cell, stiffness: range || 1 });
    if (!range) {
      for (const key of ['pressure', 'dragStiffness', 'curveStiffness', 'stiffnessValue']) delete values[key];
    }
    z.done = true;
    z.values = { size: b.size, cell, stiffness: range, ...values };
    this.tools.applySizing(values);
    this.onToolChanged();
    if (this.field !== 'stiffness') this.watch();
  }

  setField(name) {
    this.field = name;
    this.view.setField(name || null);
    if (this.session) this.watch();
  }

  send(command, what) {
    return this.conn.command(command).then((reply) => {
      if (reply.history) this.message(`${what}: ${reply.history.what} (${reply.history.undo_depth} to undo, ${reply.history.redo_depth} to redo)`);
      return reply;
    }, (err) => this.showError(err));
  }

  // ---- connection ----

  bindConnection() {
    this.conn.onFrame = (bytes) => {
      try {
        const f = this.decoder.apply(bytes);
        this.metrics.framesReceived++;
        if (f.keyframe) this.metrics.keyframes++;
        this.metrics.skipped += f.skipped;
        this.dirty = true;
        if (this.reconnecting) {
          this.reconnecting = false;
          this.metrics.reconnects++;
          this.banner('reconnected: the session is live again', 'info', 4000);
        }
      } catch (err) {
        this.metrics.frameErrors++;
        if (err instanceof FrameError && err.kind === 'precondition' && this.session) this.watch();
        else this.showError(err);
      }
    };
    this.conn.onWatchEnd = (m) => {
      this.metrics.watchEnds++;
      if (!this.session) return;
      if (m.code === Code.PERMISSION_DENIED || m.code === Code.NOT_FOUND ||
          m.code === Code.INVALID_ARGUMENT) {
        this.banner(`the session is gone: ${m.message}`, 'error', 0);
        this.leave();
        return;
      }
      if (m.code === Code.CANCELLED) return;  // our own re-watch
      this.startReconnect(`server unavailable (${m.message}); reconnecting…`);
    };
    this.conn.onState = (state) => {
      if (state === 'closed') this.startReconnect('the gateway went away; reconnecting…');
      if (state === 'open') {
        this.refreshSessions();
        this.scenes.fetch(this.conn);
      }
    };
    this.conn.onError = (text) => this.banner(`gateway: ${text}`, 'error');
  }

  startReconnect(text) {
    this.banner(text, 'warn', 0);
    if (this.reconnecting) return;
    this.reconnecting = true;
    const attempt = async () => {
      if (!this.reconnecting || !this.session) return;
      try {
        await this.conn.call('GetSession', this.session);
        this.watch();
        // Frames arriving clear `reconnecting`; until then keep trying.
        setTimeout(() => { if (this.reconnecting) attempt(); }, 2000);
      } catch (err) {
        if (err.code === Code.NOT_FOUND || err.code === Code.PERMISSION_DENIED) {
          this.reconnecting = false;
          this.banner(`the server is back but the session is gone: ${err.message}`, 'error', 0);
          this.leave();
          return;
        }
        setTimeout(attempt, 1000);
      }
    };
    setTimeout(attempt, 500);
  }

  // ---- pointer ----

  bindPointer() {
    const canvas = this.view.canvas;
    canvas.addEventListener('pointerdown', (e) => {
      this.pointer = { x: e.clientX, y: e.clientY };
      // A tool's press off the solid: nothing moves (the orbit controls
      // never see it), and the person is told.
      if (this.tools.missesSolid(e)) {
        e.stopImmediatePropagation();
        this.metrics.presses.push({ x: e.clientX, y: e.clientY, button: e.button, tool: this.tools.tool, wants: false });
        this.noSolid(e.clientX, e.clientY);
        return;
      }
      const wants = this.tools.wantsPress(e);
      this.metrics.presses.push({ x: e.clientX, y: e.clientY, button: e.button, tool: this.tools.tool, wants });
      if (this.metrics.presses.length > 20) this.metrics.presses.shift();
      if (!wants) return;
      this.view.controls.enabled = false;
      canvas.setPointerCapture(e.pointerId);
      this.tools.down(e);
    });
    canvas.addEventListener('pointermove', (e) => {
      this.pointer = { x: e.clientX, y: e.clientY };
      this.tools.move(e);
    });
    const up = (e) => {
      if (canvas.hasPointerCapture && canvas.hasPointerCapture(e.pointerId)) {
        canvas.releasePointerCapture(e.pointerId);
      }
      this.view.controls.enabled = true;
      this.tools.up();
    };
    canvas.addEventListener('pointerup', up);
    canvas.addEventListener('pointercancel', up);
    canvas.addEventListener('wheel', (e) => {
      if (wheelNudge(this, e) || this.tools.wheel(e)) {
        e.preventDefault();
        e.stopImmediatePropagation();  // no zoom
      }
    }, { passive: false });
    canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  }

  // ---- drawing ----

  frame(t) {
    requestAnimationFrame((tt) => this.frame(tt));
    if (this.dirty && this.decoder.hasKeyframe) {
      this.dirty = false;
      this.view.updateSurface(this.decoder);
      const sphere = this.view.geometry.boundingSphere;
      if (sphere) this.scale = sphere.radius;
      this.metrics.framesRendered++;
      if (this.metrics.firstPictureMs === null && this.metrics.joinedAt !== null) {
        this.metrics.firstPictureMs = performance.now() - this.metrics.joinedAt;
        this.ready();
      }
      if (this.sizing && !this.sizing.done) this.trySizing();
      const now = performance.now();
      for (const rt of this.tools.framesShown(this.decoder.step, now)) {
        this.metrics.dragRoundTrips.push(rt);
      }
      this.updateLegend();
    }
    if (this.view.render(this.keep.forceDraw(t))) this.countFps(t);
  }

  // The first picture after joining: the progress banner says so.
  ready() {
    if (!this.feedback.inProgress) return;
    const what = this.created || `joined ${(this.info && this.info.scene_name) || 'the session'}`;
    this.created = null;
    this.banner(`${what}; drawn in ${this.metrics.firstPictureMs.toFixed(0)} ms`, 'info', 4000);
  }

  // Frames drawn per second, and the intervals between drawn frames while
  // drawing continuously (the benchmark's frame time).
  countFps(t) {
    if (this.lastDrawTime !== undefined && t - this.lastDrawTime < 1000) {
      this.metrics.frameTimes.push(t - this.lastDrawTime);
      if (this.metrics.frameTimes.length > 600) this.metrics.frameTimes.shift();
    }
    this.lastDrawTime = t;
    this.fpsCount = (this.fpsCount || 0) + 1;
    if (!this.fpsStart) this.fpsStart = t;
    if (t - this.fpsStart >= 1000) {
      this.fps = (this.fpsCount * 1000) / (t - this.fpsStart);
      this.fpsCount = 0;
      this.fpsStart = t;
    }
  }

  updateLegend() {
    const legend = $('legend');
    const range = this.view.range;
    if (!this.field || !range) {
      legend.hidden = true;
      return;
    }
    legend.hidden = false;
    const f = FIELDS[this.field];
    $('legend-title').textContent = `${f.label} (${f.unit})`;
    $('legend-min').textContent = formatValue(range[0]);
    $('legend-max').textContent = formatValue(range[1]);
  }

  // ---- polling: stats, overlays ----

  async poll() {
    if (!this.session || !this.conn.open) {
      this.renderStatus();
      return;
    }
    try {
      this.stats = await this.conn.call('GetStats', this.session);
    } catch (err) {
      this.stats = null;
    }
    this.renderStatus();
  }

  renderStatus() {
    const idle = this.lastDrawTime === undefined || performance.now() - this.lastDrawTime > 1000;
    const t = statusText({ connected: this.conn.open, session: this.session, info: this.info,
      stats: this.stats, reconnecting: this.reconnecting, latency: this.conn.latencyMedian(), idle,
      fps: this.fps, skipped: this.metrics.skipped, vertices: this.decoder.vertexCount });
    const el = $('status');
    el.textContent = t.short;
    el.title = t.full;
  }

  // Whether the control mesh held is not the current topology's.
  meshStale() {
    return !this.inspect.mesh || this.inspect.meshVersion !== this.decoder.topologyVersion;
  }

  // Inspect with what the overlays need; keeps the control mesh when asked.
  async inspectOverlays({ mesh, positions, loads }) {
    const r = await this.conn.call('Inspect', { session: this.session, control_mesh: mesh,
      control_positions: positions, loads });
    if (mesh) {
      this.inspect.mesh = r.control_mesh;
      this.inspect.meshVersion = r.topology_version;
    }
    if (positions) this.inspect.positions = r.control_positions;
    return r;
  }

  async controlMesh() {
    if (this.meshStale()) await this.inspectOverlays({ mesh: true, positions: true, loads: false });
    return this.inspect.mesh;
  }

  async pollOverlays(force) {
    if (!this.session || !this.conn.open || this.reconnecting) return;
    const control = $('show-control').checked;
    const loads = $('show-loads').checked;
    if (!control && !loads && !force) {
      this.view.setControlMesh(null, null, false);
      this.overlayKey = null;
      return;
    }
    if (this.overlayBusy) return;
    this.overlayBusy = true;
    try {
      const r = await this.inspectOverlays({ mesh: control && this.meshStale(), positions: control, loads });
      this.inspect.loads = r.loads || [];
      this.inspect.constraints = r.constraints || [];
      // Rebuild the overlays only when what they show changed (an idle
      // solid draws nothing new).
      const key = JSON.stringify([control, this.inspect.meshVersion, control ? r.control_positions : null,
        this.inspect.loads, this.inspect.constraints]);
      if (key !== this.overlayKey) {
        this.overlayKey = key;
        this.view.setControlMesh(this.inspect.mesh, this.inspect.positions, control);
        this.refreshMarkers();
      }
    } catch (err) {
      // The stats poll and the watch report a lost server.
    } finally {
      this.overlayBusy = false;
    }
  }

  refreshMarkers() {
    const show = $('show-loads').checked;
    this.view.setMarkers({
      loads: show ? this.inspect.loads : [], constraints: show ? this.inspect.constraints : [],
      curvePoints: this.tools.curvePoints.map((p) => p.point),
    }, this.scale);
  }

  nearestConstraint(p) {
    let best = null;
    for (const c of this.inspect.constraints) {
      const s = c.region && c.region.sphere;
      if (!s) continue;
      const d = Math.hypot(p.x - s.center.x, p.y - s.center.y, p.z - s.center.z) - s.radius;
      if (!best || d < best.d) best = { d, c };
    }
    return best && best.d < this.scale * 0.1 ? best.c : null;
  }

  // Joins the session named in the URL (#session=ID&token=TOKEN), if any.
  joinFromUrl() {
    const h = new URLSearchParams(location.hash.slice(1));
    if (h.get('session') && h.get('token')) this.join({ id: h.get('session'), token: h.get('token') });
  }
}

const app = new App();
const start = () => {
  if (app.conn.open) app.joinFromUrl();
  else setTimeout(start, 50);
};
start();
