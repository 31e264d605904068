"""Articulatory rules: a phoneme timeline -> the four mouth parameters at 30 fps.

Theory of operation
-------------------
1. **Targets.** Every phoneme label is mapped (per inventory: espeak English, espeak Spanish,
   ARPAbet, IPA) to one or two *articulatory classes* (:data:`CLASSES`). A class holds a target
   value for each of the four parameters (IOD units, see :mod:`training.params`): where the
   mouth would go if the phoneme were held long enough. Diphthongs map to two classes, the
   segment being split 60/40 between them.
2. **Coarticulation (Cohen & Massaro 1993).** Each segment ``s`` (centre ``c_s``) has, for each
   parameter ``p``, a dominance function

       D_sp(t) = alpha_sp * exp(-theta_s * |t - c_s| ** c)

   with ``theta_s = theta_before`` for ``t < c_s`` (anticipation) and ``theta_after`` after it
   (carry-over). The trajectory is the dominance-weighted mean of the targets,

       F_p(t) = sum_s D_sp(t) T_sp / sum_s D_sp(t).

   A large ``alpha`` makes a segment hard to override (bilabial closure on mouth_open, the
   rounding of /w/ on lip_stretch); a small one makes the segment "transparent" so that its
   neighbours decide (the lips during /t d k g h/). A small ``theta`` spreads a gesture far in
   time (lip rounding is anticipated over several consonants). ``c`` shapes the peak (1 gives
   the original exponential).
3. **Hard constraints.** (a) Bilabial stops and nasals (/p b m/) close the lips: mouth_open is
   multiplied by a gate that is exactly 0 over the closure core (the central 60 % of the
   segment, widened to at least one frame period so a frame always falls inside) and rises back
   to 1 with a raised-cosine ramp of ``closure_ramp_s``; so the closure frame reads exactly 0.
   (b) Silence is the neutral pose:
   all four parameters are multiplied by an envelope that is exactly 0 inside pauses (farther
   than ``silence_ramp_s`` from speech) and before/after the utterance, with raised-cosine
   ramps. (c) mouth_open is never negative.
4. **Lips lead the sound.** Real lips move before the acoustic boundary the labels mark; the
   rules are evaluated at ``t + lead_s`` for frame time ``t``, i.e. every label is moved
   ``lead_s`` (default 33 ms, one frame) earlier.

Everything is pure numpy; a timeline of S segments and n frames costs O(S n).
The targets are phonetics first (lip and jaw positions from the visual-speech literature,
scaled to IOD units so an open /a/ opens ~0.33 IOD), then nudged against a real lip track:
GRID clip ``id2_vcd_swwp2s`` measured by :mod:`training.video`, with phone times from its word
alignment (espeak's phonemes of each word stretched over the word). That raised the close and
mid vowels' opening (the speaker's /i: u: E/ open 0.10-0.20 IOD) and made /t d n l s z/ yield
the jaw to their vowels (lower alpha); r(mouth_open) over the speech went 0.68 -> 0.72. One
clip is thin evidence: tune further as more aligned video arrives.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from training.errors import ConfigError
from training.params import FPS, N_PARAMS, frame_times

INVENTORIES = ("espeak-en", "espeak-es", "arpabet", "ipa")
"""Label sets the rules understand: espeak mnemonics per language, ARPAbet, IPA."""


@dataclass(frozen=True)
class ArticulatoryClass:
    """Target and Cohen-Massaro dominance of one articulatory class.

    target:        (4,) target per parameter, IOD units, order of ``VISUAL_PARAMS``.
    alpha:         (4,) dominance magnitude per parameter (dimensionless, > 0).
    theta_before:  anticipatory rate, 1/s (dominance falls to 1/e at 1/theta s before centre).
    theta_after:   carry-over rate, 1/s.
    bilabial:      True for full lip closure (/p b m/): mouth_open hard-gated to 0.
    silence:       True for pauses: the neutral pose, enforced by the silence envelope.
    """

    target: tuple[float, float, float, float]
    alpha: tuple[float, float, float, float]
    theta_before: float
    theta_after: float
    bilabial: bool = False
    silence: bool = False

    def __post_init__(self) -> None:
        if len(self.target) != N_PARAMS or len(self.alpha) != N_PARAMS:
            raise ConfigError("target and alpha need one value per parameter")
        if min(self.alpha) <= 0 or self.theta_before <= 0 or self.theta_after <= 0:
            raise ConfigError("alpha and theta must be > 0")


def _cls(target, alpha=(1.0, 1.0, 1.0, 1.0), theta=(14.0, 14.0), **kw) -> ArticulatoryClass:
    t, a = (float(v) for v in target), (float(v) for v in alpha)
    return ArticulatoryClass(
        (next(t), next(t), next(t), next(t)),
        (next(a), next(a), next(a), next(a)),
        float(theta[0]),
        float(theta[1]),
        **kw,
    )


# Targets: (upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress), IOD units.
# Consonants that do not involve the lips get small lip alphas ("transparent"): the lips take
# the shape of the neighbouring vowels, as observed in visual speech (e.g. /t/ in "tea" vs "two").
_CONS_LIPS_WEAK = (0.25, 0.25, 0.8, 0.25)
CLASSES: dict[str, ArticulatoryClass] = {
    # pauses and silence: neutral pose; high dominance so the mouth relaxes in pauses
    "sil": _cls((0, 0, 0, 0), (1.5, 1.5, 1.5, 1.5), (18, 18), silence=True),
    # bilabial stops/nasal: lips pressed together, slightly pulled in; hardest gesture on opening
    "bilabial": _cls((-0.010, -0.010, 0.0, 0.0), (2.0, 0.8, 2.5, 0.8), (30, 30), bilabial=True),
    # bilabial approximant (Spanish intervocalic b/v): lips nearly touch, no full closure
    "bilabial_approx": _cls((-0.005, -0.005, 0.025, 0.0), (1.2, 0.6, 2.5, 0.6), (25, 25)),
    # labiodental /f v/: lower lip tucked under the upper teeth, upper lip slightly raised
    "labiodental": _cls((0.025, 0.0, 0.025, 0.005), (2.0, 0.6, 3.0, 0.6), (22, 22)),
    # dental /T D/: tongue tip between the teeth, small jaw opening
    "dental": _cls((0.005, 0.015, 0.06, 0.0), _CONS_LIPS_WEAK, (25, 25)),
    # alveolar stops/nasal/lateral/tap: jaw fairly high, lips free
    "alveolar": _cls((0.0, 0.015, 0.06, 0.0), (0.25, 0.25, 0.5, 0.25), (25, 25)),
    # sibilants /s z/: teeth nearly together (jaw high), lips slightly spread
    "sibilant": _cls((0.005, 0.025, 0.025, -0.005), (0.4, 0.4, 0.8, 0.3), (25, 25)),
    # postalveolars /S Z tS dZ/: lips protruded and rounded, corners down
    "postalveolar": _cls((0.02, -0.05, 0.04, 0.015), (1.2, 1.5, 1.5, 1.0), (20, 20)),
    # velars /k g N x/: jaw moderately open, lips free
    "velar": _cls((0.0, 0.0, 0.08, 0.0), _CONS_LIPS_WEAK, (25, 25)),
    # glottal /h ?/: takes the following vowel's shape almost entirely
    "glottal": _cls((0.0, 0.0, 0.12, 0.0), (0.1, 0.1, 0.2, 0.1), (25, 25)),
    # English /r/: lips rounded and protruded
    "rhotic": _cls((0.01, -0.04, 0.06, 0.01), (0.8, 1.2, 0.8, 0.6), (20, 20)),
    # /w/: tightly rounded lips (strong, anticipated early)
    "labiovelar": _cls((0.01, -0.085, 0.03, 0.02), (1.2, 3.0, 1.5, 1.0), (12, 16)),
    # /j/: spread lips, high jaw
    "palatal": _cls((0.0, 0.04, 0.04, -0.01), (0.6, 1.0, 0.8, 0.6), (22, 22)),
    # vowels. Rounding (lip_stretch < 0) gets low theta: anticipated across consonants.
    "close_front": _cls((0.005, 0.065, 0.10, -0.02), (1, 1.2, 1, 1), (14, 14)),  # i: i I
    "near_close_front": _cls((0.005, 0.05, 0.12, -0.015), (1, 1, 1, 1), (15, 15)),  # I
    "mid_front": _cls((0.01, 0.05, 0.19, -0.015), (1, 1, 1, 1), (14, 14)),  # e E
    "open_front": _cls((0.015, 0.035, 0.30, -0.01), (1, 1, 1.5, 1), (12, 12)),  # ae a
    "open_central": _cls((0.015, 0.02, 0.33, -0.005), (1, 1, 1.5, 1), (12, 12)),  # a (es) A:
    "open_back": _cls((0.01, -0.015, 0.30, 0.005), (1, 1, 1.5, 1), (12, 12)),  # 0 AA
    "open_mid_back_round": _cls((0.01, -0.05, 0.24, 0.015), (1, 1.3, 1.4, 1), (12, 12)),  # O: AO
    "mid_central": _cls((0.005, 0.0, 0.13, 0.0), (0.7, 0.7, 0.8, 0.7), (16, 16)),  # @ schwa
    "open_mid_central": _cls((0.01, 0.01, 0.20, 0.0), (1, 1, 1, 1), (14, 14)),  # V AH
    "rhotic_vowel": _cls((0.01, -0.03, 0.12, 0.01), (1, 1, 1, 1), (14, 14)),  # 3: ER
    "mid_back_round": _cls((0.01, -0.065, 0.17, 0.02), (1, 1.5, 1, 1), (10, 12)),  # o
    "close_back_round": _cls((0.015, -0.09, 0.09, 0.025), (1, 2.0, 1, 1), (9, 12)),  # u: u
    "near_close_back_round": _cls((0.01, -0.06, 0.11, 0.015), (1, 1.5, 1, 1), (11, 13)),  # U
}


def _table(pairs: str) -> dict[str, tuple[str, ...]]:
    """Parse ``"label=class[+class2] ..."`` into {label: (class, ...)} (compact, checked below)."""
    out: dict[str, tuple[str, ...]] = {}
    for item in pairs.split():
        label, classes = item.rsplit("=", 1)
        out[label] = tuple(classes.split("+"))
    return out


# espeak-ng English mnemonics (phsource/ph_english*): the ones espeak emits for en, en-us,
# en-gb-* and en-029 voices. Diphthongs glide between two classes.
_SIL = "_=sil _:=sil _!=sil _^_=sil ;=sil"
PHONEME_TABLE: dict[str, dict[str, tuple[str, ...]]] = {
    "espeak-en": _table(
        _SIL + " p=bilabial b=bilabial m=bilabial f=labiodental v=labiodental"
        " T=dental D=dental t=alveolar d=alveolar n=alveolar l=alveolar t#=alveolar d#=alveolar"
        " t2=alveolar t[=alveolar d[=alveolar n-=alveolar l/=alveolar @L=mid_central+alveolar s=sibilant z=sibilant"
        " S=postalveolar Z=postalveolar tS=postalveolar dZ=postalveolar"
        " k=velar g=velar N=velar x=velar h=glottal ?=glottal r=rhotic r-=rhotic"
        " w=labiovelar w#=labiovelar j=palatal"
        " i:=close_front i=close_front I=near_close_front I2=near_close_front I#=near_close_front"
        " e=mid_front E=mid_front eI=mid_front+close_front e@=mid_front+mid_central"
        " a=open_front aa=open_front a#=open_front A:=open_central A@=open_central"
        " 0=open_back O:=open_mid_back_round O2=open_mid_back_round O@=open_mid_back_round"
        " o@=open_mid_back_round OI=open_mid_back_round+close_front"
        " @=mid_central @2=mid_central @5=mid_central @-=mid_central 3=mid_central"
        " V=open_mid_central 3:=rhotic_vowel VR=open_mid_central+rhotic IR=near_close_front+rhotic"
        " u:=close_back_round U=near_close_back_round U@=near_close_back_round+mid_central"
        " oU=mid_back_round+close_back_round @U=mid_central+close_back_round"
        " aI=open_front+close_front aI2=open_front+close_front aI@=open_front+mid_central aI3=open_front+rhotic_vowel"
        " aU=open_front+close_back_round i@=close_front+mid_central i@3=close_front+rhotic_vowel"
    ),
    # espeak-ng Spanish (ph_spanish): B D Q are the approximant allophones of b d g; ** tap,
    # R2/r trill, n^ J^ palatal nasal, l^ palatal lateral, x velar fricative, T (Castilian z).
    "espeak-es": _table(
        _SIL + " p=bilabial b=bilabial m=bilabial B=bilabial_approx f=labiodental"
        " T=dental D=dental t=alveolar d=alveolar n=alveolar l=alveolar **=alveolar r=alveolar"
        " R=alveolar R2=alveolar rr=alveolar s=sibilant z=sibilant tS=postalveolar dZ=postalveolar"
        " n^=palatal J^=palatal l^=palatal j=palatal jj=palatal y=palatal"
        " k=velar g=velar Q=velar x=velar N=velar w=labiovelar"
        " a=open_central e=mid_front E=mid_front i=close_front o=mid_back_round"
        " O=open_mid_back_round u=close_back_round"
        " aI=open_central+close_front aU=open_central+close_back_round eI=mid_front+close_front"
        " oI=mid_back_round+close_front eU=mid_front+close_back_round"
    ),
    # ARPAbet (CMUdict; ARCTIC HTS labels in lower case; LibriVox/pocketsphinx in upper case);
    # stress digits are stripped before lookup.
    "arpabet": _table(
        "sil=sil sp=sil pau=sil spn=sil h#=sil x=sil <sil>=sil"
        " p=bilabial b=bilabial m=bilabial em=bilabial f=labiodental v=labiodental"
        " th=dental dh=dental t=alveolar d=alveolar n=alveolar en=alveolar l=alveolar el=alveolar"
        " dx=alveolar nx=alveolar s=sibilant z=sibilant sh=postalveolar zh=postalveolar"
        " ch=postalveolar jh=postalveolar k=velar g=velar ng=velar hh=glottal h=glottal q=glottal"
        " r=rhotic w=labiovelar wh=labiovelar y=palatal"
        " iy=close_front ih=near_close_front ix=near_close_front eh=mid_front"
        " ey=mid_front+close_front ae=open_front aa=open_back ao=open_mid_back_round"
        " ah=open_mid_central ax=mid_central axr=rhotic_vowel er=rhotic_vowel"
        " uw=close_back_round ux=close_back_round uh=near_close_back_round"
        " ow=mid_back_round+close_back_round oy=open_mid_back_round+close_front"
        " ay=open_front+close_front aw=open_front+close_back_round"
    ),
    # IPA (praatio/MFA-style TextGrids); length marks and stress marks are stripped first.
    "ipa": _table(
        "sil=sil sp=sil spn=sil p=bilabial b=bilabial m=bilabial β=bilabial_approx"
        " f=labiodental v=labiodental ɱ=labiodental θ=dental ð=dental t=alveolar d=alveolar"
        " n=alveolar l=alveolar ɾ=alveolar r=alveolar ɹ=rhotic ɻ=rhotic ɫ=alveolar s=sibilant"
        " z=sibilant ʃ=postalveolar ʒ=postalveolar tʃ=postalveolar dʒ=postalveolar k=velar"
        " ɡ=velar g=velar ŋ=velar x=velar ɣ=velar h=glottal ʔ=glottal w=labiovelar j=palatal"
        " ɲ=palatal ʎ=palatal i=close_front ɪ=near_close_front e=mid_front ɛ=mid_front"
        " æ=open_front a=open_central ɑ=open_back ɒ=open_back ɔ=open_mid_back_round"
        " ə=mid_central ɐ=mid_central ʌ=open_mid_central ɜ=rhotic_vowel ɝ=rhotic_vowel"
        " ɚ=rhotic_vowel o=mid_back_round u=close_back_round ʊ=near_close_back_round"
        " eɪ=mid_front+close_front aɪ=open_front+close_front aʊ=open_front+close_back_round"
        " oʊ=mid_back_round+close_back_round əʊ=mid_central+close_back_round"
        " ɔɪ=open_mid_back_round+close_front y=close_back_round ø=mid_back_round œ=mid_back_round"
        " ɨ=near_close_front ʉ=close_back_round ɯ=near_close_front ɤ=mid_central"
    ),
}
"""label -> articulatory class(es), per inventory. Every class name is a key of CLASSES."""

for _inv, _tab in PHONEME_TABLE.items():  # a typo in the tables must fail at import, not at run
    for _label, _classes in _tab.items():
        for _c in _classes:
            if _c not in CLASSES:
                raise ConfigError(f"{_inv} label {_label!r} names unknown class {_c!r}")

_DIPHTHONG_SPLIT = 0.6
"""A two-class label gives its first class this fraction of the segment's duration."""


