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
//   {op: "hello", server, gateway}
//   {op: "result", id, ok, response | code, code_name, message}
//   binary: one serialized dynsolid.Frame per message
//   {op: "watch_end", code, code_name, message}
//   {op: "reply", reply}                a CommandReply
//   {op: "commands_end", code, code_name, message}  the stream broke: the
//                                       page resends what is unanswered
//                                       (same client_id and seq: exactly once)
//   {op: "error", message}              a message the gateway could not take

import { UNARY_METHODS, watchRaw, statusName, grpc } from './grpc.js';
import { MAX_REDIRECTS } from './router.js';

// Watch frames queued in the WebSocket beyond this pause the gRPC stream, so
// a slow page makes the server skip frames for it instead of the gateway
// buffering them.
const MAX_BUFFERED_BYTES = 2 << 20;

export class Bridge {
  // tokens: a Map, session id -> token, of the sessions created through
  // this gateway (shared by its pages). router: where sessions live
  // (router.js), shared likewise.
  constructor({ ws, service, router, tokens, address, callDeadlineSeconds = 600 }) {
    this.ws = ws;
    this.service = service;
    this.router = router;
    this.tokens = tokens;
    this.deadlineSeconds = callDeadlineSeconds;
    this.watch = null;
    this.commands = null;
    this.commandsSession = null;
    this.closed = false;
    this.drainTimer = null;
    this.send({ op: 'hello', server: address, gateway: 'dynsolid-web' });
  }

  send(message) {
    if (this.closed || this.ws.readyState !== 1) return;
    this.ws.send(typeof message === 'string' || message instanceof Uint8Array
      ? message : JSON.stringify(message));
  }

  onMessage(data, isBinary) {
    if (isBinary) {
      this.send({ op: 'error', message: 'the gateway takes JSON text messages only' });
      return;
    }
    let m;
    try {
      m = JSON.parse(data.toString());
    } catch (e) {
      this.send({ op: 'error', message: `not JSON: ${e.message}` });
      return;
    }
    switch (m && m.op) {
      case 'call': return this.call(m);
      case 'watch': return this.startWatch(m.request || {});
      case 'unwatch': return this.stopWatch();
      case 'command': return this.command(m.request || {});
      default: this.send({ op: 'error', message: `unknown op ${JSON.stringify(m && m.op)}` });
    }
  }

  call({ id, method, request }) {
    if (!UNARY_METHODS.has(method)) {
      this.send({ op: 'result', id, ok: false, code: grpc.status.UNIMPLEMENTED,
        code_name: 'UNIMPLEMENTED', message: `the gateway does not pass ${method}` });
      return;
    }
    const deadline = new Date(Date.now() + this.deadlineSeconds * 1000);
    const done = (err, response) => {
      if (err) {
        this.send({ op: 'result', id, ok: false, code: err.code, code_name: statusName(err.code),
          message: err.details || err.message });
        return;
      }
      if (method === 'CreateSession' || method === 'GetSession') this.router.learn(response);
      if (method === 'CreateSession') this.tokens.set(response.id, response.token);
      if (method === 'CloseSession') {
        this.tokens.delete(request.id);
        this.router.forget(request.id);
      }
      if (method === 'ListSessions') {
        for (const s of response.sessions || []) {
          if (this.tokens.has(s.id)) s.token = this.tokens.get(s.id);
        }
      }
      this.send({ op: 'result', id, ok: true, response });
    };
    if (method === 'ListSessions') {
      this.listEverywhere(deadline, done);
      return;
    }
    // The session a call names: SessionRef (id) or a request's session.
    const r = request || {};
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
