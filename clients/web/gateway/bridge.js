// One page's connection: JSON messages from the page become gRPC calls on
// dynsolid-server, and the answers go back. Thin on purpose: no simulation,
// no mesh work; Watch frames pass through as the server's bytes.
//
// Page -> gateway (JSON text):
//   {op: "call", id, method, request}   a unary call (UNARY_METHODS)
//   {op: "watch", request}              (re)starts this page's Watch stream
//   {op: "unwatch"}
//   {op: "command", request}            a CommandRequest on this page's
//                                       Commands stream (opened on demand,
//                                       one per session)
//   {op: "export", id, request: {session: {id}, format, level?, color_field}}
//                                       the design as a file (Export, a
//                                       server stream) of one of this page's
//                                       own sessions: the gateway adds the
//                                       token it holds for it and the chunk
//                                       size; at most MAX_EXPORTS at once
//   {op: "export_cancel", id}           cancels that export
// Gateway -> page:
//   {op: "hello", server, gateway, max_message_bytes, max_messages_per_second}
//   {op: "result", id, ok, response | code, code_name, message}
//   binary: one serialized dynsolid.Frame per message
//   {op: "watch_end", code, code_name, message}
//   {op: "reply", reply}                a CommandReply
//   {op: "commands_end", code, code_name, message}  the stream broke: the
//                                       page resends what is unanswered
//                                       (same client_id and seq: exactly once)
//   {op: "export_start", id, file_name, media_type, step, level, cells,
//        surface_faces, total_bytes}    the file's name and size (first chunk)
//   {op: "export_chunk", id, offset, total_bytes, data}  data: base64, each
//                                       message under max_message_bytes,
//                                       in order, offsets contiguous
//   {op: "export_end", id, ok, total_bytes | code, code_name, message}
//                                       done, or refused/failed with the
//                                       server's text (a page that goes away
//                                       cancels its exports)
//   {op: "error", message}              a message the gateway could not take
//
// A page sees and controls only its own sessions: those it created here or
// joined with their token (a GetSession the server accepted). ListSessions
// lists only those, with their tokens; nothing lists another page's
// tokens. Messages beyond the connection's rate (a token bucket) are
// refused: a call gets RESOURCE_EXHAUSTED, a command a reply saying it was
// not applied (the page sends it again a little later), anything else an
// error. README.md "Doors".

import { UNARY_METHODS, watchRaw, exportRaw, statusName, grpc } from './grpc.js';
import { MAX_REDIRECTS } from './router.js';
import { TokenBucket } from './guard.js';

// Watch frames queued in the WebSocket beyond this pause the gRPC stream, so
// a slow page makes the server skip frames for it instead of the gateway
// buffering them.
const MAX_BUFFERED_BYTES = 2 << 20;

// Per connection, unless main.js is told otherwise (--max_message_bytes,
// --max_messages_per_second, --message_burst). A drag sends about 60
// messages a second.
export const DEFAULT_LIMITS = { maxMessageBytes: 4 << 20, rate: 200, burst: 400 };

// Exports one page may run at once.
export const MAX_EXPORTS = 2;
// ExportRequest.chunk_bytes: the server takes 4096 to 4 MiB; the gateway
// asks for at most 1 MiB (one gRPC message) and for less when the page's
// messages must be smaller (exportPieceBytes).
const SERVER_MIN_CHUNK = 4096;
const SERVER_CHUNK = 1 << 20;
// JSON around an export_chunk's data, with room to spare (ids are short).
const CHUNK_ENVELOPE_BYTES = 320;
// An export's id as the page names it: a number, or a short plain string.
const validExportId = (id) => (typeof id === 'number' && Number.isSafeInteger(id)) ||
  (typeof id === 'string' && /^[\w.:-]{1,64}$/.test(id));

// The most file bytes one export_chunk may carry so that the message (the
// bytes in base64 and its JSON) stays within `maxMessageBytes`; 0 when the
// limit leaves no room.
export function exportPieceBytes(maxMessageBytes) {
  const room = maxMessageBytes - CHUNK_ENVELOPE_BYTES;
  return room < 4 ? 0 : Math.floor(room / 4) * 3;
}

const isObject = (v) => v !== null && typeof v === 'object' && !Array.isArray(v);

export class Bridge {
  // router: where sessions live (router.js), shared by every page.
  // limits: DEFAULT_LIMITS's fields, and now() (ms) for the rate limit.
  constructor({ ws, service, router, address, callDeadlineSeconds = 600, limits = {} }) {
    this.ws = ws;
    this.service = service;
    this.router = router;
    this.limits = { ...DEFAULT_LIMITS, ...limits };
    this.bucket = new TokenBucket({ rate: this.limits.rate, burst: this.limits.burst, now: limits.now });
    this.sessions = new Map();  // id -> token: this page's own sessions
    this.deadlineSeconds = callDeadlineSeconds;
    this.watch = null;
    this.commands = null;
    this.commandsSession = null;
    this.closed = false;
    this.drainTimer = null;
    this.exports = new Map();  // page's export id -> {call, timer}
    this.send({ op: 'hello', server: address, gateway: 'dynsolid-web',
      max_message_bytes: this.limits.maxMessageBytes, max_messages_per_second: this.limits.rate });
  }

