"""The face at rest before and after synthesised speech (realtime_core/synthesis/rest.py): real
espeak-ng speech and the shipped GRID s1 unit corpus, compared with the same synthesis without it."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.synthesis.rest import RestPauses, rest_weights
from realtime_core.synthesis.visemes import VISEME_ID

SIL, AA = VISEME_ID["sil"], VISEME_ID["AA"]


def test_rest_weights_are_one_in_the_pauses_zero_in_speech_and_fit_a_short_pause():
    vis = np.array([SIL, AA, SIL, AA, SIL])
    starts, ends = np.array([0.0, 0.3, 0.5, 0.6, 0.9]), np.array([0.3, 0.5, 0.6, 0.9, 1.3])
    w = rest_weights(vis, starts, ends, 39, RestPauses(ramp_s=0.2))
    t = np.arange(39) / 30
    assert np.all(w[t <= 0.1 + 1e-9] == 1) and np.all(w[t >= 1.1 - 1e-9] == 1)  # at rest before and after
    assert np.all(w[(t >= 0.3) & (t <= 0.9)] == 0)  # speech and its inner pause untouched
    assert np.all(np.diff(w[t < 0.3]) <= 0) and np.all(np.diff(w[t > 0.9]) >= 0)  # monotone ramps
    # a leading pause shorter than the ramp: the ramp is shortened, frame 0 is still at rest
    short = rest_weights(vis, starts - 0.25 + [0.25, 0, 0, 0, 0], ends - 0.25, 32, RestPauses(ramp_s=0.2))
    assert short[0] == 1 and short[2] == 0
    assert np.all(rest_weights(np.array([SIL]), np.array([0.0]), np.array([1.0]), 30) == 1)  # nothing spoken
    with pytest.raises(ConfigError):
        RestPauses(ramp_s=0.0)


@pytest.mark.system  # espeak-ng and the shipped unit corpus
@pytest.mark.parametrize("text", ["Hello, how are you today?", "My name is Anna."])
def test_synthesised_speech_starts_and_ends_at_rest_with_speech_unchanged(espeak, text):
    """Before: "Hello, how are you today?" started at mouth_open 0.156 IOD over silence (a recorded
    GRID pause, mid in-breath)."""
    from assets.tts import speak
    from assets.unitcorpus import find_unit_corpus, load_unit_corpus
    from realtime_core.synthesis.synthesizer import UnitSynthesizer

    stored = load_unit_corpus(find_unit_corpus(None))
    synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
    speech = speak(text, language="en").padded()
    n = int(np.ceil(speech.duration_s * 30 - 1e-9))
    phones = list(speech.phones)
    plain = synth.synthesize(phones, speech.inventory, n_frames=n).frames
    rested = synth.synthesize(phones, speech.inventory, n_frames=n, rest_pauses=RestPauses()).frames
    mo = stored.corpus.dim_names.index("mouth_open")
    rest = stored.rest_frame()
    # the first and last frames are the rest pose: landmark coefficients and mouth parameters
    np.testing.assert_allclose(rested[0], rest, atol=1e-12)
    np.testing.assert_allclose(rested[-1], rest, atol=1e-12)
    assert abs(rested[0, mo]) < 1e-9 and abs(rested[-1, mo]) < 1e-9
    # speech (first to last spoken phone) is the unit selection's motion as it was
    spoken = [a for lab, a, b in phones if not lab.startswith("_")]
    onset = min(spoken)
    offset = max(b for lab, a, b in phones if not lab.startswith("_"))
    k = np.arange(n) / 30
    inside = (k >= onset) & (k <= offset)
    np.testing.assert_array_equal(rested[inside], plain[inside])
    assert not np.allclose(rested[~inside], plain[~inside])  # the pauses did change
    # no pop: no frame-to-frame step of a mouth parameter, nor of the landmarks (L2 over the PCA
    # coefficients), larger than the unit selection's own (its largest is at a junction in speech)
    k0 = stored.corpus.n_coefficients
    for step in (
        lambda f: np.abs(np.diff(f[:, k0:], axis=0)).max(),
        lambda f: np.linalg.norm(np.diff(f[:, :k0], axis=0), axis=1).max(),
    ):
        assert step(rested) <= step(plain) + 1e-12, (step(rested), step(plain))
