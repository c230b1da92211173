// The bridge → page protocol (web/protocol.hpp, web/README.md "Protocol"): binary messages with a
// little-endian header (kind 1 mesh geometry, kind 2 deformation frame) and JSON text messages.
// Deformation frames are the server's codec: FULL float32 frames, and QUANTIZED_DELTA frames
// (int16 per component times a scale) added to the last FULL frame.

export const KIND_MESH_GEOMETRY = 1;
export const KIND_DEFORMATION_FRAME = 2;
export const ENCODING_FULL = 0;
export const ENCODING_DELTA = 1;
const GEOMETRY_HEADER_BYTES = 16;
const FRAME_HEADER_BYTES = 48;

// The kind of a binary message (its first byte).
export function kindOf(buffer) {
  return buffer.byteLength > 0 ? new DataView(buffer).getUint8(0) : 0;
}

// Kind 1: { meshIndex, generation, rest (Float32Array, 3 per vertex, m), triangles (Uint32Array) }.
export function parseGeometry(buffer) {
  const dv = new DataView(buffer);
  const meshIndex = dv.getUint16(2, true);
  const vertices = dv.getUint32(4, true);
  const triangles = dv.getUint32(8, true);
  const generation = dv.getUint32(12, true);
  const expected = GEOMETRY_HEADER_BYTES + 12 * vertices + 12 * triangles;
  if (buffer.byteLength !== expected) {
    throw new Error(`mesh geometry message of ${buffer.byteLength} bytes, ${expected} expected`);
  }
  return {
    meshIndex,
    generation,
    rest: new Float32Array(buffer, GEOMETRY_HEADER_BYTES, 3 * vertices),
    triangles: new Uint32Array(buffer, GEOMETRY_HEADER_BYTES + 12 * vertices, 3 * triangles),
  };
}

// Kind 2: the header fields and a typed view of the payload.
export function parseFrame(buffer) {
  const dv = new DataView(buffer);
  const h = {
    encoding: dv.getUint8(1),
    meshIndex: dv.getUint16(2, true),
    vertices: dv.getUint32(4, true),
    generation: dv.getUint32(8, true),
    frame: Number(dv.getBigUint64(16, true)),
    baseFrame: Number(dv.getBigUint64(24, true)),
    serverTimeNs: dv.getBigInt64(32, true),
    deltaScale: dv.getFloat32(40, true),
    maxDisplacement: dv.getFloat32(44, true),
  };
  const n = 3 * h.vertices;
  const per = h.encoding === ENCODING_FULL ? 4 : 2;
  if (h.encoding > ENCODING_DELTA || buffer.byteLength !== FRAME_HEADER_BYTES + per * n) {
    throw new Error(`deformation frame of ${buffer.byteLength} bytes does not match its header`);
  }
  h.payload = h.encoding === ENCODING_FULL
    ? new Float32Array(buffer, FRAME_HEADER_BYTES, n)
    : new Int16Array(buffer, FRAME_HEADER_BYTES, n);
  return h;
}

// One mesh's displacements: keeps the last FULL frame to add deltas to.
export class DeformationDecoder {
  constructor(vertices) {
    this.base = new Float32Array(3 * vertices);
    this.u = new Float32Array(3 * vertices);
    this.baseFrame = -1;
    this.frame = -1;
  }

  // Decodes a parsed frame into this.u (unit m). False when it cannot be decoded yet (a delta
  // whose FULL frame did not arrive: the bridge sends it first, so this means a protocol slip).
  decode(h) {
    if (h.payload.length !== this.u.length) return false;
    if (h.encoding === ENCODING_FULL) {
      this.base.set(h.payload);
      this.u.set(h.payload);
      this.baseFrame = h.frame;
    } else {
      if (h.baseFrame !== this.baseFrame) return false;
      const q = h.payload, base = this.base, u = this.u, s = h.deltaScale;
      for (let i = 0; i < u.length; ++i) u[i] = base[i] + s * q[i];
    }
    this.frame = h.frame;
    return true;
  }
}