  send(message) {
    if (this.closed || this.ws.readyState !== 1) return;
    this.ws.send(typeof message === 'string' || message instanceof Uint8Array
      ? message : JSON.stringify(message));
  }

  onMessage(data, isBinary) {
    const inRate = this.bucket.take();
    const m = this.parse(data, isBinary);
    if (!m) return;
    if (!inRate) {
      this.refuse(m, `over this connection's rate limit (${this.limits.rate} messages/s, bursts of ` +
        `${this.limits.burst}): not passed on`);
      return;
    }
    try {
      this.dispatch(m);
    } catch (e) {
      this.refuse(m, `the gateway could not take this ${m.op}: ${e.message}`, grpc.status.INVALID_ARGUMENT);
    }
  }

  // The message as an object {op, request?}, or null (the page told why).
  parse(data, isBinary) {
    if (isBinary) {
      this.send({ op: 'error', message: 'the gateway takes JSON text messages only' });
      return null;
    }
    let m;
    try {
      m = JSON.parse(data.toString());
    } catch (e) {
      this.send({ op: 'error', message: `not JSON: ${e.message}` });
      return null;
    }
    if (!isObject(m)) {
      this.send({ op: 'error', message: 'a message is a JSON object {op, ...}' });
      return null;
    }
    if (m.request !== undefined && !isObject(m.request)) {
      this.refuse(m, 'request must be a JSON object', grpc.status.INVALID_ARGUMENT);
      return null;
    }
    return m;
  }

  dispatch(m) {
    switch (m.op) {
      case 'call': return this.call(m);
      case 'watch': return this.startWatch(m.request || {});
      case 'unwatch': return this.stopWatch();
      case 'command': return this.command(m.request || {});
      case 'export': return this.startExport(m);
      case 'export_cancel': return this.cancelExport(m.id);
      default: this.send({ op: 'error', message: `unknown op ${JSON.stringify(m.op)}` });
    }
  }

  // Answers a message not passed on, in the form its sender waits for.
  refuse(m, message, code = grpc.status.RESOURCE_EXHAUSTED) {
    if (m.op === 'call') {
      this.send({ op: 'result', id: m.id, ok: false, code, code_name: statusName(code), message });
    } else if (m.op === 'export') {
      this.send({ op: 'export_end', id: m.id, ok: false, code, code_name: statusName(code), message });
    } else if (m.op === 'command' && isObject(m.request) && code === grpc.status.RESOURCE_EXHAUSTED) {
      // As the server's own rate limit: not applied (applied_step -1).
      const { client_id: clientId, seq } = m.request;
      this.send({ op: 'reply', reply: { client_id: clientId, seq, code, message, applied_step: -1 } });
    } else {
      this.send({ op: 'error', message: `${m.op}: ${message}` });
    }
  }

  call({ id, method, request }) {
    if (!UNARY_METHODS.has(method)) {
      this.send({ op: 'result', id, ok: false, code: grpc.status.UNIMPLEMENTED,
        code_name: 'UNIMPLEMENTED', message: `the gateway does not pass ${method}` });
      return;
    }
    const r = request || {};
    const deadline = new Date(Date.now() + this.deadlineSeconds * 1000);
    const done = (err, response) => {
      if (err) {
        this.send({ op: 'result', id, ok: false, code: err.code, code_name: statusName(err.code),
          message: err.details || err.message });
        return;
      }
      this.answered(method, r, response);
      this.send({ op: 'result', id, ok: true, response });
    };
    if (method === 'ListSessions') {
      this.listEverywhere(deadline, done);
      return;
    }
    // The session a call names: SessionRef (id) or a request's session.
    const session = r.session ? r.session.id : r.id;
    const attempt = (redirects) => {
      this.router.forSession(session)[method](r, { deadline }, (err, response) => {
        if (err && redirects < MAX_REDIRECTS && this.router.follow(err)) {
          attempt(redirects + 1);
          return;
        }
        done(err, response);
      });
    };
    attempt(0);
  }

