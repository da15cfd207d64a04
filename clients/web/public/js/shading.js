// Shading without dark bands: normals creased at sharp edges (a vertex on a
// crease gets one normal per side instead of their average, which shaded
// both sides dark) and a matcap (a lit sphere painted once: a hemisphere
// light plus a key light, never darker than a floor, the same in software
// WebGL as on a GPU, and cheaper than lights).

// Faces meeting at more than this angle keep their own normals.
export const CREASE_DEGREES = 40;

// The quads around each vertex (CSR): {offsets, quads}.
export function vertexQuads(quads, vertexCount) {
  const offsets = new Int32Array(vertexCount + 1);
  for (let i = 0; i < quads.length; ++i) offsets[quads[i] + 1]++;
  for (let v = 0; v < vertexCount; ++v) offsets[v + 1] += offsets[v];
  const fill = offsets.slice(0, vertexCount);
  const list = new Int32Array(quads.length);
  for (let i = 0; i < quads.length; ++i) list[fill[quads[i]]++] = i >> 2;
  return { offsets, quads: list };
}

// Area-weighted quad normals (the diagonals' cross product) into `out`
// (3 per quad), and their unit versions into `unit`.
export function quadNormals(positions, quads, out, unit) {
  for (let q = 0; 4 * q < quads.length; ++q) {
    const a = 3 * quads[4 * q];
    const b = 3 * quads[4 * q + 1];
    const c = 3 * quads[4 * q + 2];
    const d = 3 * quads[4 * q + 3];
    const ux = positions[c] - positions[a];
    const uy = positions[c + 1] - positions[a + 1];
    const uz = positions[c + 2] - positions[a + 2];
    const vx = positions[d] - positions[b];
    const vy = positions[d + 1] - positions[b + 1];
    const vz = positions[d + 2] - positions[b + 2];
    const nx = uy * vz - uz * vy;
    const ny = uz * vx - ux * vz;
    const nz = ux * vy - uy * vx;
    out[3 * q] = nx; out[3 * q + 1] = ny; out[3 * q + 2] = nz;
    const len = Math.hypot(nx, ny, nz) || 1;
    unit[3 * q] = nx / len; unit[3 * q + 1] = ny / len; unit[3 * q + 2] = nz / len;
  }
}

// One normal per quad corner (4 per quad, in quad order, 3 floats each):
// the sum of the area-weighted normals of the quads around the corner's
// vertex that are within the crease angle of the corner's own quad.
// `adjacency` from vertexQuads; `scratch` {area, unit} Float32Arrays of
// 3 per quad (reused between frames).
export function creasedNormals(positions, quads, adjacency, out, scratch, creaseDegrees = CREASE_DEGREES) {
  const { area, unit } = scratch;
  quadNormals(positions, quads, area, unit);
  const cosCrease = Math.cos((creaseDegrees * Math.PI) / 180);
  const { offsets, quads: around } = adjacency;
  for (let k = 0; k < quads.length; ++k) {
    const q = k >> 2;
    const v = quads[k];
    let x = 0;
    let y = 0;
    let z = 0;
    for (let i = offsets[v]; i < offsets[v + 1]; ++i) {
      const j = around[i];
      const cos = unit[3 * q] * unit[3 * j] + unit[3 * q + 1] * unit[3 * j + 1] + unit[3 * q + 2] * unit[3 * j + 2];
      if (j !== q && cos < cosCrease) continue;
      x += area[3 * j]; y += area[3 * j + 1]; z += area[3 * j + 2];
    }
    const len = Math.hypot(x, y, z) || 1;
    out[3 * k] = x / len; out[3 * k + 1] = y / len; out[3 * k + 2] = z / len;
  }
}

// The matcap's brightness for a view-space normal (nx, ny up, nz toward
// the viewer): sky above, a lighter ground below, a key light from the
// upper left front and a soft highlight. In [0.42, 1].
export function matcapShade(nx, ny, nz) {
  const hemi = 0.55 + 0.17 * ny;               // 0.38 (down) .. 0.72 (up)
  const kx = -0.45;
  const ky = 0.6;
  const kz = 0.66;
  const key = Math.max(0, nx * kx + ny * ky + nz * kz);
  const spec = key ** 24 * 0.12;
  return Math.min(1, Math.max(0.42, hemi + 0.32 * key + spec));
}

// A matcap as an RGBA byte array (size x size), greyish white: the
// material's colour (or a field's vertex colours) multiplies it.
export function matcapPixels(size = 128) {
  const px = new Uint8Array(size * size * 4);
  for (let j = 0; j < size; ++j) {
    for (let i = 0; i < size; ++i) {
      const nx = ((i + 0.5) / size) * 2 - 1;
      const ny = ((j + 0.5) / size) * 2 - 1;  // row 0 at the bottom (a DataTexture)
      const r2 = Math.min(nx * nx + ny * ny, 1);
      const s = matcapShade(nx, ny, Math.sqrt(1 - r2));
      const o = 4 * (j * size + i);
      px[o] = Math.round(255 * s);
      px[o + 1] = Math.round(255 * s);
      px[o + 2] = Math.round(255 * Math.min(1, s * 1.02));
      px[o + 3] = 255;
    }
  }
  return px;
}
