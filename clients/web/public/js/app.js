// The viewer page: sessions, the live surface, tools, status. Talks only to
// the gateway (connection.js), never to anything else: every script and
// asset comes from the gateway, so the page works without internet.

import { Connection, Code } from './connection.js';
import { SurfaceDecoder, FrameError } from './surface.js';
import { View } from './view.js';
import { Tools, PARAMS } from './tools.js';
import * as C from './commands.js';
import { FIELDS, formatValue } from './colormap.js';

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
    this.bindUi();
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
    $('close-session').onclick = () => this.closeSession();
    for (const b of document.querySelectorAll('#tool-buttons button')) {
      b.onclick = () => this.tools.setTool(b.dataset.tool);
    }
    $('undo').onclick = () => this.send(C.undo(), 'undo');
    $('redo').onclick = () => this.send(C.redo(), 'redo');
    $('bake').onclick = () => this.tools.edit(C.bake(), 'bake').catch((err) => this.showError(err));
    $('pause').onclick = () => this.send(C.pause());
    $('resume').onclick = () => this.send(C.resume());
    $('step').onclick = () => this.send(C.step(1));
    $('reset-camera').onclick = () => this.view.resetCamera();
    $('field').onchange = () => this.setField($('field').value);
    $('show-control').onchange = () => this.pollOverlays(true);
    $('show-loads').onchange = () => this.refreshMarkers();
    window.addEventListener('keydown', (e) => {
      if (e.target.tagName === 'INPUT' && e.target.type !== 'checkbox') return;
      const k = e.key.toLowerCase();
      if ((e.ctrlKey || e.metaKey) && k === 'z') {
        e.preventDefault();
        this.send(e.shiftKey ? C.redo() : C.undo(), e.shiftKey ? 'redo' : 'undo');
      } else if ((e.ctrlKey || e.metaKey) && k === 'y') {
        e.preventDefault();
        this.send(C.redo(), 'redo');
      } else if (e.key === 'Escape') {
        this.tools.cancel();
      }
    });
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
  }

  numberParam(key, label, step) {
    const input = document.createElement('input');
    input.type = 'number';
    input.step = String(step);
    input.value = String(this.tools.params[key]);
    input.onchange = () => {
      const v = Number(input.value);
      if (!Number.isFinite(v)) {
        this.showError(new Error(`${label}: not a number`));
        input.value = String(this.tools.params[key]);
        return;
      }
      this.tools.params[key] = v;
    };
    return input;
  }

  // A select of [value, text] options (the material brush's preset).
  choiceParam(key, options) {
    const select = document.createElement('select');
    for (const [value, text] of options) select.add(new Option(text, value));
    select.value = this.tools.params[key];
    select.onchange = () => { this.tools.params[key] = select.value; };
    return select;
  }

  banner(text, kind = 'info', ms = 6000) {
    const b = $('banner');
    b.textContent = text;
    b.className = kind;
    b.hidden = false;
    clearTimeout(this.bannerTimer);
    if (ms) this.bannerTimer = setTimeout(() => { b.hidden = true; }, ms);
    this.metrics.messages.push({ kind, text });
    if (this.metrics.messages.length > 50) this.metrics.messages.shift();
  }

  message(text) {
    this.banner(text, 'info', 4000);
  }

  showError(err) {
    const text = err && err.codeName ? `refused (${err.codeName}): ${err.message}` : String(err.message || err);
    this.metrics.lastError = text;
    this.banner(text, 'error', 8000);
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
    this.banner(`creating ${label || source.builtin_scene || 'scene'}…`, 'info', 0);
    try {
      const s = await this.conn.call('CreateSession', request);
      this.banner(`created ${s.scene_name}: ${s.stats.cells} cells, ${s.stats.boundary_faces} surface quads`);
      await this.join({ id: s.id, token: s.token });
    } catch (err) {
      this.showError(err);
    }
    this.refreshSessions();
  }

  async join(ref) {
    let info;
    try {
      info = await this.conn.call('GetSession', ref);
    } catch (err) {
      this.showError(err);
      return;
    }
    this.session = { id: ref.id, token: ref.token };
    this.info = info;
    this.conn.setSession(this.session);
    this.decoder.reset();
    this.view.framed = false;
    this.inspect = { loads: [], constraints: [], mesh: null, meshVersion: -1, positions: null };
    this.metrics.joinedAt = performance.now();
    this.metrics.firstPictureMs = null;
    this.watch();
    history.replaceState(null, '', `#session=${ref.id}&token=${ref.token}`);
    $('share').textContent = `share: ${location.href}`;
    $('bake').disabled = false;
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
    this.conn.watch(request);
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
      if (state === 'open') this.refreshSessions();
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
      const wants = this.tools.wantsPress(e);
      this.metrics.presses.push({ x: e.clientX, y: e.clientY, button: e.button, tool: this.tools.tool, wants });
      if (this.metrics.presses.length > 20) this.metrics.presses.shift();
      if (!wants) return;
      this.view.controls.enabled = false;
      canvas.setPointerCapture(e.pointerId);
      this.tools.down(e);
    });
    canvas.addEventListener('pointermove', (e) => this.tools.move(e));
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
      if (this.tools.wheel(e)) e.preventDefault();
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
      }
      const now = performance.now();
      for (const rt of this.tools.framesShown(this.decoder.step, now)) {
        this.metrics.dragRoundTrips.push(rt);
      }
      this.updateLegend();
    }
    if (this.view.render()) this.countFps(t);
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
    const parts = [];
    if (!this.conn.open) parts.push('gateway: disconnected');
    if (this.session) {
      const s = this.stats;
      const info = this.info || {};
      parts.push(`${info.scene_name || '?'} ${this.session.id.slice(0, 8)}`);
      const st = info.stats || {};
      if (st.model) {
        parts.push(`${st.model} / ${st.integrator}${st.substeps > 1 ? ` ×${st.substeps}` : ''}`);
      }
      if (s) {
        const rtf = s.steps_per_second * (s.time_step || 0);
        parts.push(`step ${s.step}${s.paused ? ' (paused)' : ''}`);
        parts.push(`${(s.steps_per_second || 0).toFixed(0)} steps/s`);
        parts.push(`real time ×${rtf.toFixed(2)}`);
        parts.push(`step ${(s.step_ms_median || 0).toFixed(1)} ms`);
      } else if (this.reconnecting) {
        parts.push('server unavailable');
      }
      const lat = this.conn.latencyMedian();
      parts.push(`command ${lat === null ? '–' : lat.toFixed(0) + ' ms'}`);
      const idle = this.lastDrawTime === undefined || performance.now() - this.lastDrawTime > 1000;
      parts.push(idle ? 'idle (nothing moved)' : `${this.fps.toFixed(0)} fps`);
      parts.push(`${this.metrics.skipped} skipped`);
      parts.push(`${this.decoder.vertexCount} vertices`);
    } else {
      parts.push('no session: create one or join one');
    }
    $('status').textContent = parts.join(' · ');
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
