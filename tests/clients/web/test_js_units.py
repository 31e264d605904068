"""The viewer's JavaScript modules under Node: the browser decodes exactly what wire/protocol.py
encodes (every kind, the head's own morph weights included; both twins number the kinds alike), the
playout clock resyncs on a late frame and catches up when frames come early again (never earlier than its
first frame put it), and the play-out drops only frames whose time passed by a frame (fake clock)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.prerequisites import missing
from wire import protocol as P

# Node.js runs the viewer modules.
pytestmark = pytest.mark.system


def test_js_decoder_matches_the_python_protocol_and_playout_clock_adapts(tmp_path):
    if shutil.which("node") is None:
        missing("node is not installed")
    rng = np.random.default_rng(0)
    deltas = rng.standard_normal(300).astype(np.float32) * 0.05
    cases = {
        "deltas_int16": (P.KIND_DELTAS, P.ENC_INT16, deltas),
        "deltas_float16": (P.KIND_DELTAS, P.ENC_FLOAT16, deltas),
        "params": (P.KIND_PARAMS, P.ENC_FLOAT32, np.array([0.01, -0.02, 0.3, 0.0], np.float32)),
        "morph_float32": (P.KIND_MORPH, P.ENC_FLOAT32, rng.uniform(0, 1, 52).astype(np.float32)),
        "morph_float16": (P.KIND_MORPH, P.ENC_FLOAT16, rng.uniform(0, 1, 52).astype(np.float32)),
    }
    expect = {}
    for name, (kind, enc, values) in cases.items():
        payload, scale = P.encode_payload(values, enc)
        msg = P.pack_header(kind, enc, 7, len(values), scale, 7 / 30, 1.7e9) + payload
        (tmp_path / f"{name}.bin").write_bytes(msg)
        expect[name] = P.decode_message(msg)
    audio = (np.sin(np.arange(320) / 5) * 0.5).astype(np.float32)
    msg = P.pack_header(P.KIND_AUDIO, P.ENC_INT16, 3, 320, 1 / 32768, 0.06, 1.7e9) + P.encode_audio_payload(audio)
    (tmp_path / "audio.bin").write_bytes(msg)
    expect["audio"] = P.decode_message(msg)

    out = subprocess.run(
        ["node", str(Path(__file__).with_name("units.mjs")), str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    for name, m in expect.items():
        got = r["decoded"][name]
        assert (got["kind"], got["encoding"], got["index"], got["count"]) == (
            m.kind,
            m.encoding,
            m.index,
            len(m.values),
        )
        assert got["mediaTime"] == m.media_time and got["sendTime"] == m.send_time
        np.testing.assert_array_equal(np.float32(got["values"]), m.values, err_msg=name)
    assert "shorter than the header" in r["rejected"]
    # The twins name the same kinds and encodings with the same numbers.
    assert {k.lower(): v for k, v in r["kinds"].items()} == {n: k for k, n in P.KIND_NAMES.items()}
    assert {k.lower(): v for k, v in r["encodings"].items()} == {n: e for e, n in P.ENCODING_NAMES.items()}

    slack = np.array(r["slack"])
    assert np.allclose(slack[:60], 0.08)  # steady: every frame waits the 80 ms jitter buffer
    assert r["resyncs"] == 1 and r["afterLate"] > r["beforeLate"] + 0.15  # the late frame moved the timeline
    assert slack[60] >= 0  # ... so that it is shown, not skipped
    assert r["catchups"] >= 1 and r["afterRecovery"] < r["afterLate"]  # and it moves back once frames are early
    assert slack[61:].min() >= 0.08 - 1e-9  # never so far that a frame would be late
    assert r["afterRecovery"] >= r["baseOffset"] - 1e-12  # nor earlier than the first frame put the timeline

    # A text session's frames come 0.5 s ahead of their time by design: no hiccup to recover from, so the
    # timeline stays where the first frame put it. Catch-ups used to move it 0.25 s, then 0.125 s earlier,
    # each dropping the frames (and the speech) the step passed over.
    text = r["text"]
    assert text["catchups"] == 0 and text["resyncs"] == 0 and text["offset"] == text["baseOffset"]
    frames = text["frames"]
    assert all(f["fate"] in ("shown", "skipped") for f in frames)  # every frame was shown or dropped
    assert text["shown"] == sorted(set(text["shown"]))  # in order, each once
    fps = 30
    for f in frames:
        late = f["tick"] - f["due"]  # how far its time had passed when the refresh that took it came
        assert late >= -1e-9
        # Dropped only for a newer frame due in the same refresh: its own time had passed by a frame or more;
        # a frame whose time passed by less than a frame is shown.
        assert (f["fate"] == "skipped") == (late >= 1 / fps - 1e-9), f
    # So a display refreshing at 60/s drops nothing; one refreshing every 40-100 ms (4-8 s) drops what it must.
    skipped_at = np.array([f["tick"] for f in frames if f["fate"] == "skipped"])
    assert skipped_at.size > 0 and np.all((skipped_at >= 4.0) & (skipped_at < 8.2))

    # The display rate: refreshes per second over the last second.
    rates = r["rates"]
    assert rates[59] == pytest.approx(60) and rates[-1] == pytest.approx(20)

    # The page's look from its URL: embed hides the panel, background sets the colour or none (transparent);
    # a value it does not know keeps the default and says so.
    page, default = r["page"], 0x292B33
    want = {
        "": (False, default),
        "embed=1": (True, default),
        "embed": (True, default),
        "embed=0": (False, default),
        "embed=maybe": (False, default),
        "background=transparent": (False, None),
        "background=%23ff8000": (False, 0xFF8000),
        "background=ff8000": (False, 0xFF8000),
        "background=F80": (False, 0xFF8800),
        "background=red": (False, default),
        "background=12345": (False, default),
        "embed=1&background=none": (True, None),
    }
    assert {q: (p["embed"], p["background"]) for q, p in page.items()} == want
    warned = {q for q, p in page.items() if p["warnings"]}
    assert warned == {"embed=maybe", "background=red", "background=12345"}
    assert "expected transparent or a hex colour" in page["background=red"]["warnings"][0]
