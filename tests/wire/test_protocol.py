"""The wire format in Python: every encoding round-trips within its quantisation, and damaged
messages are refused with a reason (the JS twin is checked against this in tests/clients/web)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wire import protocol as P

values = arrays(np.float32, st.integers(0, 300), elements=st.floats(-4, 4, width=32))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    v=values,
    encoding=st.sampled_from([P.ENC_FLOAT32, P.ENC_INT16, P.ENC_FLOAT16]),
    index=st.integers(0, 2**32 - 1),
    media=st.floats(0, 1e6),
    sent=st.floats(0, 2e9),
)
def test_payloads_round_trip_within_their_quantisation(v, encoding, index, media, sent):
    payload, scale = P.encode_payload(v, encoding)
    msg = P.decode_message(P.pack_header(P.KIND_DELTAS, encoding, index, len(v), scale, media, sent) + payload)
    assert (msg.kind, msg.encoding, msg.index, msg.media_time, msg.send_time) == (
        P.KIND_DELTAS,
        encoding,
        index,
        media,
        sent,
    )
    assert msg.values.dtype == np.float32 and msg.values.shape == v.shape
    peak = float(np.abs(v).max()) if v.size else 0.0
    # float32 exact; int16 within half a step of peak/32767; float16 within its 11-bit mantissa.
    tol = {P.ENC_FLOAT32: 0.0, P.ENC_INT16: 0.5 * peak / 32767 * 1.0001 + 1e-12, P.ENC_FLOAT16: 1e-3 * peak + 1e-7}
    assert np.abs(msg.values - v).max(initial=0.0) <= tol[encoding]


def test_audio_payload_is_int16_at_1_over_32768_and_clipped():
    x = np.array([0.0, 0.5, -1.0, 1.5, -2.0])
    msg = P.decode_message(
        P.pack_header(P.KIND_AUDIO, P.ENC_INT16, 0, len(x), 1 / 32768, 0.0, 0.0) + P.encode_audio_payload(x)
    )
    np.testing.assert_array_equal(msg.values, np.array([0.0, 0.5, -1.0, 32767 / 32768, -1.0], np.float32))


@pytest.mark.parametrize(
    "data,reason",
    [
        (b"\x01" * 10, "shorter than the 32-byte header"),
        (P.pack_header(P.KIND_PARAMS, P.ENC_FLOAT32, 0, 4, 1.0, 0.0, 0.0) + b"\x00" * 15, "payload of 15 bytes"),
        (bytes([9]) + P.pack_header(P.KIND_PARAMS, P.ENC_FLOAT32, 0, 0, 1.0, 0.0, 0.0)[1:], "protocol version 9"),
        (P.pack_header(P.KIND_PARAMS, 77, 0, 0, 1.0, 0.0, 0.0), "unknown encoding 77"),
    ],
)
def test_damaged_messages_are_refused_with_a_reason(data, reason):
    with pytest.raises(ValueError, match=reason):
        P.decode_message(data)
