"""``extract_corpus`` / ``load_face_track`` on real GRID clips with real ffmpeg and MediaPipe:
the cache resumes, bad clips are skipped and counted, and FaceTrack keeps its invariants."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.prerequisites import missing, require_module
from training.params import n_frames_for

# ffmpeg and MediaPipe on real GRID clips.
pytestmark = [pytest.mark.system, pytest.mark.slow]


@pytest.fixture(autouse=True)
def _mediapipe_installed() -> None:
    require_module("mediapipe", "optional extra: pip install 'facecast[video]'")


@pytest.fixture(scope="module")
def s1(shared_data) -> Path:
    root = shared_data / "video" / "grid_s1"
    if not (root / "video" / "bbaf2n.mp4").is_file():
        missing(f"GRID s1 not found in {root}")
    return root


def _ffmpeg(*args: str) -> None:
    subprocess.run([shutil.which("ffmpeg") or "ffmpeg", "-v", "error", "-y", *args], check=True)


def test_second_run_reads_the_cache_only(grid_copy, tmp_path, ffmpeg) -> None:
    """The first run measures both clips; the second measures nothing and leaves the cache files
    untouched; a renamed copy of a clip (same bytes) is a cache hit too."""
    from training.video import extract_corpus

    corpus = grid_copy(["bbaf2n", "bbaf3s"])
    cache = tmp_path / "cache"
    first = extract_corpus([corpus / "video"], cache_dir=cache, workers=2)
    assert (first.n_extracted, first.n_cached, len(first.skipped)) == (2, 0, 0)
    files = sorted(cache.rglob("*.npz"))
    assert len(files) == 2
    stamps = [f.stat().st_mtime_ns for f in files]
    shutil.copy(corpus / "video" / "bbaf2n.mp4", corpus / "video" / "renamed.mp4")
    second = extract_corpus([corpus / "video"], cache_dir=cache, workers=2)
    assert (second.n_extracted, second.n_cached, len(second.skipped)) == (0, 3, 0)
    assert sorted(cache.rglob("*.npz")) == files and [f.stat().st_mtime_ns for f in files] == stamps
    # the same measurement whichever way it was reached
    by_name = {Path(c["file"]).stem: c for c in second.clips}
    assert by_name["renamed"]["sha1"] == by_name["bbaf2n"]["sha1"]
    assert by_name["bbaf2n"] == {**first.clips[0], "file": by_name["bbaf2n"]["file"]}


def test_bad_clips_are_skipped_named_and_counted(s1, grid_copy, tmp_path, ffmpeg) -> None:
    """One run over a folder of good and bad clips: every bad clip is skipped with its reason and
    counted; the good ones are measured; nothing aborts."""
    from training.video import ExtractConfig, extract_corpus

    root = grid_copy(["bbaf2n", "bbaf3s", "bbaf4p", "bbaf5a"])
    v, a = root / "video", root / "align"
    src = s1 / "video" / "bbal6n.mp4"
    # no face at all: a grey picture with a tone
    _ffmpeg(
        "-f",
        "lavfi",
        "-i",
        "color=c=gray:s=360x288:r=25:d=3",
        "-f",
        "lavfi",
        "-i",
        "sine=f=220:d=3",
        "-shortest",
        "-c:v",
        "libx264",
        "-c:a",
        "aac",
        str(v / "noface.mp4"),
    )
    shutil.copy(s1 / "align" / "bbaf2n.align", a / "noface.align")
    # face lost mid-clip for 1 s (black box over the whole picture from 1.0 to 2.0 s)
    _ffmpeg(
        "-i",
        str(src),
        "-vf",
        "drawbox=enable='between(t,1,2)':x=0:y=0:w=iw:h=ih:color=black:t=fill",
        "-c:a",
        "copy",
        str(v / "lost.mp4"),
    )
    shutil.copy(s1 / "align" / "bbal6n.align", a / "lost.align")
    # audio cut to 1.5 s under 3 s of video
    _ffmpeg("-i", str(src), "-c:v", "copy", "-af", "atrim=0:1.5", str(v / "short.mp4"))
    shutil.copy(s1 / "align" / "bbal6n.align", a / "short.align")
    # a malformed alignment (bbaf4p) and a missing one (bbaf5a)
    (a / "bbaf4p.align").write_text("0 23750 sil\nthis is not an alignment\n")
    (a / "bbaf5a.align").unlink()

    lines: list[str] = []
    report = extract_corpus([v], cache_dir=tmp_path / "cache", workers=2, require_alignment=True, log=lines.append)
    ok = sorted(Path(c["file"]).stem for c in report.clips)
    reasons = {Path(s["file"]).stem: s["reason"] for s in report.skipped}
    assert ok == ["bbaf2n", "bbaf3s"], (ok, reasons)
    assert set(reasons) == {"noface", "lost", "short", "bbaf4p", "bbaf5a"}
    assert reasons["noface"].startswith("no face found in 75 of 75 frames")
    assert reasons["lost"].startswith("face lost for 1.0") and "from 1.0" in reasons["lost"]
    assert reasons["short"].startswith("audio (1.5") and "and video (3.00 s) differ in length" in reasons["short"]
    # the file at fault named: the malformed .align, not only the clip beside it
    assert reasons["bbaf4p"].startswith(f"{a / 'bbaf4p.align'}: line 2 is not 'start end word'")
    assert reasons["bbaf5a"] == "no word alignment found (missing .align)"
    assert report.as_json()["n_skipped"] == 5 and report.as_json()["n_ok"] == 2
    # one line each, naming the file and the reason
    assert len(lines) == 5 and all(ln.startswith("skipped ") for ln in lines)
    assert any(str(v / "lost.mp4") in ln and "face lost" in ln for ln in lines)
    # without the alignment requirement the clip with no .align is measured (rest from the audio level)
    kept: list[str] = []
    again = extract_corpus([v / "bbaf5a.mp4"], cache_dir=tmp_path / "cache", workers=1, log=kept.append)
    assert again.n_cached == 1 and again.clips[0]["neutral"]["method"] == "quiet"
    # ... and said so in one line, counted in the report (it was kept without a word)
    assert kept == [
        f"no word alignment for {v / 'bbaf5a.mp4'}: kept, its rest pose without one (--require-alignment skips it)"
    ]
    assert again.as_json()["summary"]["clips_without_alignment"] == 1
    # a face lost for a short while is bridged and flagged
    short_gap = extract_corpus(
        [v / "lost.mp4"],
        cache_dir=tmp_path / "cache",
        workers=1,
        config=ExtractConfig(max_gap_s=1.5, min_face_fraction=0.6),
    )
    q = short_gap.clips[0]
    assert 0.6 < q["face_found_fraction"] < 0.7 and short_gap.n_cached == 1


def test_face_track_invariants(s1, tmp_path, ffmpeg) -> None:
    """Shapes, dtypes and frames of a FaceTrack on a real clip; its parameters follow from its own
    landmarks and neutral face; the face frame is the documented one."""
    from training.facetrack import (
        CHEEKS,
        JAW,
        LEFT_EYE_CORNERS,
        LIPS_INNER,
        LIPS_OUTER,
        LOWER_FACE,
        NOSE_TIP,
        RIGHT_EYE_CORNERS,
        FaceTrack,
    )
    from training.video import load_face_track, mouth_params

    track = load_face_track(s1 / "video" / "bbaf2n.mp4", cache_dir=tmp_path / "cache")
    assert isinstance(track, FaceTrack)
    n = n_frames_for(track.duration_s)
    assert track.sample_rate_hz == 16000 and track.samples.dtype == np.float32
    assert track.landmarks.shape == (n, 468, 3) and track.landmarks.dtype == np.float32
    assert track.neutral.shape == (468, 3) and track.neutral.dtype == np.float32
    assert track.params.shape == (n, 4) and track.params.dtype == np.float64
    assert track.face_found.shape == (n,) and track.face_found.all()
    assert np.isfinite(track.landmarks).all()
    np.testing.assert_allclose(
        track.params, mouth_params(track.landmarks, track.neutral, closed_gap=track.closed_gap_iod), atol=1e-6
    )
    # mouth_open's zero is lip contact: never far below 0, and the rest face reads its own gap
    assert track.params[:, 2].min() > -0.01 and 0 <= track.closed_gap_iod <= track.quality["neutral"]["lip_gap_iod"]
    # face frame, IOD units: eye centres at x = -/+ 0.5 on the x axis, the mouth below (y > 0),
    # the nose tip towards the camera (z = x cross y points into the face)
    eye_r, eye_l = track.neutral[list(RIGHT_EYE_CORNERS)].mean(0), track.neutral[list(LEFT_EYE_CORNERS)].mean(0)
    np.testing.assert_allclose(eye_l - eye_r, [1.0, 0.0, eye_l[2] - eye_r[2]], atol=0.05)
    assert abs(np.linalg.norm(eye_l - eye_r) - 1.0) < 0.05 and abs(eye_l[1]) < 0.05 and abs(eye_r[1]) < 0.05
    assert track.neutral[list(LIPS_OUTER), 1].min() > 0.8  # the mouth is about 1-1.5 IOD below the eyes
    assert track.neutral[NOSE_TIP, 2] < eye_r[2] - 0.1
    # the groups: valid, distinct, LOWER_FACE their union, mirrored left/right about x = 0
    for group in (LIPS_OUTER, LIPS_INNER, JAW, CHEEKS):
        assert len(set(group)) == len(group) and all(0 <= i < 468 for i in group)
        pts = track.neutral[list(group)]
        mirrored = pts * np.array([-1.0, 1.0, 1.0])
        nearest = np.min(np.linalg.norm(mirrored[:, None] - pts[None], axis=2), axis=1)
        assert nearest.max() < 0.12, (group, nearest.max())
    assert set(LOWER_FACE) == set(LIPS_OUTER) | set(LIPS_INNER) | set(JAW) | set(CHEEKS)
    # rest = the alignment's silences: the parameters are ~0 there, and the mouth opens in speech
    assert track.quality["neutral"]["method"] == "silence" and track.quality["neutral"]["n_frames"] >= 20
    assert track.params[:, 2].max() > 0.1
    # a cache file loads to the same track
    cached = next((tmp_path / "cache").rglob("*.npz"))
    again = load_face_track(cached)
    np.testing.assert_array_equal(again.landmarks, track.landmarks)


def test_malformed_alignments_name_the_file(tmp_path) -> None:
    from assets.grid import read_words
    from training.errors import AlignmentFormatError

    cases = {
        "empty.align": "",
        "text.align": "hello world\n",
        "float.align": "0 1.5 sil\n",
        "backwards.align": "0 100 sil\n50 20 bin\n",
    }
    for name, text in cases.items():
        p = tmp_path / name
        p.write_text(text)
        with pytest.raises(AlignmentFormatError, match=rf"{name}: "):
            read_words(p)
    with pytest.raises(AlignmentFormatError, match=r"missing.align: cannot be read"):
        read_words(tmp_path / "missing.align")
