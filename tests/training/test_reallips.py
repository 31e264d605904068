"""training.reallips: speed perturbation keeps labels in step with the audio; the real-lips scores
agree with independent computations."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS
from tests.prerequisites import require_module
from training.corpus import Utterance
from training.params import FPS, n_frames_for

# Real GRID clips and ffmpeg.
pytestmark = pytest.mark.system


def _tone_utterance(freq_hz: float = 200.0, dur_s: float = 2.0, rate: int = 16000) -> Utterance:
    t = np.arange(int(dur_s * rate)) / rate
    n = n_frames_for(dur_s)
    ramp = np.arange(n) / FPS  # params = time itself, so re-timing is visible exactly
    params = np.stack([ramp, -ramp, 0.1 * ramp, np.zeros(n)], axis=1)
    return Utterance(
        id="tone",
        samples=(0.3 * np.sin(2 * np.pi * freq_hz * t)).astype(np.float32),
        sample_rate_hz=rate,
        params=params,
        phonemes=(),
        voice="v",
        language="en",
        source="video",
        speaker_group="g",
    )


@pytest.mark.parametrize("factor", [0.88, 1.12])
def test_speed_perturbation_scales_pitch_and_time_together(factor) -> None:
    from training.reallips import speed_perturb

    u = _tone_utterance()
    v = speed_perturb(u, factor)
    assert v.sample_rate_hz == u.sample_rate_hz
    assert abs(len(v.samples) - len(u.samples) / factor) <= 1
    assert v.params.shape == (n_frames_for(len(v.samples) / v.sample_rate_hz), 4)
    spec = np.abs(np.fft.rfft(v.samples * np.hanning(len(v.samples))))
    peak_hz = np.argmax(spec) * v.sample_rate_hz / len(v.samples)
    assert peak_hz == pytest.approx(200.0 * factor, rel=0.01)
    # frame k of the result shows the original at k * factor / 30 s (the ramp is time itself)
    k = np.arange(len(v.params))
    expect = np.minimum(k * factor / FPS, u.params[-1, 0])
    np.testing.assert_allclose(v.params[:, 0], expect, atol=2e-3)
    assert speed_perturb(u, 1.0) is u
    with pytest.raises(ValueError):
        speed_perturb(u, 1.5)


def test_bilabial_spans_of_a_grid_sentence() -> None:
    from training.reallips import CLOSURE_S, bilabial_spans

    words = [
        (0.0, 0.5, "sil"),
        (0.5, 0.8, "bin"),
        (0.8, 1.1, "red"),
        (1.1, 1.3, "at"),
        (1.3, 1.6, "m"),
        (1.6, 1.9, "seven"),
        (1.9, 2.3, "please"),
        (2.3, 3.0, "sil"),
    ]
    spans = bilabial_spans(words)
    assert [w for _, _, w in spans] == ["bin", "m", "please"]
    assert spans[0][:2] == pytest.approx((0.5 - CLOSURE_S / 2, 0.5 + CLOSURE_S))
    assert spans[1][:2] == pytest.approx((1.6 - CLOSURE_S, 1.6 + CLOSURE_S / 2))  # /m/ ends "em"


def test_scores_match_independent_computations() -> None:
    """r and nu against numpy on the pooled frames; the best lag of a shifted copy; closures counted
    by hand; the loudness baseline's r."""
    from training.reallips import score_lips

    rng = np.random.default_rng(0)
    items, truths, ests = [], [], []
    for c in range(3):
        T = 120
        truth = np.cumsum(rng.standard_normal((T, 4)), axis=0) * 0.01
        truth[:, 2] = np.abs(truth[:, 2])
        est = 0.7 * np.roll(truth, 2, axis=0) + 0.01 * rng.standard_normal((T, 4))  # 2 frames late, shrunk
        est[:2] = truth[:2]
        loud = truth[:, 2] * 50 + rng.standard_normal(T)
        # two closure spans per clip: the estimate reaches 0 in the first only
        est[10:14, 2] = 0.0
        truth[10:14, 2] = 0.0
        truth[60:64, 2] = 0.0
        est[58:66, 2] = 0.05
        spans = [(10 / FPS, 13 / FPS, "b"), (60 / FPS, 63 / FPS, "p")]
        items.append((f"clip{c}", truth, est, loud, spans))
        truths.append(truth)
        ests.append(est)
    s = score_lips(items)
    tr, es = np.concatenate(truths), np.concatenate(ests)
    for j, p in enumerate(VISUAL_PARAMS):
        assert s.r[p] == pytest.approx(np.corrcoef(tr[:, j], es[:, j])[0, 1], abs=1e-9)
        assert s.nu[p] == pytest.approx(es[:, j].std() / tr[:, j].std(), rel=1e-9)
        assert s.best_lag[p] == 2 and s.r_best[p] > s.r[p]
    assert s.n_closures == 6 and s.closure_rate == pytest.approx(0.5) and s.truth_closure_rate == 1.0
    lo = np.concatenate([it[3] for it in items])
    assert s.r_loudness == pytest.approx(np.corrcoef(tr[:, 2], lo)[0, 1], abs=1e-9)


