// The page's side of the gateway's WebSocket (gateway/bridge.js): unary
// calls as promises, the Watch stream, and commands sent exactly once.
//
// Commands: every command gets (client_id, seq) here; it stays pending until
// its reply arrives. When the command stream or the WebSocket breaks, the
// pending commands are sent again with the same (client_id, seq) once the
// connection is back: the server applies each at most once and repeats its
// answer to a resend (service.proto "Commands"). A rate-limited command
// (RESOURCE_EXHAUSTED, never applied) is sent again after a short wait.
//
// Works in the browser and, with a WebSocket-like object and a clock given,
// in Node's test runner (test/unit/connection.test.js).

export class CallError extends Error {
  constructor(code, codeName, message) {
    super(message);
    this.code = code;
    this.codeName = codeName;
  }
}

export const Code = {
  OK: 0, CANCELLED: 1, INVALID_ARGUMENT: 3, DEADLINE_EXCEEDED: 4, NOT_FOUND: 5,
  PERMISSION_DENIED: 7, RESOURCE_EXHAUSTED: 8, FAILED_PRECONDITION: 9, OUT_OF_RANGE: 11,
  UNIMPLEMENTED: 12, INTERNAL: 13, UNAVAILABLE: 14,
};

function randomId() {
  const bytes = new Uint8Array(6);
  (globalThis.crypto || { getRandomValues: (b) => b.map(() => Math.floor(Math.random() * 256)) })
    .getRandomValues(bytes);
  return Array.from(bytes, (b) => b.toString(16).padStart(2, '0')).join('');
}

export class Connection {
  // options: url (ws://host/ws), makeSocket(url) -> WebSocket-like,
  // now() -> ms, setTimeout, clientId.
  constructor(options) {
    this.url = options.url;
    this.makeSocket = options.makeSocket || ((url) => new WebSocket(url));
    this.now = options.now || (() => performance.now());
    this.setTimeout = options.setTimeout || ((f, ms) => setTimeout(f, ms));
    this.clientId = options.clientId || `web-${randomId()}`;
    this.reconnectMs = options.reconnectMs ?? 1000;
    this.seq = 0;
    this.nextCallId = 1;
    this.calls = new Map();      // id -> {resolve, reject}
    this.exports = new Map();    // id -> an export in progress (exportDesign)
    this.nextExportId = 1;
    this.pending = new Map();    // seq -> {request, resolve, reject, sentAt}
    this.socket = null;
    this.open = false;
    this.closedByUser = false;
    this.session = null;         // {id, token}: the session commands go to
    this.watchRequest = null;    // re-sent after a reconnect
    this.maxMessageBytes = Infinity;  // the gateway's, from its hello
    // Callbacks the app sets.
    this.onFrame = () => {};
    this.onWatchEnd = () => {};
    this.onReply = () => {};
    this.onState = () => {};     // ('open' | 'closed')
    this.onError = () => {};
    this.latencies = [];         // command round trips, ms (last 200)
    this.connect();
  }

  connect() {
    const socket = this.makeSocket(this.url);
    this.socket = socket;
    socket.binaryType = 'arraybuffer';
    socket.onopen = () => {
      if (this.socket !== socket) return;
      this.open = true;
      this.onState('open');
      if (this.watchRequest) this.sendJson({ op: 'watch', request: this.watchRequest });
      this.resendPending();
    };
    socket.onmessage = (event) => this.onMessage(event.data);
    socket.onclose = () => {
      if (this.socket !== socket) return;
      const wasOpen = this.open;
      this.open = false;
      for (const [, c] of this.calls) {
        c.reject(new CallError(Code.UNAVAILABLE, 'UNAVAILABLE', 'the gateway went away'));
      }
      this.calls.clear();
      for (const [, x] of this.exports) {
        x.reject(new CallError(Code.UNAVAILABLE, 'UNAVAILABLE', 'the gateway went away during the download'));
      }
      this.exports.clear();
      if (wasOpen) this.onState('closed');
      if (!this.closedByUser) this.setTimeout(() => this.connect(), this.reconnectMs);
    };
    socket.onerror = () => {};
  }

  close() {
    this.closedByUser = true;
    if (this.socket) this.socket.close();
  }

