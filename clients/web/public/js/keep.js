// Keeping the work: the Download menu (the design as a file,
// made by the server's Export and relayed by the gateway in pieces, with
// progress) and the Record button (what the canvas shows, as WebM, made in
// the browser by MediaRecorder). The helpers at the top are pure (tested
// in Node: test/unit/keep.test.js); Keep binds them to the page.

// The Download menu's entries: the ExportRequest format, the file's
// extension, the colour field (glTF), and what each is for.
export const FORMATS = [
  { key: 'obj', format: 'OBJ', label: 'OBJ', ext: 'obj', color_field: '',
    what: 'surface as polygons: Blender and most 3D tools' },
  { key: 'stl', format: 'STL', label: 'STL', ext: 'stl', color_field: '',
    what: 'surface as triangles: slicers for 3D printing' },
  { key: 'ply', format: 'PLY', label: 'PLY', ext: 'ply', color_field: '',
    what: 'surface with its displacement: MeshLab, ParaView' },
  { key: 'glb', format: 'GLB', label: 'glTF (.glb)', ext: 'glb', color_field: 'displacement',
    what: 'coloured by displacement: any glTF viewer, Blender, the web' },
  { key: 'vtu', format: 'VTU', label: 'VTU (volume)', ext: 'vtu', color_field: '',
    what: 'every element, with its displacement: ParaView' },
  { key: 'scene', format: 'SCENE', label: 'Scene (save as)', ext: 'textproto', color_field: '',
    sessionLevelOnly: true,
    what: 'the design itself, painted and shaped: open it again with "Scene file…"' },
];

// The server's own export limit on levels (service.proto ExportRequest).
export const MAX_EXPORT_LEVEL = 6;

// The levels offered for a session simulated at `level`: its own first,
// then up to two finer ones (never above MAX_EXPORT_LEVEL); only its own
// for an entry saved at the session's level (a scene file: its painted
// samples belong to that level).
export function levelChoices(level, entry) {
  const base = Math.max(0, Math.min(MAX_EXPORT_LEVEL, Number.isInteger(level) ? level : 0));
  const out = [];
  const last = entry && entry.sessionLevelOnly ? base : Math.min(MAX_EXPORT_LEVEL, base + 2);
  for (let l = base; l <= last; ++l) {
    out.push({ level: l, text: l === base ? `level ${l} (session)` : `level ${l} (finer)` });
  }
  return out;
}

// The ExportRequest the page sends (the gateway adds the token).
export function exportRequest(sessionId, entry, level) {
  return { session: { id: sessionId }, format: entry.format, level, color_field: entry.color_field };
}

// Whole percent of `received` of `total` (100 for an empty file).
export function percent(received, total) {
  if (!(total > 0)) return 100;
  return Math.min(100, Math.floor((100 * received) / total));
}

