// The facecast wire protocol in the browser: the 32-byte little-endian header and payload codecs.
// Normative text: docs/protocol.md; reference implementation: wire/protocol.py (keep in step).
//
//   offset size field
//   0      u8   version (1)        1  u8  kind      2  u8  encoding    3  u8 reserved
//   4      u32  index (frame k)    8  u32 count     12 f32 scale (int16: value = int16 * scale)
//   16     f64  media_time (s of session audio)     24 f64 send_time (server clock, s since epoch)
//   32     ...  payload: count values (float32, int16 or float16)

export const PROTOCOL_VERSION = 1;
export const HEADER_BYTES = 32;
export const KIND = { PARAMS: 1, DELTAS: 2, ARKIT52: 3, OVR15: 4, AUDIO: 5, MORPH: 6 };
export const ENC = { FLOAT32: 1, INT16: 2, FLOAT16: 3 };

// Close codes the viewer reacts to (server/protocol.py).
export const CLOSE = { NORMAL: 1000, GOING_AWAY: 1001, TOO_SLOW: 4000, UNAUTHORIZED: 4001, NOT_FOUND: 4004,
  CONFLICT: 4009, TOO_FAST: 4029, BAD_REQUEST: 4400 };

function halfToFloat(h) {
  // IEEE 754 binary16 -> number (no Float16Array needed).
  const s = h & 0x8000 ? -1 : 1;
  const e = (h >> 10) & 0x1f;
  const f = h & 0x3ff;
  if (e === 0) return s * f * 2 ** -24;
  if (e === 31) return f ? NaN : s * Infinity;
  return s * (1 + f / 1024) * 2 ** (e - 15);
}

/**
 * Decode one binary message (ArrayBuffer) into
 * {kind, encoding, index, count, scale, mediaTime (s), sendTime (s), values: Float32Array(count)}.
 * int16 payloads are dequantised (value * scale); audio samples come out in [-1, 1].
 * Throws Error naming the problem for a short, foreign or inconsistent message.
 */
export function decodeMessage(buf) {
  if (buf.byteLength < HEADER_BYTES) throw new Error(`message of ${buf.byteLength} bytes is shorter than the header`);
  const dv = new DataView(buf);
  const version = dv.getUint8(0);
  if (version !== PROTOCOL_VERSION) throw new Error(`protocol version ${version}, expected ${PROTOCOL_VERSION}`);
  const kind = dv.getUint8(1);
  const encoding = dv.getUint8(2);
  const index = dv.getUint32(4, true);
  const count = dv.getUint32(8, true);
  const scale = dv.getFloat32(12, true);
  const mediaTime = dv.getFloat64(16, true);
  const sendTime = dv.getFloat64(24, true);
  const width = { [ENC.FLOAT32]: 4, [ENC.INT16]: 2, [ENC.FLOAT16]: 2 }[encoding];
  if (!width) throw new Error(`unknown encoding ${encoding}`);
  if (buf.byteLength !== HEADER_BYTES + count * width) throw new Error(`payload size does not match ${count} values`);
  const values = new Float32Array(count);
  if (encoding === ENC.FLOAT32) {
    values.set(new Float32Array(buf, HEADER_BYTES, count));
  } else if (encoding === ENC.INT16) {
    const q = new Int16Array(buf, HEADER_BYTES, count);
    for (let i = 0; i < count; i++) values[i] = q[i] * scale;
  } else {
    const q = new Uint16Array(buf, HEADER_BYTES, count);
    for (let i = 0; i < count; i++) values[i] = halfToFloat(q[i]);
  }
  return { kind, encoding, index, count, scale, mediaTime, sendTime, values };
}