  // What a successful call tells about this page's own sessions. A
  // GetSession the server answered proves the page has the token (joined).
  answered(method, request, response) {
    if (method === 'CreateSession' || method === 'GetSession') this.router.learn(response);
    if (method === 'CreateSession') this.sessions.set(response.id, response.token);
    if (method === 'GetSession') this.sessions.set(request.id, request.token);
    if (method === 'CloseSession') {
      this.sessions.delete(request.id);
      this.router.forget(request.id);
    }
    if (method === 'ListSessions') {
      response.sessions = (response.sessions || []).filter((s) => this.sessions.has(s.id))
        .map((s) => ({ ...s, token: this.sessions.get(s.id) }));
    }
  }

  // ListSessions of every replica (the first one's GetServerInfo names its
  // peers), merged; a peer that does not answer is left out.
  listEverywhere(deadline, done) {
    const first = this.router.client();
    first.GetServerInfo({}, { deadline }, (infoErr, info) => {
      const addresses = [this.router.first];
      if (!infoErr) for (const p of info.peers || []) addresses.push(p.address);
      const sessions = [];
      let pending = addresses.length;
      let firstErr = null;
      addresses.forEach((address, i) => {
        this.router.client(address).ListSessions({}, { deadline }, (err, response) => {
          if (err && i === 0) firstErr = err;
          if (!err) sessions.push(...(response.sessions || []));
          if (--pending > 0) return;
          if (firstErr) done(firstErr);
          else done(null, { sessions });
        });
      });
    });
  }

