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
// Gateway -> page:
//   {op: "hello", server, gateway, max_message_bytes, max_messages_per_second}
//   {op: "result", id, ok, response | code, code_name, message}
//   binary: one serialized dynsolid.Frame per message
//   {op: "watch_end", code, code_name, message}
//   {op: "reply", reply}                a CommandReply
//   {op: "commands_end", code, code_name, message}  the stream broke: the
//                                       page resends what is unanswered
//                                       (same client_id and seq: exactly once)
//   {op: "error", message}              a message the gateway could not take
//
// A page sees and controls only its own sessions: those it created here or
// joined with their token (a GetSession the server accepted). ListSessions
// lists only those, with their tokens; nothing lists another page's
// tokens. Messages beyond the connection's rate (a token bucket) are
// refused: a call gets RESOURCE_EXHAUSTED, a command a reply saying it was
// not applied (the page sends it again a little later), anything else an
// error. README.md "Doors".

import { UNARY_METHODS, watchRaw, statusName, grpc } from './grpc.js';
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
      default: this.send({ op: 'error', message: `unknown op ${JSON.stringify(m.op)}` });
    }
  }

  // Answers a message not passed on, in the form its sender waits for.
  refuse(m, message, code = grpc.status.RESOURCE_EXHAUSTED) {
    if (m.op === 'call') {
      this.send({ op: 'result', id: m.id, ok: false, code, code_name: statusName(code), message });
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

  close() {
    this.closed = true;
    clearInterval(this.drainTimer);
    this.stopWatch();
    // Half-close: the server answers what it has and releases this page's
    // drags and curves (their streams ended).
    this.endCommands();
  }
}
