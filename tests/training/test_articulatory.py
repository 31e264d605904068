"""The articulatory rules: bilabial closures, silence, lead, coverage of espeak's phonemes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from assets.espeak import LANGUAGES, Voice
from training.articulatory import ArticulatoryConfig, render_params, unknown_labels
from training.params import FPS, n_frames_for

# Real espeak-ng speech.
pytestmark = pytest.mark.system

MOUTH_OPEN = 2


@dataclass(frozen=True)
class Seg:
    phoneme: str
    start_s: float
    end_s: float


def _timeline(spec: str, start: float = 0.2, dur: float = 0.09) -> list[Seg]:
    out, t = [], start
    for ph in spec.split():
        out.append(Seg(ph, t, t + dur))
        t += dur
    return out


@pytest.mark.parametrize(
    "inventory,spec",
    [
        ("arpabet", "AA1 P AA1 B AA1 M AA1"),
        ("espeak-en", "a p a b a m a"),
        ("espeak-es", "a p a b o m a"),
        ("ipa", "a p a b a m a"),
    ],
)
def test_bilabials_close_to_exactly_zero(inventory, spec) -> None:
    tl = _timeline(spec)
    cfg = ArticulatoryConfig(lead_s=0.0)
    P = render_params(tl, n_frames_for(1.2), inventory=inventory, config=cfg)
    t = np.arange(len(P)) / FPS
    for seg in tl:
        if seg.phoneme in ("P", "B", "M", "p", "b", "m"):
            centre = 0.5 * (seg.start_s + seg.end_s)
            k = int(np.argmin(np.abs(t - centre)))
            assert P[k, MOUTH_OPEN] == 0.0, (seg, P[k])
        else:  # the open vowels between them really open
            inside = (t >= seg.start_s) & (t < seg.end_s)
            assert P[inside, MOUTH_OPEN].max() > 0.12, (seg, P[inside, MOUTH_OPEN])


def test_zero_at_closure_for_short_bilabial_between_frames() -> None:
    """A 20 ms /b/ between two frame instants still gets a frame with exactly zero opening."""
    tl = [Seg("AA", 0.1, 0.31), Seg("B", 0.31, 0.33), Seg("AA", 0.33, 0.6)]
    P = render_params(tl, 20, inventory="arpabet", config=ArticulatoryConfig(lead_s=0.0))
    assert (P[:, MOUTH_OPEN] == 0.0)[9:11].any()


def test_silence_is_neutral_and_lead_moves_earlier() -> None:
    tl = [Seg("sil", 0.0, 0.5), Seg("AA", 0.5, 0.8), Seg("sil", 0.8, 1.6), Seg("IY", 1.6, 1.9), Seg("sil", 1.9, 2.5)]
    n = n_frames_for(2.5)
    P = render_params(tl, n, inventory="arpabet", config=ArticulatoryConfig(lead_s=0.0))
    t = np.arange(n) / FPS
    assert np.all(P[t < 0.3] == 0.0) and np.all(P[(t > 1.0) & (t < 1.4)] == 0.0) and np.all(P[t > 2.1] == 0.0)
    assert P[:, MOUTH_OPEN].max() > 0.25
    assert P[(t > 1.6) & (t < 1.9), 1].max() > 0.04  # /i/ spreads the lips
    led = render_params(tl, n, inventory="arpabet", config=ArticulatoryConfig(lead_s=1 / FPS))
    np.testing.assert_allclose(led[:-1], P[1:], atol=1e-12)  # one frame earlier exactly


def test_rounded_vowels_narrow_open_vowels_drop_jaw() -> None:
    tl = _timeline("UW", dur=0.3) + _timeline("AA", start=0.8, dur=0.3)
    P = render_params(tl, n_frames_for(1.3), inventory="arpabet", config=ArticulatoryConfig(lead_s=0.0))
    u, a = P[10], P[28]
    assert u[1] < -0.05 and a[MOUTH_OPEN] > 2 * u[MOUTH_OPEN]


def test_every_espeak_phoneme_of_the_sentence_lists_has_a_target(espeak) -> None:
    """All phonemes espeak emits for (a sample of) the project's sentences are in the tables."""
    from pathlib import Path

    import training

    folder = Path(training.__file__).parent / "sentences"
    for lang in LANGUAGES:
        lines = [
            ln.strip()
            for ln in (folder / f"{lang}.txt").read_text().splitlines()
            if ln.strip() and not ln.startswith("#")
        ]
        assert len(lines) >= 300, f"{lang}: only {len(lines)} sentences"
        inv = f"espeak-{lang}"
        for base in LANGUAGES[lang]:
            missing: set[str] = set()
            for text in lines[::7]:
                missing |= unknown_labels(espeak.synthesize(text, Voice(language=lang, base=base)).phonemes, inv)
            assert not missing, f"{base}: no target for {sorted(missing)}"


def test_real_espeak_utterance_closes_on_bilabials(espeak) -> None:
    syn = espeak.synthesize("Bob bought a map, but Peter fumbled.", Voice(language="en", base="en-us"))
    P = render_params(syn.phonemes, n_frames_for(syn.duration_s), inventory="espeak-en")
    lead = ArticulatoryConfig().lead_s
    t = np.arange(len(P)) / FPS + lead
    for seg in syn.phonemes:
        if seg.phoneme in ("p", "b", "m"):
            inside = (t >= seg.start_s) & (t <= seg.end_s)
            near = np.abs(t - 0.5 * (seg.start_s + seg.end_s)) <= 0.5 / FPS + 1e-9
            assert (P[inside | near, MOUTH_OPEN] == 0.0).any(), seg
