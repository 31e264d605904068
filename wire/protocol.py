"""The facecast wire protocol: message kinds, binary frame layout, payload codecs, close codes.

Pure functions over bytes and numpy arrays, no I/O: the server encodes with them and the Python
client (``clients/client.py``) decodes with them. ``docs/protocol.md`` is the normative text; this
module is its reference implementation.

Binary message = 32-byte little-endian header + payload::

    offset size  field
    0      u8    version (1)
    1      u8    kind       (KIND_* below)
    2      u8    encoding   (ENC_* below)
    3      u8    reserved (0)
    4      u32   index      (frame index k; for audio the block's sequence number)
    8      u32   count      (number of values in the payload)
    12     f32   scale      (ENC_INT16: value = int16 * scale; otherwise 1.0)
    16     f64   media_time (s of session audio: frame k at k / fps; audio: time of its first sample)
    24     f64   send_time  (server wall clock, s since the Unix epoch, when the message was queued)
    32     ...   payload    (count values: float32, int16 or float16, little-endian)
"""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

PROTOCOL_VERSION = 1
HEADER = struct.Struct("<BBBxIIfdd")
HEADER_BYTES = HEADER.size  # 32

# Message kinds (header byte 1).
KIND_PARAMS = 1
KIND_DELTAS = 2
KIND_ARKIT52 = 3
KIND_OVR15 = 4
KIND_AUDIO = 5
KIND_MORPH = 6  # the served head's own morph-target weights (order: the description's head.morph.names)
KIND_NAMES = {
    KIND_PARAMS: "params",
    KIND_DELTAS: "deltas",
    KIND_ARKIT52: "arkit52",
    KIND_OVR15: "ovr15",
    KIND_AUDIO: "audio",
    KIND_MORPH: "morph",
}

# Value encodings (header byte 2).
ENC_FLOAT32 = 1
ENC_INT16 = 2
ENC_FLOAT16 = 3
_ENC_DTYPES: dict[int, np.dtype[Any]] = {
    ENC_FLOAT32: np.dtype("<f4"),
    ENC_INT16: np.dtype("<i2"),
    ENC_FLOAT16: np.dtype("<f2"),
}
ENCODING_NAMES = {ENC_FLOAT32: "float32", ENC_INT16: "int16", ENC_FLOAT16: "float16"}

# Viewer subscriptions: kind -> {encoding name: (header kind, header encoding)}; first = default.
VIEW_KINDS: dict[str, dict[str, tuple[int, int]]] = {
    "params": {"float32": (KIND_PARAMS, ENC_FLOAT32)},
    "deltas": {"int16": (KIND_DELTAS, ENC_INT16), "float16": (KIND_DELTAS, ENC_FLOAT16)},
    "blendshapes": {"arkit52": (KIND_ARKIT52, ENC_FLOAT32), "ovr15": (KIND_OVR15, ENC_FLOAT32)},
    # A head driven by its own morph targets: one weight per driven target (three.js morphTargetInfluences).
    "morph": {"float32": (KIND_MORPH, ENC_FLOAT32), "float16": (KIND_MORPH, ENC_FLOAT16)},
}

# Ingest sample formats: name -> (numpy dtype, bytes per sample).
SAMPLE_FORMATS: dict[str, np.dtype] = {"pcm_s16le": np.dtype("<i2"), "f32le": np.dtype("<f4")}

SESSION_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
SESSION_NAME_RULE = "session must be 1-64 characters of A-Z a-z 0-9 _ . -"
"""The one wording of :data:`SESSION_NAME` in a refusal (start messages, view queries, admission)."""

