"""Keyframe sets in the Motion-Unit landmark space (paper 002 eq. 3-4), for the round-trip check.

* **paper8**: the paper's eight keyframes (Sec. VII-B): visemes i, a, o, f, u, m taken from the real
  data, as the paper does ("training samples that semantically correspond"), plus smile and sad. GRID
  has word alignments, so a viseme is the median deformation of the train frames in a fixed part of
  words that carry it (:data:`VISEME_WORDS`, e.g. the end of "three" for /i/, the start of "four" and
  "five" for /f/, the closure at the start of "bin", "blue", "by", "place", "please" for /m/); smile
  and sad are the expression deformations (:mod:`training.mu_expressions`).
* **arkit52**: the built-in head's 52 ARKit targets carried onto the speaker's landmarks (the same
  correspondence as the expressions); shapes that do not reach the lower face are zero columns, so the
  set is solved with a small ridge.
* **ovr15**: the 14 non-silent OVR visemes taken from the real data like the paper's: the median
  deformation of the train frames in the middle half of every phone of the viseme's class
  (:data:`OVR_PHONES`, Oculus Lipsync's viseme reference in ARPAbet) in the shipped GRID s1 phone
  alignment (``assets/data/grid_s1_phones.json``); ``sil`` is the neutral face (a zero column, dropped).
  (The earlier set, the visemes' articulatory targets in the four mouth parameters mapped to
  deformations, has rank 4 and cannot carry more than 4 MUs: :func:`ovr_param_keyframes`.)

Every set is also solved in the MU subspace (:func:`realtime_core.motion_units.in_mu_space`), where
the round trip is measured both unconstrained (eq. 4) and with ``b >= 0`` (what an engine can use).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from realtime_core.motion_units import KeyframeSet
from training.motion_units import Clip

VISEME_WORDS: dict[str, tuple[tuple[str, float, float], ...]] = {
    "i": (("three", 0.6, 0.9), ("e", 0.3, 0.8), ("d", 0.5, 0.9), ("t", 0.5, 0.9)),
    "a": (("at", 0.1, 0.5),),
    "o": (("zero", 0.65, 0.95), ("o", 0.3, 0.8)),
    "f": (("four", 0.0, 0.25), ("five", 0.0, 0.25)),
    "u": (("two", 0.5, 0.9), ("blue", 0.6, 0.9), ("q", 0.5, 0.9), ("u", 0.5, 0.9)),
    "m": (("bin", 0.0, 0.15), ("blue", 0.0, 0.15), ("by", 0.0, 0.15), ("place", 0.0, 0.15), ("please", 0.0, 0.15)),
}
"""Viseme -> (GRID word, start, end as fractions of the word's duration)."""

OVR_PHONES: dict[str, tuple[str, ...]] = {
    "PP": ("P", "B", "M"),
    "FF": ("F", "V"),
    "TH": ("TH", "DH"),
    "DD": ("T", "D"),
    "kk": ("K", "G", "NG", "HH"),
    "CH": ("CH", "JH", "SH", "ZH"),
    "SS": ("S", "Z"),
    "nn": ("N", "L"),
    "RR": ("R", "ER"),
    "aa": ("AA", "AE", "AH", "AY", "AW"),
    "E": ("EH", "EY"),
    "I": ("IH", "IY", "Y"),
    "O": ("AO", "OW", "OY"),
    "U": ("UW", "UH", "W"),
}
"""OVR viseme -> the ARPAbet phones it shows (Oculus Lipsync viseme reference; diphthongs by their onset)."""


def phone_keyframes(
    clips: Sequence[Clip], phones_of: Mapping[str, Sequence[tuple[str, float, float]]], fps: float = 30.0
) -> dict[str, np.ndarray]:
    """Median deformation ``(3 L,)`` of each OVR viseme over the frames in the middle half of its phones.

    phones_of: sentence id -> ``(phone, start_s, end_s)`` (ARPAbet, upper case); sentences without
    phones are skipped."""
    of_phone = {ph: v for v, phs in OVR_PHONES.items() for ph in phs}
    rows: dict[str, list[np.ndarray]] = {v: [] for v in OVR_PHONES}
    for c in clips:
        for ph, start, end in phones_of.get(c.sentence_id, ()):
            v = of_phone.get(ph)
            if v is None:
                continue
            lo = round((start + 0.25 * (end - start)) * fps)
            hi = max(lo + 1, round((start + 0.75 * (end - start)) * fps))
            if lo < len(c.deform):
                rows[v].append(c.deform[lo : min(hi, len(c.deform))])
    return {v: np.median(np.concatenate(r), axis=0) for v, r in rows.items() if r}


def viseme_keyframes(clips: Sequence[Clip], words_of: dict[str, list], fps: float = 30.0) -> dict[str, np.ndarray]:
    """Median deformation ``(3 L,)`` of each viseme over the clips' matching word parts."""
    rows: dict[str, list[np.ndarray]] = {v: [] for v in VISEME_WORDS}
    for c in clips:
        for start, end, w in words_of[c.sentence_id]:
            for v, specs in VISEME_WORDS.items():
                for word, a, b in specs:
                    if w.lower() == word:
                        lo = round((start + a * (end - start)) * fps)
                        hi = max(lo + 1, round((start + b * (end - start)) * fps))
                        rows[v].append(c.deform[lo : min(hi, len(c.deform))])
    return {v: np.median(np.concatenate(r), axis=0) for v, r in rows.items() if r and len(np.concatenate(r))}


def params_to_deformation(clips: Sequence[Clip]) -> tuple[np.ndarray, np.ndarray]:
    """Least squares ``d ~ B p + d0`` over the clips' frames: ``(B (3 L, 4), d0 (3 L,))``."""
    p = np.concatenate([c.params for c in clips])
    d = np.concatenate([c.deform for c in clips]).astype(np.float64)
    coef = np.linalg.lstsq(np.hstack([p, np.ones((len(p), 1))]), d, rcond=None)[0]
    return coef[:4].T, coef[4]


def ovr_param_keyframes(train: Sequence[Clip]) -> KeyframeSet:
    """The OVR visemes' articulatory targets in the four mouth parameters (:mod:`training.fit_maps`) as
    deformations, through the least-squares map from mouth parameters to deformations (rank 4)."""
    from realtime_core.blendshapes import OVR_NAMES, ovr_keyframes

    b, _ = params_to_deformation(train)
    return KeyframeSet(names=OVR_NAMES[1:], shapes=b @ ovr_keyframes(), ridge=1e-4)


def keyframe_sets(
    train: Sequence[Clip],
    words_of: dict[str, list],
    expr: dict[str, np.ndarray],
    arkit: dict[str, np.ndarray],
    phones_of: Mapping[str, Sequence[tuple[str, float, float]]],
) -> dict[str, KeyframeSet]:
    """The paper's eight, ARKit-52 and OVR-15 (from the phones), plus ``ovr15_params`` (the rank-4 set)."""
    vis = viseme_keyframes(train, words_of)
    names = (*tuple(vis), "smile", "sad")
    paper = KeyframeSet(names=names, shapes=np.column_stack([*vis.values(), expr["smile"], expr["sad"]]))
    ark_names = tuple(n for n, v in arkit.items() if np.abs(v).max() > 0)
    ark = KeyframeSet(names=ark_names, shapes=np.column_stack([arkit[n] for n in ark_names]), ridge=1e-4)
    ph = phone_keyframes(train, phones_of)
    ovr = KeyframeSet(names=tuple(ph), shapes=np.column_stack(list(ph.values())), ridge=1e-4)
    return {"paper8": paper, "arkit52": ark, "ovr15": ovr, "ovr15_params": ovr_param_keyframes(train)}
