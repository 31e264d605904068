"""The algorithmic-delay formula against a direct measurement with a click.

A click at sample s changes every output frame that depends on that sample; the first such frame,
t_first(s), could not have been final before the click arrived, so the chain's delay for that frame
is at least (s + 1) / rate - t_first(s) / fps. The largest value over s is the algorithmic delay:
it must equal :meth:`FrontEndConfig.algorithmic_delay_ms` (the formula used by the CLI, the server,
the latency benchmark and the docs), never exceed it, for every tc / window / lag of the latency dial.
"""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.avmodel import AvModel
from realtime_core.features import FrontEndConfig, MfccConfig
from realtime_core.hmm.sampling import random_av_hmm
from realtime_core.inversion import StreamConfig
from realtime_core.pipeline import SpeechToParams

pytestmark = pytest.mark.slow  # trains small models per delay setting

N_CEPS = 3


def _model(tc: int, window_hops: float) -> AvModel:
    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=N_CEPS, window_hops=window_hops), tc=tc)
    hmm = random_av_hmm(np.random.default_rng(tc), n_states=3, n_mix=2, n_audio=fe.audio_dim, n_visual=4)
    return AvModel(hmm=hmm, frontend=fe, cmvn_mean=np.zeros(N_CEPS), cmvn_var=np.ones(N_CEPS))


def _run(model: AvModel, x: np.ndarray, rate_hz: int, lag: int) -> np.ndarray:
    # A small likelihood scale keeps the posteriors soft: one-hot posteriors (a random model's 35
    # context dims make them so at kappa 1) would hide the smoothing's dependence on later frames.
    stream = StreamConfig(lag=lag, dtype="float64", likelihood_scale=0.01)
    # Without the output noise gate: it would rest this steady noise, and a one-sample click (+0.04 dB) does not open
    # it. It cannot add delay: it returns every row in the push that produced it, looking ahead tc frames at most.
    chain = SpeechToParams(model, rate_hz=rate_hz, stream=stream, noise_gate=None)
    return np.concatenate([chain.push(x), chain.flush()])


def _first_changed_frame(model: AvModel, base: np.ndarray, base_out: np.ndarray, s: int, rate_hz: int, lag: int) -> int:
    x = base.copy()
    x[s] = 0.95  # a click far louder than the background
    changed = np.flatnonzero(np.any(_run(model, x, rate_hz, lag) != base_out, axis=1))
    assert changed.size, f"a click at sample {s} changed no output frame"
    return int(changed[0])


def measured_delay_ms(model: AvModel, *, lag: int, rate_hz: int = 16000, frames: range = range(12, 18)) -> float:
    """The largest (s + 1) / rate - t_first(s) / fps over click positions s, found per frame t in
    ``frames`` by bisection for the last sample whose click first changes frame t or an earlier one
    (t_first is non-decreasing in s)."""
    fps = model.frontend.mfcc.frame_rate_hz
    base = np.random.default_rng(1).standard_normal(int(1.5 * rate_hz)) * 0.1
    base_out = _run(model, base, rate_hz, lag)
    worst = -np.inf
    for t in frames:
        lo, hi = int(t * rate_hz / fps), int((t + 10) * rate_hz / fps)  # t_first(lo) <= t < t_first(hi)
        assert _first_changed_frame(model, base, base_out, lo, rate_hz, lag) <= t
        assert _first_changed_frame(model, base, base_out, hi, rate_hz, lag) > t
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if _first_changed_frame(model, base, base_out, mid, rate_hz, lag) <= t:
                lo = mid
            else:
                hi = mid
        worst = max(worst, 1e3 * ((lo + 1) / rate_hz - t / fps))
    return worst


@pytest.mark.parametrize(
    ("tc", "window_hops", "lag"), [(3, 2.0, 0), (1, 1.35, 0), (0, 2.0, 0), (0, 1.35, 1), (2, 1.0, 2)]
)
def test_formula_equals_the_measured_delay(tc, window_hops, lag):
    model = _model(tc, window_hops)
    formula = model.algorithmic_delay_ms(lag)
    assert formula == pytest.approx(1e3 * ((tc + lag) / 30 + model.frontend.mfcc.window_len / 16000))
    # Six consecutive frames cover the 3-frame cycle of 16000 / 30 samples, so the worst case is met exactly.
    assert measured_delay_ms(model, lag=lag) == pytest.approx(formula, abs=1e-9)


def test_resampled_input_adds_the_resampler_lookahead():
    model = _model(1, 1.35)
    rate = 44100
    chain = SpeechToParams(model, rate_hz=rate, stream=StreamConfig(lag=0))
    measured = measured_delay_ms(model, lag=0, rate_hz=rate, frames=range(12, 15))
    # The chain's figure is an upper bound within one model-rate sample of the truth.
    assert chain.algorithmic_delay_ms - 1e3 / 16000 <= measured <= chain.algorithmic_delay_ms + 1e-9
    assert chain.algorithmic_delay_ms > model.algorithmic_delay_ms()


def test_the_dial_settings():
    """The settings of the latency dial (docs/accuracy.md): 167 ms default, 78.3 ms low-latency."""
    assert _model(3, 2.0).algorithmic_delay_ms() == pytest.approx(166.6875)
    assert _model(1, 1.35).algorithmic_delay_ms() == pytest.approx(78.3333, abs=1e-3)
    assert _model(1, 1.35).algorithmic_delay_ms(lag=1) == pytest.approx(111.6667, abs=1e-3)
