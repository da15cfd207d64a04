// What the gateway lets in (clients/web/README.md "Doors"): which
// WebSocket upgrades it takes (Origin, loopback, access token), where it
// may listen (beyond loopback only with TLS or a token), request paths it
// can read, and a per-connection rate limit. Plain functions, no
// I/O: main.js and bridge.js call them, test/unit/guard.test.js tests them.

import net from 'node:net';
import crypto from 'node:crypto';

// True for an address on this machine's loopback (127.0.0.0/8, ::1, and
// IPv4 loopback seen through an IPv6 socket).
export function isLoopback(address) {
  if (!address) return false;
  const a = address.startsWith('::ffff:') ? address.slice(7) : address;
  return a === '::1' || (net.isIPv4(a) && a.startsWith('127.'));
}

// "scheme://host[:port]" as a browser writes it in Origin (default port
// dropped, host lower case), or null when `text` is not one.
export function normalOrigin(text) {
  try {
    const u = new URL(text);
    if (u.protocol !== 'http:' && u.protocol !== 'https:') return null;
    return u.origin;
  } catch {
    return null;
  }
}

// --allow_origin's value: comma-separated origins. Throws on one that is
// not an origin, so a typo is not silently ignored.
export function parseOriginList(text) {
  const out = new Set();
  for (const item of (text || '').split(',').map((s) => s.trim()).filter(Boolean)) {
    const o = normalOrigin(item);
    if (!o) throw new Error(`--allow_origin: "${item}" is not an origin (http://HOST[:PORT] or https://...)`);
    out.add(o);
  }
  return out;
}

// The Host header as "host[:port]" (lower case, the default port of
// `scheme` dropped), or null.
function normalHost(host, scheme) {
  if (!host) return null;
  try {
    return new URL(`${scheme}//${host}`).host;
  } catch {
    return null;
  }
}

// The scheme of the gateway's own pages as this request reached it:
// "https:" on a TLS socket (--tls_cert: HTTPS and WSS), "http:" otherwise.
function ownScheme(req) {
  return req.socket && req.socket.encrypted ? 'https:' : 'http:';
}

// A host name no DNS answer can point elsewhere: an IP address or localhost.
function fixedHostName(hostPort) {
  const name = new URL(`http://${hostPort}`).hostname.replace(/^\[|\]$/g, '');
  return net.isIP(name) !== 0 || name === 'localhost';
}

// Why a WebSocket upgrade is refused, or null to take it.
//  - Origin in `allowOrigins` (--allow_origin): taken.
//  - Same origin: Origin's scheme is the gateway's own (https on a TLS
//    socket, http otherwise), its host:port is the Host header, and that
//    host is an IP address or localhost. A name (evil.example) could be a
//    DNS rebinding of this machine, so names are taken only through
//    --allow_origin. (Origin is never ws: or wss:; a page's WebSocket
//    carries the page's own http(s) origin.)
//  - No Origin (not a browser: scripts, curl, the tests): from loopback only.
//  - `accessToken` set (--access_token): the upgrade's URL must carry
//    ?access=TOKEN as well, whatever the origin.
export function upgradeRefusal(req, { allowOrigins = new Set(), accessToken = '' } = {}) {
  const origin = req.headers.origin;
  const from = req.socket && req.socket.remoteAddress;
  if (origin === undefined) {
    if (!isLoopback(from)) return `a WebSocket without an Origin header is taken from loopback only (this one came from ${from})`;
  } else if (!allowOrigins.has(normalOrigin(origin))) {
    const scheme = ownScheme(req);
    const host = normalHost(req.headers.host, scheme);
    const o = normalOrigin(origin);
    const same = o !== null && host !== null && new URL(o).protocol === scheme && new URL(o).host === host;
    if (!same) return `Origin ${origin} is not this gateway's (${scheme}//${req.headers.host}); --allow_origin lists others`;
    if (!fixedHostName(host)) return `Origin ${origin} is a host name, not an IP address or localhost; --allow_origin ${o} takes it`;
  }
  if (accessToken && !sameSecret(accessParam(req.url), accessToken)) {
    return 'this gateway needs its access token: open the URL it printed (?access=...)';
  }
  return null;
}

function accessParam(url) {
  try {
    return new URL(url, 'http://x').searchParams.get('access') || '';
  } catch {
    return '';
  }
}

function sameSecret(a, b) {
  const x = crypto.createHash('sha256').update(a).digest();
  const y = crypto.createHash('sha256').update(b).digest();
  return crypto.timingSafeEqual(x, y);
}

// Why the gateway must not serve on `address` (the address it listens on),
// or null. Beyond loopback it needs TLS (`tls`) or an access token
// (`accessToken`): with neither, a page on another machine would get
// unauthenticated plain-text control of every session it can reach.
// An empty address is every interface.
export function exposureRefusal(address, { tls = false, accessToken = '' } = {}) {
  if (isLoopback(address) || tls || accessToken) return null;
  const where = address === '' || address === '::' || address === '0.0.0.0' ? 'every interface' : address;
  return `refusing to listen on ${where} beyond loopback with neither TLS nor an access token: ` +
    'a page from another machine would get unauthenticated plain-text control of the sessions. ' +
    'Give --access_token_file FILE (and --tls_cert FILE --tls_key FILE), or listen on 127.0.0.1';
}

// What to tell the operator about serving on `address` that is allowed but
// weak, or null: beyond loopback without a token (anyone who reaches it can
// use it) or without TLS (the token and the sessions travel in plain text).
export function exposureWarning(address, { tls = false, accessToken = '' } = {}) {
  if (isLoopback(address)) return null;
  if (!accessToken) return 'serving beyond loopback without --access_token_file: anyone who reaches this port can use it';
  if (!tls) return 'serving beyond loopback without --tls_cert/--tls_key: the access token and the sessions travel in plain text';
  return null;
}

// The decoded path of a request URL, or null when it cannot be decoded
// (bad percent-escapes such as /%E0%A4%A, a NUL byte).
export function requestPath(url) {
  try {
    const p = decodeURIComponent(new URL(url, 'http://x').pathname);
    return p.includes('\0') ? null : p;
  } catch {
    return null;
  }
}

// A token bucket: `burst` messages at once, refilled at `rate` per second.
// `now()` in milliseconds (a fake clock in tests).
export class TokenBucket {
  constructor({ rate, burst, now = () => performance.now() }) {
    this.rate = rate;
    this.burst = burst;
    this.now = now;
    this.tokens = burst;
    this.last = now();
  }

  // Takes one token: false when there is none (the message is refused).
  take() {
    const t = this.now();
    this.tokens = Math.min(this.burst, this.tokens + ((t - this.last) / 1000) * this.rate);
    this.last = t;
    if (this.tokens < 1) return false;
    this.tokens -= 1;
    return true;
  }
}