  sendJson(message) {
    if (!this.open) return false;
    this.socket.send(JSON.stringify(message));
    return true;
  }

  // Why `message` is over the gateway's size limit (it would close the
  // connection), or null.
  tooBig(message) {
    const bytes = new TextEncoder().encode(JSON.stringify(message)).length;
    if (bytes <= this.maxMessageBytes) return null;
    return new CallError(Code.RESOURCE_EXHAUSTED, 'RESOURCE_EXHAUSTED',
      `${bytes} bytes: more than the gateway takes in one message (${this.maxMessageBytes})`);
  }

  onMessage(data) {
    if (typeof data !== 'string') {
      this.onFrame(new Uint8Array(data));
      return;
    }
    let m;
    try {
      m = JSON.parse(data);
    } catch (e) {
      this.onError(`gateway sent bad JSON: ${e.message}`);
      return;
    }
    switch (m.op) {
      case 'result': {
        const c = this.calls.get(m.id);
        if (!c) return;
        this.calls.delete(m.id);
        if (m.ok) c.resolve(m.response);
        else c.reject(new CallError(m.code, m.code_name, m.message));
        return;
      }
      case 'reply': return this.onCommandReply(m.reply);
      case 'export_start':
      case 'export_chunk':
      case 'export_end':
        return this.onExport(m);
      case 'watch_end':
        if (m.code !== Code.OK) this.watchRequest = null;
        this.onWatchEnd(m);
        return;
      case 'commands_end':
        // Resend what is unanswered on a new stream (same seq: exactly once).
        if (m.code === Code.UNAVAILABLE) {
          this.setTimeout(() => this.resendPending(), this.reconnectMs);
        } else if (m.code !== Code.OK) {
          this.failPending(new CallError(m.code, m.code_name, m.message));
        } else {
          this.resendPending();
        }
        return;
      case 'hello':
        this.maxMessageBytes = m.max_message_bytes || Infinity;
        return;
      case 'error':
        this.onError(m.message);
        return;
      default:
        this.onError(`gateway sent unknown op ${m.op}`);
    }
  }

  // A unary call: resolves with the response, rejects with CallError.
  call(method, request = {}) {
    return new Promise((resolve, reject) => {
      const id = this.nextCallId++;
      const tooBig = this.tooBig({ op: 'call', id, method, request });
      if (tooBig) {
        reject(tooBig);
        return;
      }
      if (!this.sendJson({ op: 'call', id, method, request })) {
        reject(new CallError(Code.UNAVAILABLE, 'UNAVAILABLE', 'not connected to the gateway'));
        return;
      }
      this.calls.set(id, { resolve, reject });
    });
  }

  // The current design as a file (the server's Export through the
  // gateway): `request` is {session: {id}, format, level?, color_field}.
  // onProgress({received, total, file_name}) after each piece. Resolves
  // {file_name, media_type, step, level, cells, surface_faces, bytes
  // (Uint8Array)}; rejects with CallError (the server's code and words).
  // The returned promise has cancel() (the gateway cancels the call).
  exportDesign(request, onProgress = () => {}) {
    const id = this.nextExportId++;
    let job;
    const promise = new Promise((resolve, reject) => {
      job = { resolve, reject, onProgress, start: null, bytes: null, received: 0 };
      if (!this.sendJson({ op: 'export', id, request })) {
        reject(new CallError(Code.UNAVAILABLE, 'UNAVAILABLE', 'not connected to the gateway'));
        return;
      }
      this.exports.set(id, job);
    });
    promise.cancel = () => {
      if (this.exports.has(id)) this.sendJson({ op: 'export_cancel', id });
    };
    return promise;
  }