@pytest.mark.slow
def test_train_on_grid_s1_from_the_cli(grid_copy, tmp_path, ffmpeg) -> None:
    """`facecast train --grid-s1 ROOT --speed 1.1 --closure-band 0.02` on a three-sentence GRID copy:
    the model records its data, holds the speed copies, keeps the band, and its output never goes
    below the closed pose."""
    require_module("mediapipe", "optional extra: pip install 'facecast[video]'")

    from assets.modelfile import load_model
    from facecast.cli import main
    from realtime_core.pipeline import speech_to_params

    root = grid_copy(("bbaf2n", "bbaf3s", "bbal6n"))
    out = tmp_path / "m.npz"
    assert (
        main(
            [
                "train",
                "--grid-s1",
                str(root),
                "--grid-split",
                "all",
                "--speed",
                "1.1",
                "--closure-band",
                "0.02",
                "--cache-dir",
                str(tmp_path / "cache"),
                "-o",
                str(out),
                "--states",
                "2",
                "--mix",
                "1",
                "--iters",
                "1",
            ]
        )
        == 0
    )
    m = load_model(out)
    assert m.metadata["grid_s1"] == {"split": "all", "sentences": 3, "speeds": [1.1], "mic_copies": 0}
    assert m.metadata["train_utterances"] == 6 and m.closure_band == 0.02
    x = np.random.default_rng(0).standard_normal(16000).astype(np.float32) * 0.05
    assert speech_to_params(m, x)[:, VISUAL_PARAMS.index("mouth_open")].min() >= 0.0


@pytest.mark.skipif(__import__("importlib").util.find_spec("mediapipe") is None, reason="mediapipe not installed")
def test_real_lips_evaluation_of_the_shipped_model(grid_copy, tmp_path, ffmpeg) -> None:
    """Two s1 sentences through the eval path: closures counted on the shipped phone labels' /p b m/,
    the estimate never below the closed pose, and the markdown table lists every parameter."""

    from assets.modelfile import load_model
    from training.grid_phones import read_grid_phones
    from training.reallips import (
        evaluate_lips,
        lips_markdown,
        phone_bilabial_spans,
        s1_clips,
    )

    root = grid_copy(("bbaf2n", "bbal6n"))
    phones = read_grid_phones()
    clips = s1_clips(None, root=root, cache_dir=tmp_path / "cache", phones=phones)
    want = sum(len(phone_bilabial_spans(phones[sid].phones)) for sid in ("bbaf2n", "bbal6n"))
    assert [c[0] for c in clips] == ["bbaf2n", "bbal6n"] and want >= 2
    scores, items = evaluate_lips(load_model(None), clips)
    assert scores.n_closures == want and scores.n_frames == sum(len(t.params) for _, t, _ in clips)
    assert all(est[:, VISUAL_PARAMS.index("mouth_open")].min() >= 0 for _, _, est, _, _ in items)
    md = lips_markdown("t", scores)
    assert all(f"| {p} |" in md for p in VISUAL_PARAMS)