def normalise_label(label: str, inventory: str) -> str:
    """Canonical form for lookup: ARPAbet lower-cased without stress digits; IPA without
    length/stress/tie marks; espeak labels unchanged (case matters there)."""
    label = label.strip()
    if inventory == "arpabet":
        return re.sub(r"[0-9]", "", label).lower()
    if inventory == "ipa":
        return re.sub("[ːˑˈˌ\u0361\u035c\u0329\u032f]", "", label)
    return label


def classes_for(label: str, inventory: str) -> tuple[str, ...] | None:
    """The class(es) for one label, or None if the inventory does not know it.

    Empty labels (unlabelled TextGrid intervals) are silence.
    """
    if inventory not in PHONEME_TABLE:
        raise ConfigError(f"unknown inventory {inventory!r}; known: {INVENTORIES}")
    norm = normalise_label(label, inventory)
    if not norm:
        return ("sil",)
    return PHONEME_TABLE[inventory].get(norm)


@dataclass(frozen=True)
class ArticulatoryConfig:
    """Settings of :func:`render_params` (all times in seconds).

    lead_s:          labels are moved this much earlier (real lips lead the sound; 1 frame).
    closure_ramp_s:  length of the raised-cosine ramp of the bilabial closure gate.
    silence_ramp_s:  length of the ramp into/out of the neutral pose in pauses.
    shape_c:         Cohen-Massaro exponent c (1 = exponential dominance).
    unknown:         "transparent" (unknown labels get a weak neutral target) or "error".
    """

    lead_s: float = 0.033
    closure_ramp_s: float = 0.05
    silence_ramp_s: float = 0.08
    shape_c: float = 1.0
    unknown: str = "transparent"

    def __post_init__(self) -> None:
        if not -0.2 <= self.lead_s <= 0.2:
            raise ConfigError(f"lead_s must be within +-0.2 s, got {self.lead_s}")
        if self.closure_ramp_s <= 0 or self.silence_ramp_s <= 0:
            raise ConfigError("ramps must be > 0 s")
        if not 0.5 <= self.shape_c <= 3.0:
            raise ConfigError(f"shape_c must be in 0.5..3, got {self.shape_c}")
        if self.unknown not in ("transparent", "error"):
            raise ConfigError(f"unknown must be 'transparent' or 'error', got {self.unknown!r}")