  onExport(m) {
    const job = this.exports.get(m.id);
    if (!job) return;
    const fail = (code, codeName, message) => {
      this.exports.delete(m.id);
      job.reject(new CallError(code, codeName, message));
    };
    if (m.op === 'export_start') {
      job.start = m;
      job.bytes = new Uint8Array(m.total_bytes);
      job.onProgress({ received: 0, total: m.total_bytes, file_name: m.file_name });
      return;
    }
    if (m.op === 'export_chunk') {
      const data = fromBase64(m.data);
      if (!job.bytes || m.offset !== job.received || m.offset + data.length > job.bytes.length) {
        fail(Code.INTERNAL, 'INTERNAL', `the download's bytes came out of order (at ${m.offset}, expected ${job.received})`);
        this.sendJson({ op: 'export_cancel', id: m.id });
        return;
      }
      job.bytes.set(data, m.offset);
      job.received += data.length;
      job.onProgress({ received: job.received, total: m.total_bytes, file_name: job.start.file_name });
      return;
    }
    if (!m.ok) {
      fail(m.code, m.code_name, m.message);
      return;
    }
    if (!job.start || job.received !== job.bytes.length) {
      fail(Code.INTERNAL, 'INTERNAL', `the download ended after ${job.received} bytes of ${job.bytes ? job.bytes.length : '?'}`);
      return;
    }
    this.exports.delete(m.id);
    const { file_name, media_type, step, level, cells, surface_faces } = job.start;
    job.resolve({ file_name, media_type, step, level, cells, surface_faces, bytes: job.bytes });
  }

  watch(request) {
    this.watchRequest = request;
    this.sendJson({ op: 'watch', request });
  }

  unwatch() {
    this.watchRequest = null;
    this.sendJson({ op: 'unwatch' });
  }

  setSession(session) {
    if (this.session && session && this.session.id !== session.id) {
      this.failPending(new CallError(Code.CANCELLED, 'CANCELLED', 'left the session'));
    }
    this.session = session;
  }

  // Sends `command` (a dynsolid.Command as JSON) to the current session.
  // Resolves with the CommandReply when it was applied (code 0); rejects
  // with CallError carrying the server's message otherwise.
  command(command) {
    if (!this.session) {
      return Promise.reject(new CallError(Code.FAILED_PRECONDITION, 'FAILED_PRECONDITION',
        'no session joined'));
    }
    const seq = ++this.seq;
    const request = { session: this.session, client_id: this.clientId, seq, command };
    const tooBig = this.tooBig({ op: 'command', request });
    if (tooBig) return Promise.reject(tooBig);
    return new Promise((resolve, reject) => {
      this.pending.set(seq, { request, resolve, reject, sentAt: this.now() });
      this.sendJson({ op: 'command', request });
    });
  }

  resendPending() {
    if (!this.open) return;
    const seqs = [...this.pending.keys()].sort((a, b) => a - b);
    for (const s of seqs) this.sendJson({ op: 'command', request: this.pending.get(s).request });
  }

  failPending(error) {
    for (const [, p] of this.pending) p.reject(error);
    this.pending.clear();
  }

  onCommandReply(reply) {
    if (reply.client_id !== this.clientId) return;
    const p = this.pending.get(reply.seq);
    if (!p) return;  // a repeated answer to a resend already answered
    const code = reply.code || 0;
    if (code === Code.RESOURCE_EXHAUSTED && (reply.applied_step ?? -1) < 0) {
      // Rate limited, never applied: same seq again a little later.
      this.setTimeout(() => {
        if (this.pending.has(reply.seq)) this.sendJson({ op: 'command', request: p.request });
      }, 50);
      return;
    }
    this.pending.delete(reply.seq);
    this.latencies.push(this.now() - p.sentAt);
    if (this.latencies.length > 200) this.latencies.shift();
    this.onReply(reply, p.request.command);
    if (code === Code.OK) p.resolve(reply);
    else p.reject(new CallError(code, codeNameOf(code), reply.message || `code ${code}`));
  }

  latencyMedian() {
    if (!this.latencies.length) return null;
    const s = [...this.latencies].sort((a, b) => a - b);
    return s[Math.floor(s.length / 2)];
  }
}

// Base64 text as bytes (atob in the browser, Buffer in Node's tests).
export function fromBase64(text) {
  if (typeof atob === 'function') {
    const s = atob(text);
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; ++i) out[i] = s.charCodeAt(i);
    return out;
  }
  return new Uint8Array(Buffer.from(text, 'base64'));
}

export function codeNameOf(code) {
  for (const [name, value] of Object.entries(Code)) if (value === code) return name;
  return `code ${code}`;
}