# WebSocket close codes used by the server (RFC 6455 section 7.4 plus application codes 4000-4999).
CLOSE_NORMAL = 1000  # the session ended normally
CLOSE_GOING_AWAY = 1001  # server shutting down
CLOSE_UNSUPPORTED_DATA = 1003  # text where binary was expected, or the reverse
CLOSE_INVALID_PAYLOAD = 1007  # malformed JSON, audio bytes that are not whole samples, NaN/inf samples
CLOSE_POLICY = 1008  # a message out of order (audio before start, a second start, a viewer talking)
CLOSE_TOO_BIG = 1009  # a message over the server's max_message_bytes (sent by the websockets library)
CLOSE_INTERNAL = 1011  # a server bug: only this connection is closed
CLOSE_TRY_LATER = 1013  # too many sessions or viewers
CLOSE_TOO_SLOW = 4000  # a viewer stayed behind longer than the server allows
CLOSE_UNAUTHORIZED = 4001  # missing or wrong token
CLOSE_NOT_FOUND = 4004  # unknown session or endpoint
CLOSE_CONFLICT = 4009  # the session name is in use
CLOSE_TOO_FAST = 4029  # an ingest ran ahead of real time beyond its burst (servers set to close, not pace)
CLOSE_BAD_REQUEST = 4400  # a start message or viewer query with missing or invalid fields


@dataclass(frozen=True)
class Message:
    """A decoded binary message. values: (count,) float32 (dequantised) or, for audio, float32 samples
    in [-1, 1]; the rest mirrors the header (times in seconds)."""

    kind: int
    encoding: int
    index: int
    media_time: float
    send_time: float
    scale: float
    values: np.ndarray

    @property
    def kind_name(self) -> str:
        return KIND_NAMES.get(self.kind, f"kind{self.kind}")


def encode_payload(values: np.ndarray, encoding: int) -> tuple[bytes, float]:
    """values (count,) float -> (payload bytes, scale). int16 uses a per-message scale max|v| / 32767."""
    v = np.asarray(values, dtype=np.float32).reshape(-1)
    if encoding == ENC_INT16:
        peak = float(np.max(np.abs(v))) if v.size else 0.0
        scale = peak / 32767.0 if peak > 0 else 1.0
        q = np.rint(v / np.float32(scale)).astype("<i2")
        return q.tobytes(), scale
    if encoding in _ENC_DTYPES:
        return v.astype(_ENC_DTYPES[encoding]).tobytes(), 1.0
    raise ValueError(f"unknown encoding {encoding}")


def encode_audio_payload(samples: np.ndarray) -> bytes:
    """samples (n,) float in [-1, 1] -> int16 bytes (scale 1/32768), clipped."""
    s = np.clip(np.asarray(samples, dtype=np.float64) * 32768.0, -32768, 32767)
    return np.rint(s).astype("<i2").tobytes()


def pack_header(
    kind: int, encoding: int, index: int, count: int, scale: float, media_time: float, send_time: float
) -> bytes:
    """The 32-byte header (see the module docstring)."""
    return HEADER.pack(PROTOCOL_VERSION, kind, encoding, index & 0xFFFFFFFF, count, scale, media_time, send_time)


def decode_message(data: bytes) -> Message:
    """Parse one binary message; raises ValueError naming the problem."""
    if len(data) < HEADER_BYTES:
        raise ValueError(f"message of {len(data)} bytes is shorter than the {HEADER_BYTES}-byte header")
    version, kind, encoding, index, count, scale, media_time, send_time = HEADER.unpack_from(data)
    if version != PROTOCOL_VERSION:
        raise ValueError(f"protocol version {version}, expected {PROTOCOL_VERSION}")
    dtype = _ENC_DTYPES.get(encoding)
    if dtype is None:
        raise ValueError(f"unknown encoding {encoding}")
    if len(data) != HEADER_BYTES + count * dtype.itemsize:
        raise ValueError(f"payload of {len(data) - HEADER_BYTES} bytes for {count} {ENCODING_NAMES[encoding]} values")
    raw = np.frombuffer(data, dtype=dtype, count=count, offset=HEADER_BYTES)
    values = raw.astype(np.float32) * np.float32(scale) if encoding == ENC_INT16 else raw.astype(np.float32)
    return Message(kind, encoding, index, media_time, send_time, scale, values)


def dumps(obj: dict[str, Any]) -> str:
    """JSON text of a control/description message (compact, no NaN)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False)