  startWatch(request, redirects = 0) {
    this.stopWatch();
    const session = request.session && request.session.id;
    const call = watchRaw(this.service, this.router.forSession(session), request);
    this.watch = call;
    call.on('data', (bytes) => {
      if (this.watch !== call) return;
      this.send(new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength));
      if (this.ws.bufferedAmount > MAX_BUFFERED_BYTES) this.pauseUntilDrained(call);
    });
    call.on('error', (err) => {
      if (this.watch !== call) return;
      this.watch = null;
      if (redirects < MAX_REDIRECTS && this.router.follow(err)) {
        this.startWatch(request, redirects + 1);  // watch it where it lives
        return;
      }
      this.send({ op: 'watch_end', code: err.code, code_name: statusName(err.code),
        message: err.details || err.message });
    });
    call.on('end', () => {
      if (this.watch !== call) return;
      this.watch = null;
      this.send({ op: 'watch_end', code: 0, code_name: 'OK', message: 'the watch stream ended' });
    });
  }

  pauseUntilDrained(call) {
    call.pause();
    clearInterval(this.drainTimer);
    this.drainTimer = setInterval(() => {
      if (this.closed || this.watch !== call || this.ws.bufferedAmount < MAX_BUFFERED_BYTES / 4) {
        clearInterval(this.drainTimer);
        this.drainTimer = null;
        if (!this.closed && this.watch === call) call.resume();
      }
    }, 5);
  }

  stopWatch() {
    if (this.watch) {
      const call = this.watch;
      this.watch = null;
      call.cancel();
    }
  }

  command(request) {
    const session = request.session && request.session.id;
    if (!session) {
      this.send({ op: 'error', message: 'command: request.session.id is required' });
      return;
    }
    if (this.commands && this.commandsSession !== session) this.endCommands();
    if (!this.commands) this.openCommands(session);
    this.commands.write(request);
  }

  openCommands(session) {
    const call = this.router.forSession(session).Commands();
    this.commands = call;
    this.commandsSession = session;
    call.on('data', (reply) => this.send({ op: 'reply', reply }));
    const ended = (code, message) => {
      if (this.commands !== call) return;
      this.commands = null;
      this.commandsSession = null;
      this.send({ op: 'commands_end', code, code_name: statusName(code), message });
    };
    call.on('error', (err) => {
      // Redirected: the page resends what is unanswered at once (an OK end),
      // and the new stream opens where the session lives.
      if (this.router.follow(err)) ended(grpc.status.OK, err.details);
      else ended(err.code, err.details || err.message);
    });
    call.on('end', () => ended(0, 'the command stream ended'));
  }

  endCommands() {
    if (!this.commands) return;
    const call = this.commands;
    this.commands = null;
    this.commandsSession = null;
    call.end();
  }

  // ---- Export: the design as a file, relayed in pieces ----

  exportFailed(id, code, message) {
    this.send({ op: 'export_end', id, ok: false, code, code_name: statusName(code), message });
  }

  startExport({ id, request }) {
    if (!validExportId(id)) {
      this.send({ op: 'error', message: 'export: id must be a whole number or a short string (letters, digits, _.:-)' });
      return;
    }
    const r = request || {};
    const session = isObject(r.session) ? r.session.id : undefined;
    if (this.exports.has(id)) {
      this.exportFailed(id, grpc.status.ALREADY_EXISTS, `export ${id} is already running`);
      return;
    }
    if (this.exports.size >= MAX_EXPORTS) {
      this.exportFailed(id, grpc.status.RESOURCE_EXHAUSTED,
        `${MAX_EXPORTS} exports are already running for this page: wait for one to finish`);
      return;
    }
    if (typeof session !== 'string' || !this.sessions.has(session)) {
      this.exportFailed(id, grpc.status.PERMISSION_DENIED, `export: session ${JSON.stringify(session ?? null)} ` +
        'is not one this page created or joined (join it with its link first)');
      return;
    }
    const piece = exportPieceBytes(this.limits.maxMessageBytes);
    if (piece === 0) {
      this.exportFailed(id, grpc.status.RESOURCE_EXHAUSTED,
        `the gateway's message limit (${this.limits.maxMessageBytes} bytes) leaves no room for an export's data`);
      return;
    }
    // Only the fields a page may set; the token is the one this page holds.
    const req = { session: { id: session, token: this.sessions.get(session) },
      format: r.format, color_field: r.color_field || '',
      chunk_bytes: Math.min(SERVER_CHUNK, Math.max(SERVER_MIN_CHUNK, piece)) };
    if (r.level !== undefined && r.level !== null) req.level = r.level;
    this.runExport(id, req, piece, 0);
  }

  runExport(id, request, piece, redirects) {
    const deadline = new Date(Date.now() + this.deadlineSeconds * 1000);
    const call = exportRaw(this.service, this.router.forSession(request.session.id), request, { deadline });
    const job = { call, timer: null, next: 0, total: -1 };
    this.exports.set(id, job);
    const current = () => this.exports.get(id) === job;
    const finish = () => {
      clearInterval(job.timer);
      this.exports.delete(id);
    };
    const fail = (code, message) => {
      finish();
      call.cancel();
      this.exportFailed(id, code, message);
    };
    call.on('data', (chunk) => {
      if (!current()) return;
      if (job.total < 0) {
        job.total = chunk.total_bytes;
        const { file_name, media_type, step, level, cells, surface_faces, total_bytes } = chunk;
        this.send({ op: 'export_start', id, file_name, media_type, step, level, cells, surface_faces, total_bytes });
      }
      if (chunk.offset !== job.next || chunk.total_bytes !== job.total ||
          job.next + chunk.data.length > job.total) {
        fail(grpc.status.INTERNAL, `the server sent bytes ${chunk.offset}-${chunk.offset + chunk.data.length} ` +
          `of ${chunk.total_bytes} where ${job.next} of ${job.total} was next`);
        return;
      }
      for (let at = 0; at < chunk.data.length; at += piece) {
        const data = chunk.data.subarray(at, Math.min(chunk.data.length, at + piece));
        this.send({ op: 'export_chunk', id, offset: job.next, total_bytes: job.total, data: data.toString('base64') });
        job.next += data.length;
      }
      if (this.ws.bufferedAmount > MAX_BUFFERED_BYTES) this.pauseExport(job);
    });
    call.on('error', (err) => {
      if (!current()) return;
      finish();
      if (job.total < 0 && redirects < MAX_REDIRECTS && this.router.follow(err)) {
        this.runExport(id, request, piece, redirects + 1);  // export it where it lives
        return;
      }
      // A server from before Export answers UNIMPLEMENTED with no words.
      const words = err.details || err.message;
      this.exportFailed(id, err.code, err.code === grpc.status.UNIMPLEMENTED
        ? `this dynsolid-server has no Export (an older build): ${words}` : words);
    });
    call.on('end', () => {
      if (!current()) return;
      finish();
      if (job.total < 0 || job.next !== job.total) {
        this.exportFailed(id, grpc.status.INTERNAL,
          `the server's export ended after ${job.next} of ${Math.max(job.total, 0)} bytes`);
        return;
      }
      this.send({ op: 'export_end', id, ok: true, total_bytes: job.total });
    });
  }

  // A page that reads slowly pauses the export's gRPC stream until its
  // WebSocket has drained.
  pauseExport(job) {
    job.call.pause();
    clearInterval(job.timer);
    job.timer = setInterval(() => {
      if (this.closed || !this.ws || this.ws.bufferedAmount < MAX_BUFFERED_BYTES / 4) {
        clearInterval(job.timer);
        job.timer = null;
        if (!this.closed) job.call.resume();
      }
    }, 5);
  }

  cancelExport(id, why = 'cancelled by the page') {
    const job = this.exports.get(id);
    if (!job) return;
    this.exports.delete(id);
    clearInterval(job.timer);
    job.call.cancel();
    this.exportFailed(id, grpc.status.CANCELLED, why);
  }

  close() {
    this.closed = true;
    clearInterval(this.drainTimer);
    this.stopWatch();
    // The page is gone: its exports stop on the server too.
    for (const id of [...this.exports.keys()]) this.cancelExport(id, 'the page went away');
    // Half-close: the server answers what it has and releases this page's
    // drags and curves (their streams ended).
    this.endCommands();
  }
}