export function formatBytes(n) {
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KiB`;
  return `${(n / (1024 * 1024)).toFixed(1)} MiB`;
}

// The WebM types tried, best first.
export const WEBM_TYPES = ['video/webm;codecs=vp9', 'video/webm;codecs=vp8', 'video/webm'];

// Whether this browser can record the canvas as WebM: {ok: true, mimeType}
// or {ok: false, why} in plain words. `env`: {MediaRecorder, canvas}.
export function recordSupport({ MediaRecorder: Recorder, canvas }) {
  if (!canvas || typeof canvas.captureStream !== 'function') {
    return { ok: false, why: 'This browser cannot record the view: its canvas has no captureStream.' };
  }
  if (typeof Recorder !== 'function') {
    return { ok: false, why: 'This browser cannot record video: it has no MediaRecorder.' };
  }
  const can = typeof Recorder.isTypeSupported === 'function' ? (t) => Recorder.isTypeSupported(t) : () => false;
  const mimeType = WEBM_TYPES.find(can);
  if (!mimeType) return { ok: false, why: 'This browser cannot record WebM video: it has no VP8 or VP9 encoder.' };
  return { ok: true, mimeType };
}

// "<scene>-<YYYYMMDD-HHMMSS>.webm" (local time), the scene name kept to
// letters, digits, '-' and '_'.
export function recordingName(scene, date) {
  const base = String(scene || 'view').replace(/[^A-Za-z0-9_-]/g, '_').slice(0, 64) || 'view';
  const p = (n) => String(n).padStart(2, '0');
  const t = `${date.getFullYear()}${p(date.getMonth() + 1)}${p(date.getDate())}-` +
    `${p(date.getHours())}${p(date.getMinutes())}${p(date.getSeconds())}`;
  return `${base}-${t}.webm`;
}

// Saves bytes or a Blob as a file named `name` (a download the browser
// keeps: an <a download> clicked).
export function saveFile(data, name, type = 'application/octet-stream') {
  const blob = data instanceof Blob ? data : new Blob([data], { type });
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  a.href = url;
  a.download = name;
  a.hidden = true;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000);
}

const $ = (id) => document.getElementById(id);

// The Download menu and the Record button of the page (`app`: App).
export class Keep {
  constructor(app) {
    this.app = app;
    this.download = null;   // the export in progress (its promise), or null
    this.recorder = null;   // the MediaRecorder while recording
    this.lastForced = 0;
    this.support = recordSupport({ MediaRecorder: globalThis.MediaRecorder, canvas: app.view.canvas });
    this.buildMenu();
    this.bindRecord();
    this.setSession(null);
  }

  buildMenu() {
    $('download').onclick = () => {
      $('download-menu').hidden = !$('download-menu').hidden;
    };
    const list = $('download-formats');
    list.textContent = '';
    for (const f of FORMATS) {
      const row = document.createElement('div');
      row.className = 'download-row';
      const b = document.createElement('button');
      b.textContent = f.label;
      b.dataset.format = f.key;
      b.title = `download the design as ${f.label}: ${f.what}`;
      b.onclick = () => this.start(f);
      const level = document.createElement('select');
      level.dataset.levelFor = f.key;
      level.title = 'subdivision level of the file';
      const what = document.createElement('span');
      what.className = 'small';
      what.textContent = f.what;
      row.append(b, level, what);
      list.appendChild(row);
    }
    $('download-cancel').onclick = () => {
      if (this.download) this.download.cancel();
    };
  }

  // A session joined (the Session message) or left (null).
  setSession(info) {
    const level = info && info.stats ? info.stats.levels : 0;
    for (const select of document.querySelectorAll('#download-formats select')) {
      select.textContent = '';
      const entry = FORMATS.find((f) => f.key === select.dataset.levelFor);
      for (const c of levelChoices(level, entry)) select.add(new Option(c.text, String(c.level)));
    }
    $('download').disabled = !info;
    if (!info) $('download-menu').hidden = true;
    this.updateRecord();
  }

  async start(entry) {
    const app = this.app;
    if (!app.session || this.download) return;
    const level = Number(document.querySelector(`#download-formats select[data-level-for=${entry.key}]`).value);
    const bar = $('download-progress');
    const label = $('download-status');
    bar.value = 0;
    bar.hidden = false;
    $('download-cancel').hidden = false;
    for (const b of document.querySelectorAll('#download-formats button')) b.disabled = true;
    label.textContent = `${entry.label} at level ${level}: the server is making the file…`;
    app.metrics.downloadProgress = [];
    const task = app.conn.exportDesign(exportRequest(app.session.id, entry, level), ({ received, total, file_name }) => {
      const p = percent(received, total);
      app.metrics.downloadProgress.push(p);
      bar.value = p;
      label.textContent = `${file_name}: ${p} % of ${formatBytes(total)}`;
    });
    this.download = task;
    app.metrics.downloads = app.metrics.downloads || [];
    try {
      const file = await task;
      bar.value = 100;
      label.textContent = `saved ${file.file_name} (${formatBytes(file.bytes.length)}, step ${file.step}, ` +
        `level ${file.level}, ${file.cells} cells)`;
      saveFile(file.bytes, file.file_name, file.media_type);
      app.metrics.downloads.push({ ok: true, file_name: file.file_name, bytes: file.bytes.length });
      app.banner(`saved ${file.file_name} (${formatBytes(file.bytes.length)})`, 'info', 4000);
    } catch (err) {
      label.textContent = `${entry.label}: not downloaded`;
      bar.hidden = true;
      app.metrics.downloads.push({ ok: false, message: err.message });
      app.showError(err);
    } finally {
      this.download = null;
      $('download-cancel').hidden = true;
      for (const b of document.querySelectorAll('#download-formats button')) b.disabled = false;
    }
  }

  // ---- Record ----

  bindRecord() {
    $('record').onclick = () => (this.recorder ? this.stopRecording() : this.startRecording());
  }

  updateRecord() {
    const b = $('record');
    if (!this.support.ok) {
      b.disabled = true;
      b.textContent = 'Record (unavailable)';
      b.title = this.support.why;
      $('record-why').textContent = this.support.why;
      $('record-why').hidden = false;
      return;
    }
    b.disabled = !this.app.session && !this.recorder;
    b.textContent = this.recorder ? 'Stop' : 'Record';
    b.classList.toggle('recording', !!this.recorder);
    b.title = this.recorder ? 'stop and download the video' : 'record what the view shows as WebM video';
  }

  get recording() {
    return this.recorder !== null;
  }

  startRecording() {
    const app = this.app;
    let recorder;
    try {
      const stream = app.view.canvas.captureStream(30);
      recorder = new MediaRecorder(stream, { mimeType: this.support.mimeType });
    } catch (err) {
      this.support = { ok: false, why: `This browser cannot record the view: ${err.message}` };
      this.updateRecord();
      app.banner(this.support.why, 'error', 8000);
      return;
    }
    const parts = [];
    const scene = (app.info && app.info.scene_name) || 'view';
    const started = new Date();
    recorder.ondataavailable = (e) => {
      if (e.data && e.data.size > 0) parts.push(e.data);
    };
    recorder.onstop = () => {
      const blob = new Blob(parts, { type: 'video/webm' });
      const name = recordingName(scene, started);
      app.metrics.recordings = app.metrics.recordings || [];
      app.metrics.recordings.push({ name, bytes: blob.size });
      if (blob.size > 0) {
        saveFile(blob, name);
        app.banner(`saved ${name} (${formatBytes(blob.size)})`, 'info', 4000);
      } else {
        app.banner('The recording is empty: nothing was drawn while it ran.', 'warn', 6000);
      }
    };
    recorder.onerror = (e) => app.banner(`recording stopped: ${(e.error && e.error.message) || 'an error'}`, 'error');
    recorder.start(1000);
    this.recorder = recorder;
    this.recordStart = performance.now();
    app.view.render(true);
    this.updateRecord();
  }

  stopRecording() {
    const r = this.recorder;
    this.recorder = null;
    if (r && r.state !== 'inactive') r.stop();
    this.updateRecord();
  }

  // While recording the view is drawn about 30 times a second even when
  // nothing moves, so the video keeps time (the page otherwise draws only
  // on change).
  forceDraw(t) {
    if (!this.recorder || t - this.lastForced < 33) return false;
    this.lastForced = t;
    return true;
  }
}