_TRANSPARENT = _cls((0.0, 0.0, 0.10, 0.0), (0.1, 0.1, 0.1, 0.1), (25, 25))


@dataclass(frozen=True)
class _Seg:
    start: float
    end: float
    cls: ArticulatoryClass


def _segments(timeline: Iterable, inventory: str, cfg: ArticulatoryConfig) -> list[_Seg]:
    """Expand labelled segments (objects with phoneme, start_s, end_s) into class segments."""
    out: list[_Seg] = []
    for seg in timeline:
        start, end = float(seg.start_s), float(seg.end_s)
        if end <= start:
            continue
        names = classes_for(seg.phoneme, inventory)
        if names is None:
            if cfg.unknown == "error":
                raise ConfigError(f"no articulatory target for {inventory} label {seg.phoneme!r}")
            out.append(_Seg(start, end, _TRANSPARENT))
            continue
        if len(names) == 1:
            out.append(_Seg(start, end, CLASSES[names[0]]))
        else:
            mid = start + _DIPHTHONG_SPLIT * (end - start)
            out.append(_Seg(start, mid, CLASSES[names[0]]))
            out.append(_Seg(mid, end, CLASSES[names[1]]))
    return out


def unknown_labels(timeline: Iterable, inventory: str) -> set[str]:
    """Labels of ``timeline`` that the inventory's table does not know (for audits/tests)."""
    return {s.phoneme for s in timeline if classes_for(s.phoneme, inventory) is None}


