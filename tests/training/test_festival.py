"""Festival as a second speech engine: real synthesis, phone timings that line up with the
audio, labels the rules know, and a deterministic corpus."""

from __future__ import annotations

import numpy as np
import pytest

from tests.prerequisites import require_tool
from training.articulatory import render_params, unknown_labels
from training.corpus import load_corpus
from training.evaluation import MOUTH_OPEN
from training.festival import VOICES, FestivalVoice, build_festival_corpus, synthesize_batch

# Festival speech synthesis.
pytestmark = pytest.mark.system


@pytest.fixture(autouse=True)
def _festival_installed() -> None:
    require_tool("festival", "apt package festival")


@pytest.mark.parametrize("voice", VOICES)
def test_phone_timings_line_up_with_the_audio(voice):
    """In "a papa", the closures of /p/ are quieter than the vowels around them (so the
    timings sit on the audio), and the rules close the mouth there."""
    [(x, rate, phones)] = synthesize_batch(["a papa, a papa."], FestivalVoice(name=voice))
    assert rate in (16000, 32000) and len(x) > rate * 0.5
    assert not unknown_labels(phones, "arpabet")
    assert phones[-1].end_s == pytest.approx(len(x) / rate, abs=0.12)

    def rms(seg):
        a, b = int(seg.start_s * rate), int(seg.end_s * rate)
        return float(np.sqrt(np.mean(x[a:b] ** 2)))

    ps = [p for p in phones if p.phoneme == "p"]
    vowels = [p for p in phones if p.phoneme == "aa"]  # the stressed vowels of "papa"
    assert ps and vowels
    assert np.mean([rms(p) for p in ps]) < 0.6 * np.mean([rms(v) for v in vowels])
    params = render_params(phones, int(np.ceil(len(x) / rate * 30)), inventory="arpabet")
    # Labels lead the sound by 33 ms: each /p/ closes the mouth within its (shifted) span.
    lead = 0.033
    closed = [
        params[int(np.ceil((p.start_s - lead) * 30)) : int((p.end_s - lead) * 30) + 1, MOUTH_OPEN].min() for p in ps
    ]
    assert max(closed) < 0.02 and params[:, MOUTH_OPEN].max() > 0.1


def test_festival_corpus_is_deterministic_and_loads(tmp_path):
    texts = ["Bob bought a map.", "Five wise owls flew by."]
    voices = [FestivalVoice(name="kal_diphone", stretch=0.9), FestivalVoice(name="cmu_us_slt_arctic_hts")]
    a = build_festival_corpus(tmp_path / "a", texts, seed=3, voices=voices, augment_audio=True)
    b = build_festival_corpus(tmp_path / "b", texts, seed=3, voices=voices, augment_audio=True)
    assert a.read_bytes() == b.read_bytes()
    ua, ub = load_corpus(tmp_path / "a"), load_corpus(tmp_path / "b")
    assert [u.source for u in ua] == ["festival", "festival"]
    for x, y in zip(ua, ub):
        np.testing.assert_array_equal(x.samples, y.samples)
        np.testing.assert_array_equal(x.params, y.params)
