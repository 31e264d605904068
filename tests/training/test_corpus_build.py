"""The corpus builder and reader: layout, determinism, real speech, augmentation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from training.articulatory import ArticulatoryConfig
from training.augment import AugmentConfig, augment
from training.build_corpus import BuildConfig, build_corpus
from training.corpus import CSV_HEADER, load_corpus
from training.errors import ConfigError
from training.params import FPS, PARAM_NAMES, n_frames_for

# Synthesises a corpus with espeak-ng.
pytestmark = [pytest.mark.system, pytest.mark.slow]


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_build_is_deterministic_and_loads(espeak, tmp_path) -> None:
    cfg = dict(sentences=4, languages=("en", "es"), seed=7, augment=True)
    a, b = tmp_path / "a", tmp_path / "b"
    build_corpus(BuildConfig(out_dir=a, **cfg))
    build_corpus(BuildConfig(out_dir=b, **cfg))
    fa, fb = _files(a), _files(b)
    assert len(fa) == 1 + 8 * 3
    assert fa.keys() == fb.keys()
    assert all(fa[k] == fb[k] for k in fa), [k for k in fa if fa[k] != fb[k]]
    assert not list(a.rglob("*.tmp"))  # atomic writes leave no temporaries
    other = tmp_path / "c"
    build_corpus(BuildConfig(out_dir=other, **{**cfg, "seed": 8}))
    assert _files(other)["en-00000/audio.wav"] != fa["en-00000/audio.wav"]

    utts = load_corpus(a)
    assert [u.id for u in utts] == [f"en-{i:05d}" for i in range(4)] + [f"es-{i:05d}" for i in range(4, 8)]
    manifest = json.loads((a / "manifest.json").read_text())
    assert manifest["version"] == 1 and manifest["seed"] == 7 and manifest["params"] == list(PARAM_NAMES)
    for u, e in zip(utts, manifest["utterances"]):
        assert u.samples.dtype == np.float32 and u.samples.ndim == 1 and np.abs(u.samples).max() <= 1.0
        assert u.params.shape == (n_frames_for(u.duration_s), 4) and u.params.dtype == np.float64
        assert u.sample_rate_hz == e["sample_rate_hz"] in (8000, 16000, 22050, 44100)
        assert u.source == "espeak" and u.speaker_group and u.language in ("en", "es")
        assert u.phonemes and u.params[:, 2].min() == 0.0  # every sentence has a closure or pause
        csv = (a / e["dir"] / "params.csv").read_text().splitlines()
        assert csv[0] == CSV_HEADER and float(csv[-1].split(",")[0]) == pytest.approx((len(csv) - 2) / FPS, abs=1e-6)


def test_real_speech_is_labelled_by_the_same_rules(espeak, shared_data, tmp_path) -> None:
    rep = build_corpus(BuildConfig(out_dir=tmp_path, sentences=0, languages=(), real_dirs=(shared_data / "speech",)))
    utts = load_corpus(tmp_path)
    assert rep.by_source == {"real": len(utts)} and len(utts) >= 5
    names = {u.id.split("-", 2)[2] for u in utts}
    assert {"arctic_a0009", "bobby", "mary"} <= names
    bobby = next(u for u in utts if u.id.endswith("bobby"))
    # "Bobby ripped": /b/ at 0.065-0.084 s and 0.233-0.279 s; the rules close the lips there
    t = np.arange(len(bobby.params)) / FPS + ArticulatoryConfig().lead_s
    closed = bobby.params[(t > 0.23) & (t < 0.285), 2]
    assert closed.min() == 0.0 and bobby.params[:, 2].max() > 0.15
    assert all(u.source == "real" and u.speaker_group.startswith("real:") for u in utts)


def test_augmentation_draws_are_in_range() -> None:
    rng = np.random.default_rng(3)
    rate = 22050
    t = np.arange(rate) / rate
    x = (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32)
    cfg = AugmentConfig(reverb_prob=1.0, noise_prob=1.0)
    for _ in range(5):
        a = augment(x, rate, rng, cfg)
        assert a.sample_rate_hz in (8000, 16000, 22050, 44100)
        assert abs(len(a.samples) / a.sample_rate_hz - 1.0) < 1e-3  # duration preserved
        assert 10 <= a.info["noise"]["snr_db"] <= 30 and np.abs(a.samples).max() <= 1.0


def test_bad_config() -> None:
    with pytest.raises(ConfigError, match="unknown language"):
        BuildConfig(out_dir=Path("x"), languages=("fr",))
    with pytest.raises(ConfigError, match="does not exist"):
        BuildConfig(out_dir=Path("x"), real_dirs=(Path("/nonexistent/speech"),))


def test_noise_is_added_at_the_drawn_snr() -> None:
    rate = 22050
    rng = np.random.default_rng(0)
    x = (0.2 * np.sin(2 * np.pi * 180 * np.arange(rate) / rate)).astype(np.float32)
    cfg = AugmentConfig(
        reverb_prob=0.0, noise_prob=1.0, snr_range_db=(15.0, 15.0), gain_range_db=(0.0, 0.0), sample_rates_hz=(22050,)
    )
    a = augment(x, rate, rng, cfg)
    noise = a.samples.astype(np.float64) - x
    snr = 20 * np.log10(np.sqrt(np.mean(x.astype(np.float64) ** 2)) / np.sqrt(np.mean(noise**2)))
    assert snr == pytest.approx(15.0, abs=0.2) and a.info["noise"]["snr_db"] == 15.0


def test_real_speech_that_cannot_be_used_is_skipped_named_and_counted(shared_data, tmp_path) -> None:
    """A recording whose only alignment is malformed was dropped without a word, and an unreadable WAV beside
    a good alignment aborted the whole build; both are now skipped with the file and the reason."""
    arctic = shared_data / "speech" / "arctic"
    real = tmp_path / "real"
    real.mkdir()
    for stem in ("good", "badlab", "badwav"):
        (real / f"{stem}.wav").write_bytes((arctic / "arctic_a0009.wav").read_bytes())
    (real / "good_phone.lab").write_bytes((arctic / "arctic_a0009_phone.lab").read_bytes())
    (real / "badlab_phone.lab").write_text("garbage line\n")
    (real / "badwav_phone.lab").write_bytes((arctic / "arctic_a0009_phone.lab").read_bytes())
    (real / "badwav.wav").write_bytes(b"RIFF\x04\x00\x00\x00WAVE")  # a header and nothing else
    rep = build_corpus(BuildConfig(out_dir=tmp_path / "out", sentences=0, languages=(), real_dirs=(real,)))
    assert rep.by_source == {"real": 1} and [u.id for u in load_corpus(tmp_path / "out")] == ["real-0000-good"]
    why = {Path(f).name: reason for f, reason in rep.skipped}
    assert sorted(why) == ["badlab.wav", "badwav.wav"], rep.skipped
    assert why["badlab.wav"].startswith("badlab_phone.lab: ") and why["badwav.wav"], rep.skipped