def _vowel(f0_hz: float, formants_hz: tuple[float, ...], dur_s: float = 1.0, rate: int = 16000) -> np.ndarray:
    """A steady vowel: a glottal pulse train at ``f0_hz`` through two-pole resonators (80 Hz bandwidth)."""
    from scipy.signal import lfilter

    n = int(dur_s * rate)
    x = np.zeros(n)
    x[:: int(round(rate / f0_hz))] = 1.0
    for f in formants_hz:
        r = np.exp(-np.pi * 80.0 / rate)
        x = lfilter([1.0 - r], [1.0, -2.0 * r * np.cos(2 * np.pi * f / rate), r * r], x)
    return (0.3 * x / np.abs(x).max()).astype(np.float32)


def _f0_hz(x: np.ndarray, rate: int) -> float:
    """Autocorrelation pitch of the middle half (independent of Praat's tracker)."""
    seg = x[len(x) // 4 : 3 * len(x) // 4].astype(np.float64)
    ac = np.correlate(seg, seg, "full")[len(seg) - 1 :]
    lo, hi = rate // 400, rate // 60
    return rate / (lo + int(np.argmax(ac[lo:hi])))


def _first_formant_hz(x: np.ndarray, rate: int, order: int = 10) -> float:
    """Lowest LPC resonance above 250 Hz of the middle half (autocorrelation method)."""
    from scipy.linalg import solve_toeplitz

    seg = x[len(x) // 4 : 3 * len(x) // 4].astype(np.float64) * np.hamming(len(x) // 2)
    r = np.correlate(seg, seg, "full")[len(seg) - 1 : len(seg) + order]
    a = solve_toeplitz(r[:order], r[1 : order + 1])
    roots = np.roots(np.concatenate([[1.0], -a]))
    f = np.sort(np.angle(roots[np.imag(roots) > 0]) * rate / (2 * np.pi))
    return float(f[f > 250][0])


@pytest.mark.parametrize(("formant", "pitch"), [(1.2, 1.5), (0.88, 0.8)])
def test_voice_perturbation_moves_formants_and_pitch_but_not_time(formant, pitch) -> None:
    """The formants move by ``formant`` and the pitch by ``pitch`` (measured independently: LPC and
    autocorrelation), the length and the lip track are unchanged."""
    require_module("parselmouth", "pip install -e '.[train]'")
    from training.reallips import voice_perturb

    rate = 16000
    x = _vowel(120.0, (700.0, 1200.0))
    u = _tone_utterance(rate=rate, dur_s=1.0)
    u = Utterance(**{**u.__dict__, "samples": x})
    v = voice_perturb(u, formant_ratio=formant, pitch_ratio=pitch)
    assert len(v.samples) == len(x) and v.samples.dtype == np.float32
    assert v.params is u.params
    assert _f0_hz(v.samples, rate) == pytest.approx(120.0 * pitch, rel=0.05)
    assert _first_formant_hz(v.samples, rate) / _first_formant_hz(x, rate) == pytest.approx(formant, rel=0.08)
    with pytest.raises(ValueError):
        voice_perturb(u, formant_ratio=2.0, pitch_ratio=1.0)


def test_voice_variety_changes_every_speed_copy_and_keeps_the_size() -> None:
    require_module("parselmouth", "pip install -e '.[train]'")
    from training.reallips import Variety, add_variety

    u = _tone_utterance()
    plain = add_variety([u], Variety(speeds=(0.9, 1.1)))
    voiced = add_variety([u], Variety(speeds=(0.9, 1.1), formant_range=(0.85, 1.2), pitch_range=(0.7, 1.8)))
    assert len(voiced) == len(plain) == 3
    assert voiced[0] is u
    for p, v in zip(plain[1:], voiced[1:]):
        assert len(v.samples) == len(p.samples)
        np.testing.assert_array_equal(v.params, p.params)  # timing unchanged by the voice change
        assert not np.allclose(v.samples, p.samples)
    with pytest.raises(ValueError):
        Variety(formant_range=(0.85, 1.2), pitch_range=(0.7, 1.8))  # no speed copies to perturb
    with pytest.raises(ValueError):
        Variety(speeds=(0.9,), formant_range=(0.85, 1.2))  # pitch range missing
