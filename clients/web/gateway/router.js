// Where each session lives when dynsolid-server runs as several replicas
// (docs/deploy.md "How sessions are placed and found"): a session's calls go
// to the address its Session reply named, or to the owner a redirect named
// (FAILED_PRECONDITION with a dynsolid.SessionRedirect in the
// grpc-status-details-bin trailer). One gRPC client per address, shared by
// every page. A server running alone names no address: everything goes to
// the first one.

import { Reader } from '../public/js/wire.js';
import { makeClient, grpc } from './grpc.js';

const REDIRECT_TYPE_URL = 'type.googleapis.com/dynsolid.SessionRedirect';
// Redirects followed in a row before a call gives up (as the C++ client).
export const MAX_REDIRECTS = 4;

const utf8 = new TextDecoder();

// The strings of a message's length-delimited fields named in `names`
// (field number -> key).
function readStrings(reader, names) {
  const out = {};
  for (const key of Object.values(names)) out[key] = '';
  while (!reader.done()) {
    const { field, wire } = reader.tag();
    if (names[field] && wire === 2) out[names[field]] = utf8.decode(reader.bytesField());
    else reader.skip(wire);
  }
  return out;
}

// The SessionRedirect a gRPC error carries ({session_id, replica, address}),
// or null. grpc-status-details-bin holds an RpcStatus (google.rpc.Status on
// the wire): details = 3, each an Any (type_url = 1, value = 2).
export function parseRedirect(err) {
  if (!err || err.code !== grpc.status.FAILED_PRECONDITION || !err.metadata) return null;
  const [details] = err.metadata.get('grpc-status-details-bin');
  if (!details) return null;
  try {
    const status = new Reader(new Uint8Array(details));
    while (!status.done()) {
      const { field, wire } = status.tag();
      if (field !== 3 || wire !== 2) {
        status.skip(wire);
        continue;
      }
      const any = status.sub();
      let typeUrl = '';
      let value = null;
      while (!any.done()) {
        const t = any.tag();
        if (t.field === 1 && t.wire === 2) typeUrl = utf8.decode(any.bytesField());
        else if (t.field === 2 && t.wire === 2) value = any.sub();
        else any.skip(t.wire);
      }
      if (typeUrl !== REDIRECT_TYPE_URL || value === null) continue;
      const r = readStrings(value, { 1: 'session_id', 2: 'replica', 3: 'address' });
      if (r.address) return r;
    }
  } catch {
    return null;  // not ours, or damaged: the error goes to the page as it is
  }
  return null;
}

export class Router {
  // credentials: for every replica (TLS roots), or undefined for plaintext.
  constructor(service, firstAddress, credentials = undefined) {
    this.service = service;
    this.first = firstAddress;
    this.credentials = credentials;
    this.clients = new Map();  // address -> grpc client
    this.owners = new Map();   // session id -> address
  }

  client(address = this.first) {
    let c = this.clients.get(address);
    if (!c) {
      c = makeClient(this.service, address, this.credentials);
      this.clients.set(address, c);
    }
    return c;
  }

  // The client for calls on session `id` (the first address if unknown).
  forSession(id) {
    return this.client((id && this.owners.get(id)) || this.first);
  }

  // A Session reply: remember where it lives.
  learn(session) {
    if (session && session.id && session.address) this.owners.set(session.id, session.address);
  }

  // A redirect: remember the owner and return true (call again).
  follow(err) {
    const r = parseRedirect(err);
    if (!r) return false;
    this.owners.set(r.session_id, r.address);
    return true;
  }

  forget(id) {
    this.owners.delete(id);
  }
}
