// The gateway's gRPC side: the dynsolid.Sessions client built from the
// project's .proto files at start-up (no generated code), the unary calls a
// page may make, and Watch with the frames left as the server's bytes.

import path from 'node:path';
import { fileURLToPath } from 'node:url';
import grpc from '@grpc/grpc-js';
import protoLoader from '@grpc/proto-loader';
import { Reader } from '../public/js/wire.js';

const here = path.dirname(fileURLToPath(import.meta.url));
export const DEFAULT_PROTO_ROOT = path.resolve(here, '../../../proto');

// Unary calls a page may make, as service.proto names them.
export const UNARY_METHODS = new Set([
  'CreateSession', 'GetSession', 'ListSessions', 'CloseSession', 'GetStats', 'Inspect', 'Pick', 'Section', 'ListScenes',
]);

export function loadService(protoRoot = DEFAULT_PROTO_ROOT) {
  const definition = protoLoader.loadSync('dynsolid/service.proto', {
    includeDirs: [protoRoot],
    keepCase: true,      // field names exactly as in the .proto (the page uses them)
    longs: Number,       // steps, ids and counts stay far below 2^53
    enums: String,
    defaults: true,      // every scalar present (0, "", false), as the page expects
    oneofs: true,        // replies name their set oneof member ("result": "load_id")
    bytes: Array,
  });
  const pkg = grpc.loadPackageDefinition(definition);
  return { definition, Sessions: pkg.dynsolid.Sessions };
}

// `credentials`: TLS (grpc.credentials.createSsl) or, when absent, plaintext.
export function makeClient(service, address, credentials = undefined) {
  const options = {
    'grpc.max_receive_message_length': 64 << 20,
    'grpc.max_send_message_length': 16 << 20,
    // Reconnect quickly after the server comes back.
    'grpc.initial_reconnect_backoff_ms': 200,
    'grpc.max_reconnect_backoff_ms': 1000,
  };
  return new service.Sessions(address, credentials || grpc.credentials.createInsecure(), options);
}

// Watch with the Frame bytes passed through untouched: the page decodes
// them (clients/web/public/js/surface.js).
export function watchRaw(service, client, request) {
  const method = service.definition['dynsolid.Sessions'].Watch;
  return client.makeServerStreamRequest(method.path, method.requestSerialize,
                                        (bytes) => bytes, request, new grpc.Metadata(), {});
}

// Export with each ExportChunk decoded here (exportChunk): its data stays a
// view of the server's bytes, not a JavaScript array of numbers as the
// loader's own decoding (bytes: Array) would make it.
export function exportRaw(service, client, request, options = {}) {
  const method = service.definition['dynsolid.Sessions'].Export;
  return client.makeServerStreamRequest(method.path, method.requestSerialize,
                                        exportChunk, request, new grpc.Metadata(), options);
}

const utf8 = new TextDecoder();

// A serialized dynsolid.ExportChunk as {data (Buffer), offset, total_bytes,
// file_name, media_type, step, level, cells, surface_faces}.
export function exportChunk(bytes) {
  const b = new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const r = new Reader(b);
  const c = { data: Buffer.alloc(0), offset: 0, total_bytes: 0, file_name: '', media_type: '',
    step: 0, level: 0, cells: 0, surface_faces: 0 };
  const numbers = { 2: 'offset', 3: 'total_bytes', 6: 'step', 7: 'level', 8: 'cells', 9: 'surface_faces' };
  while (!r.done()) {
    const { field, wire } = r.tag();
    if (field === 1 && wire === 2) {
      const d = r.bytesField();
      c.data = Buffer.from(d.buffer, d.byteOffset, d.byteLength);
    } else if ((field === 4 || field === 5) && wire === 2) {
      c[field === 4 ? 'file_name' : 'media_type'] = utf8.decode(r.bytesField());
    } else if (numbers[field] && wire === 0) {
      c[numbers[field]] = r.varint();
    } else {
      r.skip(wire);
    }
  }
  return c;
}

export function statusName(code) {
  for (const [name, value] of Object.entries(grpc.status)) if (value === code) return name;
  return String(code);
}

export { grpc };
