// What the gateway lets in (clients/web/README.md "Doors"): which
// WebSocket upgrades it takes (Origin, loopback, access token), request
// paths it can read, and a per-connection rate limit. Plain functions, no
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

// The Host header as "host[:port]" (lower case, default port dropped), or null.
function normalHost(host) {
  if (!host) return null;
  try {
    return new URL(`http://${host}`).host;
  } catch {
    return null;
  }
}

// A host name no DNS answer can point elsewhere: an IP address or localhost.
function fixedHostName(hostPort) {
  const name = new URL(`http://${hostPort}`).hostname.replace(/^\[|\]$/g, '');
  return net.isIP(name) !== 0 || name === 'localhost';
}

// Why a WebSocket upgrade is refused, or null to take it.
//  - Origin in `allowOrigins` (--allow_origin): taken.
//  - Same origin: Origin's host:port is the Host header, and that host is
//    an IP address or localhost. A name (evil.example) could be a DNS
//    rebinding of this machine, so names are taken only through
//    --allow_origin.
//  - No Origin (not a browser: scripts, curl, the tests): from loopback only.
//  - `accessToken` set (--access_token): the upgrade's URL must carry
//    ?access=TOKEN as well, whatever the origin.
export function upgradeRefusal(req, { allowOrigins = new Set(), accessToken = '' } = {}) {
  const origin = req.headers.origin;
  const from = req.socket && req.socket.remoteAddress;
  if (origin === undefined) {
    if (!isLoopback(from)) return `a WebSocket without an Origin header is taken from loopback only (this one came from ${from})`;
  } else if (!allowOrigins.has(normalOrigin(origin))) {
    const host = normalHost(req.headers.host);
    const o = normalOrigin(origin);
    const same = o !== null && host !== null && new URL(o).host === host;
    if (!same) return `Origin ${origin} is not this gateway's (${req.headers.host}); --allow_origin lists others`;
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