def _raised_cosine_gate(t: np.ndarray, lo: float, hi: float, ramp: float) -> np.ndarray:
    """(n,) gate: 0 on [lo, hi], rising to 1 over ``ramp`` s on both sides (raised cosine)."""
    d = np.maximum(lo - t, t - hi)  # distance outside the interval (<= 0 inside)
    x = np.clip(d / ramp, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def render_params(
    timeline: Sequence, n_frames: int, *, inventory: str, config: ArticulatoryConfig = ArticulatoryConfig()
) -> np.ndarray:
    """The four parameters for frames 0..n_frames-1 (frame k at t = k/30 s).

    timeline:   segments with ``phoneme``, ``start_s``, ``end_s`` (seconds from the audio's
                first sample), e.g. :class:`assets.espeak.PhonemeSegment`; gaps are silence.
    inventory:  one of :data:`INVENTORIES`.
    Returns (n_frames, 4) float64, IOD units, order of ``VISUAL_PARAMS``.
    """
    if n_frames < 0:
        raise ConfigError(f"n_frames must be >= 0, got {n_frames}")
    if inventory not in PHONEME_TABLE:
        raise ConfigError(f"unknown inventory {inventory!r}; known: {INVENTORIES}")
    out = np.zeros((n_frames, N_PARAMS))
    segs = _segments(timeline, inventory, config)
    speech = [s for s in segs if not s.cls.silence]
    if n_frames == 0 or not speech:
        return out
    # Evaluate the rules at t + lead: the same as moving every label lead_s earlier.
    t = frame_times(n_frames) + config.lead_s

    starts = np.array([s.start for s in segs])
    ends = np.array([s.end for s in segs])
    centres = 0.5 * (starts + ends)
    targets = np.array([s.cls.target for s in segs])  # (S, 4)
    alphas = np.array([s.cls.alpha for s in segs])  # (S, 4)
    th_b = np.array([s.cls.theta_before for s in segs])
    th_a = np.array([s.cls.theta_after for s in segs])

    tau = t[None, :] - centres[:, None]  # (S, n) seconds from each centre
    theta = np.where(tau < 0, th_b[:, None], th_a[:, None])
    # exp(-theta |tau|^c) underflows to 0 far away; the floor keeps the denominator positive
    # (far from every segment the result is irrelevant: the silence envelope zeroes it).
    dom = np.exp(-theta * np.abs(tau) ** config.shape_c)  # (S, n)
    dom = np.maximum(dom, 1e-300)
    num = np.einsum("sn,sp,sp->np", dom, alphas, targets)
    den = np.einsum("sn,sp->np", dom, alphas)
    out = num / den

    # (a) bilabial closures: mouth_open exactly 0 over the closure core (>= one frame wide).
    gate = np.ones(n_frames)
    half_frame = 0.5 / FPS
    for s in segs:
        if s.cls.bilabial:
            c = 0.5 * (s.start + s.end)
            half = max(0.5 * (s.end - s.start) * 0.6, half_frame)
            gate = np.minimum(gate, _raised_cosine_gate(t, c - half, c + half, config.closure_ramp_s))
    out[:, 2] *= gate

    # (b) silence: neutral pose inside pauses and outside the speech span.
    env = np.ones(n_frames)
    first, last = speech[0].start, max(s.end for s in speech)
    env = np.minimum(env, _raised_cosine_gate(t, -np.inf, first - config.silence_ramp_s, config.silence_ramp_s))
    env = np.minimum(env, _raised_cosine_gate(t, last + config.silence_ramp_s, np.inf, config.silence_ramp_s))
    # pauses = silence segments or unlabelled gaps between speech segments
    spans = sorted((s.start, s.end) for s in speech)
    cursor = spans[0][1]
    for a, b in spans[1:]:
        if a - cursor > 2 * config.silence_ramp_s:
            env = np.minimum(
                env,
                _raised_cosine_gate(
                    t, cursor + config.silence_ramp_s, a - config.silence_ramp_s, config.silence_ramp_s
                ),
            )
        cursor = max(cursor, b)
    out *= env[:, None]

    # (c) a gap cannot be negative
    out[:, 2] = np.maximum(out[:, 2], 0.0)
    return out
