"""The one track codec (assets.tracks): CSV and JSON round trips, the strict corpus mode, the
renderer's resampling reader, and errors that name the file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from assets.errors import CorpusFormatError, TruncatedFileError
from assets.tracks import (
    decode_csv,
    decode_json,
    encode_csv,
    encode_json,
    read_csv,
    read_csv_resampled,
    read_json,
    write_csv,
)
from realtime_core import VISUAL_PARAMS
from realtime_core.track import Track
from tests.tracks import syllable_track


def test_csv_round_trip_is_exact_for_float32_and_has_time_column():
    tr = syllable_track()
    data = encode_csv(tr)
    header = data.decode().splitlines()[0].split(",")
    assert header == ["t", *VISUAL_PARAMS]
    back = decode_csv(data)
    np.testing.assert_array_equal(back.values.astype(np.float32), tr.values.astype(np.float32))
    np.testing.assert_allclose(back.times(), np.arange(90) / 30, atol=1e-6)
    assert float(data.decode().splitlines()[31].split(",")[0]) == pytest.approx(1.0)  # frame 30 at 1 s


finite32 = st.floats(-1e6, 1e6, width=32, allow_subnormal=False)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(
    v=arrays(np.float32, st.tuples(st.integers(0, 40), st.integers(1, 5)), elements=finite32),
    fps=st.sampled_from([24.0, 25.0, 30.0, 59.94, 100.0]),
    start_frames=st.integers(0, 10_000),
)
def test_csv_round_trip_is_bit_exact_for_any_float32_values(v, fps, start_frames):
    """9 significant digits: every float32 value comes back bit-identical (any fps, any start)."""
    names = tuple(f"c{j}" for j in range(v.shape[1]))
    tr = Track(values=v, names=names, fps=fps, start_s=start_frames / fps)
    back = decode_csv(encode_csv(tr), fps=fps)
    assert back.names == names and back.n_frames == tr.n_frames
    np.testing.assert_array_equal(back.values.astype(np.float32), v)
    if len(v):
        assert back.start_s == pytest.approx(tr.start_s, abs=1e-6)


def test_float64_values_round_trip_to_nine_significant_digits():
    v = np.random.default_rng(1).standard_normal((50, 4)) * 0.1
    back = decode_csv(encode_csv(Track(values=v)))
    np.testing.assert_allclose(back.values, v, rtol=1e-8, atol=0)


def test_json_round_trip_is_exact():
    tr = Track(values=syllable_track().values, start_s=2.0)
    doc = encode_json(tr, audio="take.wav")
    back = decode_json(doc)
    np.testing.assert_array_equal(back.values, tr.values)
    assert back.start_s == 2.0 and back.fps == 30.0
    d = json.loads(doc)
    assert d["audio"] == "take.wav" and d["t"][30] == pytest.approx(3.0)


def test_strict_mode_is_the_corpus_contract(tmp_path):
    """Exact header, exactly n_frames rows (fewer: truncated), t = k / 30 from 0."""
    path = write_csv(tmp_path / "params.csv", syllable_track(15))
    ok = read_csv(path, names=VISUAL_PARAMS, n_frames=15, start_s=0.0)
    np.testing.assert_array_equal(ok.values.astype(np.float32), syllable_track(15).values)
    with pytest.raises(TruncatedFileError, match=r"params\.csv: truncated: 15 frames, expected 20"):
        read_csv(path, names=VISUAL_PARAMS, n_frames=20)
    with pytest.raises(CorpusFormatError, match=r"params\.csv: 15 frames, expected 10"):
        read_csv(path, names=VISUAL_PARAMS, n_frames=10)
    with pytest.raises(CorpusFormatError, match="header must be 't,a,b,c,d'"):
        read_csv(path, names=("a", "b", "c", "d"))
    late = write_csv(tmp_path / "late.csv", Track(values=np.zeros((3, 4)), start_s=1.0))
    read_csv(late)  # on the grid from its own start: fine ...
    with pytest.raises(CorpusFormatError, match=r"late\.csv: the t column must be 0 \+ k/30"):
        read_csv(late, start_s=0.0)  # ... but a corpus track starts at 0 s
    with pytest.raises(CorpusFormatError, match=r"late\.csv: the t column must be"):
        read_csv(late, fps=25.0)  # another rate is refused, not resampled


@pytest.mark.parametrize(
    "text,reason",
    [
        ("", "header must be 't,<channel names>'"),
        ("x,a\n0,1\n", "header must be 't,<channel names>'"),
        ("t,a\n0,1,2\n", "row 1 has 3 columns"),
        ("t,a\n0,one\n", "non-numeric value"),
        ("t,a\n0,nan\n", "finite"),
        ("t,a\n0,1\n0.5,1\n", "the t column must be"),
    ],
)
def test_bad_csv_is_refused_naming_the_file(tmp_path, text, reason):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CorpusFormatError, match=rf"bad\.csv: .*{reason}"):
        read_csv(path)
    with pytest.raises(CorpusFormatError, match="not found"):
        read_csv(tmp_path / "nope.csv")


def test_resampling_reader_takes_any_rate_and_column_order(tmp_path):
    path = tmp_path / "other.csv"
    t = np.arange(0, 2.0, 0.01)  # 100 Hz from another tool, columns shuffled, one extra
    cols = {n: np.sin(t * (j + 1)) for j, n in enumerate(VISUAL_PARAMS)}
    order = ["mouth_open", "extra", "lip_corner_depress", "upper_lip_raise", "lip_stretch"]
    lines = ["t," + ",".join(order)] + [
        f"{ti:.4f}," + ",".join(f"{(cols[n][i] if n in cols else 9.0):.9g}" for n in order) for i, ti in enumerate(t)
    ]
    path.write_text("\n".join(lines) + "\n")
    tr = read_csv_resampled(path, 30.0)
    assert tr.names == VISUAL_PARAMS and tr.fps == 30.0 and tr.n_frames == int(np.floor(t[-1] * 30)) + 1
    ft = np.arange(tr.n_frames) / 30
    for j, n in enumerate(VISUAL_PARAMS):
        np.testing.assert_allclose(tr.values[:, j], np.interp(ft, t, cols[n]), atol=1e-8)


def test_resampling_reader_keeps_every_frame_of_a_facecast_csv(tmp_path):
    """`facecast animate --csv` (t to 6 decimals) -> `facecast render --params` at the same rate: the
    same frames, the last included, whatever way k/30 s was rounded in the file (1/30 s is written
    0.033333, below the frame's time)."""
    path = tmp_path / "take.csv"
    for n in range(1, 40):
        tr = syllable_track(n)
        write_csv(path, tr)
        back = read_csv_resampled(path, tr.fps)
        assert back.n_frames == n, f"{n} frames written, {back.n_frames} read"
        np.testing.assert_allclose(back.values, tr.values, atol=1e-6)


def test_resampling_reader_covers_as_long_as_a_file_at_another_rate(tmp_path):
    """`animate --fps 24` rows read at 25, 30, 60 fps: every frame that starts before the last row's own frame ends
    (n rows at 24 fps last n / 24 s; Track.at_fps's count), from the CSV and the JSON alike. Read only through the
    last row's time, 52 rows at 30 fps gave 64 frames (2.133 s) for 2.167 s of rows, shorter than the speech."""
    from assets.tracks import read_params_resampled

    for n in (2, 52, 73, 74):
        tr = Track(values=syllable_track(n).values, fps=24.0)
        write_csv(tmp_path / "take.csv", tr)
        (tmp_path / "take.json").write_bytes(encode_json(tr))
        for fps in (24.0, 25.0, 30.0, 60.0):
            covering = int(np.ceil(n / 24 * fps - 1e-6))  # frames k with k / fps < n / 24
            for ext in ("csv", "json"):
                got = read_params_resampled(tmp_path / f"take.{ext}", fps)
                assert got.n_frames == covering, (n, fps, ext, got.n_frames)
                np.testing.assert_allclose(got.values[0], tr.values[0], atol=1e-6)


def test_render_reads_a_facecast_json_like_its_csv(tmp_path):
    """`render --params take.json` (facecast's own `animate --json` export) was refused: "header must be
    't,<channel names>'". Now the same frames as the CSV of the same track, at 30 fps and resampled."""
    from assets.tracks import read_params_resampled

    tr = syllable_track(37)
    (tmp_path / "take.json").write_bytes(encode_json(tr))
    write_csv(tmp_path / "take.csv", tr)
    for fps in (30.0, 25.0):
        js, cs = (read_params_resampled(tmp_path / f"take.{ext}", fps) for ext in ("json", "csv"))
        assert js.names == cs.names == VISUAL_PARAMS and js.n_frames == cs.n_frames
        np.testing.assert_allclose(js.values, cs.values, atol=1e-6)
    other = Track(values=np.zeros((3, 2)), names=("a", "b"))
    (tmp_path / "other.json").write_bytes(encode_json(other))
    with pytest.raises(CorpusFormatError, match=r"other\.json: expected curves"):
        read_params_resampled(tmp_path / "other.json", 30.0)


def test_resampling_reader_errors_name_the_file(tmp_path):
    with pytest.raises(CorpusFormatError, match=r"nope\.csv: parameters file not found"):
        read_csv_resampled(tmp_path / "nope.csv", 30.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,mouth_open\n0,0.1\n")
    with pytest.raises(CorpusFormatError, match=r"bad\.csv: expected columns"):
        read_csv_resampled(bad, 30.0)
    back = tmp_path / "back.csv"
    back.write_text("t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress\n0.1,0,0,0,0\n0.0,0,0,0,0\n")
    with pytest.raises(CorpusFormatError, match=r"back\.csv: .*strictly increasing"):
        read_csv_resampled(back, 30.0)


def test_json_file_errors(tmp_path):
    p = tmp_path / "c.json"
    p.write_bytes(encode_json(syllable_track(5)))
    assert read_json(p).n_frames == 5
    p.write_text(json.dumps({"format": "other"}))
    with pytest.raises(CorpusFormatError, match=r"c\.json: expected facecast-curves version 1"):
        read_json(p)
    p.write_text('{"format": "facecast-curves", "version": 1, "fps": 30, "names": ["a"], "curves": {}}')
    with pytest.raises(CorpusFormatError, match=r"c\.json: inconsistent curves JSON"):
        read_json(p)


def test_a_json_given_for_a_csv_is_refused_in_a_short_line(tmp_path):
    """`render --params take.json` quoted the whole one-line JSON (every curve, thousands of characters)."""
    p = tmp_path / "take.json"
    p.write_bytes(encode_json(syllable_track(200)))
    with pytest.raises(CorpusFormatError, match=r"take\.json: header must be 't,<channel names>'") as info:
        read_csv_resampled(p, 30.0)
    assert len(str(info.value)) < len(str(p)) + 150 and '{"format":"facecast-curves"' in str(info.value)


@pytest.mark.parametrize("which", ["arkit52", "ovr15"])
@pytest.mark.parametrize("ext", ["csv", "json"])
def test_a_blendshape_curves_file_given_for_the_mouth_parameters_is_named_as_such(tmp_path, which, ext):
    """`render --params` of an `animate --curves arkit52` CSV listed its 52 columns against the four wanted, naming
    neither what the file holds nor what to give; now one line says both."""
    from assets.tracks import read_params_resampled
    from realtime_core.blendshapes import blendshape_names

    names = blendshape_names(which)
    tr = Track(values=np.full((4, len(names)), 0.25), names=names)
    path = tmp_path / f"w.{ext}"
    if ext == "csv":
        write_csv(path, tr)
    else:
        path.write_bytes(encode_json(tr, units=f"{which} blendshape weight [0, 1]"))
    with pytest.raises(CorpusFormatError) as err:
        read_params_resampled(path, 30.0)
    msg = str(err.value)
    assert f"w.{ext}: holds {which} blendshape weights" in msg and "without --curves" in msg
    assert "eyeBlinkLeft" not in msg and "\n" not in msg
