"""Phones with timings -> recorded motion at 30 fps: viseme mapping, unit search, warping.

The sans-I/O front of unit selection (seed 001 Sec. 3.7-3.8): a target phone timeline (labels of
one inventory, start/end seconds) is made gapless (a gap becomes a pause, joined to a pause next to it),
mapped to viseme classes (unknown labels fall back to a neutral open vowel and are reported;
classes the corpus lacks fall back to look-alikes, :func:`realtime_core.synthesis.visemes.resolve`),
searched (:func:`realtime_core.synthesis.search.select_units`) and rendered
(:func:`realtime_core.synthesis.concat.concatenate`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.synthesis.closure import ClosureConfig, close_bilabials, closed_pose
from realtime_core.synthesis.concat import concatenate
from realtime_core.synthesis.corpus import FPS, MotionCorpus
from realtime_core.synthesis.recording import (
    RecordingBlend,
    blend_recording,
    param_to_coefficient_map,
    region_weights,
)
from realtime_core.synthesis.rest import RestPauses, ease_to_rest
from realtime_core.synthesis.search import (
    NoPathError,
    SearchConfig,
    Selection,
    UnitGraph,
    build_graph,
    select_units,
)
from realtime_core.synthesis.visemes import (
    LINKS,
    PHONE_TO_VISEME,
    VISEME_ID,
    VISEMES,
    normalise_phone,
    resolve,
    viseme_of,
)

UNKNOWN_PHONE_VISEME = "AH"
"""Class used for a phone label outside the table: a mid-open neutral mouth keeps speech moving."""


@dataclass(frozen=True, kw_only=True)
class Target:
    """A gapless target: labels (T,), visemes (T,) int class ids after fallback, starts_s/ends_s (T,)."""

    labels: tuple[str, ...]
    visemes: np.ndarray
    starts_s: np.ndarray
    ends_s: np.ndarray
    unknown: tuple[str, ...] = ()
    substituted: int = 0

    @property
    def durations_s(self) -> np.ndarray:
        return self.ends_s - self.starts_s


@dataclass(frozen=True, kw_only=True)
class UnitSynthesis:
    """frames: (n_frames, D) float64 at k / 30 s (dims named by the corpus); target; selection:
    the best unit sequence; alternatives: the further sequences averaged in (``n_best`` > 1)."""

    frames: np.ndarray
    target: Target
    selection: Selection
    alternatives: tuple[Selection, ...] = ()


def make_target(phones: Sequence[tuple[str, float, float]], inventory: str, available: frozenset[str]) -> Target:
    """Phones ``[(label, start_s, end_s)]`` -> a gapless :class:`Target` starting at 0 s."""
    if not phones:
        raise ConfigError("no phones to synthesise")
    rows = sorted(((str(lab), float(a), float(b)) for lab, a, b in phones), key=lambda r: r[1])
    labels: list[str] = []
    vis: list[int] = []
    starts: list[float] = []
    ends: list[float] = []
    unknown: list[str] = []
    substituted = 0
    t = 0.0

    inserted = [False]  # whether the last entry is a pause inserted for a gap

    def add(label: str, v: str, a: float, b: float, *, gap: bool = False) -> None:
        if b - a <= 1e-6:
            return
        # a gap joins a neighbouring pause (the input's own pauses are kept as they are, so a
        # corpus sentence's phones reproduce that sentence exactly)
        if vis and v == "sil" and VISEMES[vis[-1]] == "sil" and (gap or inserted[0]):
            ends[-1] = b
            inserted[0] = inserted[0] and gap
            return
        labels.append(label)
        vis.append(VISEME_ID[v])
        starts.append(a)
        ends.append(b)
        inserted[0] = gap

    for label, a, b in rows:
        if not np.isfinite(a) or not np.isfinite(b):
            raise ConfigError(f"phone {label!r} has a non-finite time")
        if a > t + 1e-6:
            add("sil", resolve("sil", available), t, a, gap=True)
        a = max(a, t)
        if b <= a:
            continue
        if inventory not in PHONE_TO_VISEME:
            raise ConfigError(f"unknown phone inventory {inventory!r}")
        if normalise_phone(label, inventory) in LINKS[inventory]:
            # a link, not a phone: the lips go on from the phone before it (a pause at the very start)
            if labels:
                ends[-1] = b
            else:
                add("sil", resolve("sil", available), a, b, gap=True)
            t = b
            continue
        if normalise_phone(label, inventory) not in PHONE_TO_VISEME[inventory]:
            unknown.append(label)
        v = viseme_of(label, inventory, default=UNKNOWN_PHONE_VISEME)
        r = resolve(v, available)
        substituted += r != v
        add(label, r, a, b)
        t = b
    if not labels:
        raise ConfigError("the phones have no duration")
    return Target(
        labels=tuple(labels),
        visemes=np.array(vis, dtype=np.int16),
        starts_s=np.array(starts),
        ends_s=np.array(ends),
        unknown=tuple(unknown),
        substituted=substituted,
    )


def pause_anchors(visemes: np.ndarray) -> np.ndarray:
    """(T,) int8: -1 for a leading pause, +1 for a trailing pause, else 0 (concat's ``anchored``)."""
    out = np.zeros(len(visemes), dtype=np.int8)
    sil = VISEME_ID["sil"]
    if len(visemes) > 1 and visemes[0] == sil:
        out[0] = -1
    if len(visemes) > 1 and visemes[-1] == sil:
        out[-1] = 1
    return out


ENSEMBLE_GAIN = 1.2
"""Default articulation-range gain of an ``n_best`` > 1 ensemble (chosen on the val split, see
:meth:`UnitSynthesizer.synthesize`)."""


class UnitSynthesizer:
    """Unit-selection visual speech from one corpus (the graph is built once; thread-safe reads).

    rest: (D,) the frame vector of the face at rest (the neutral face: its PCA coefficients and
    zero mouth parameters, :meth:`realtime_core.synthesis.corpus.StoredCorpus.rest_frame`), the
    centre an ensemble's articulation range is restored around; None = the zero vector.

    closure: how every /p b m/ is made to close (:mod:`realtime_core.synthesis.closure`); None = the
    selected motion as it is. Needs a ``mouth_open`` dim and closing PBM tokens in the corpus (else off)."""

    def __init__(
        self,
        corpus: MotionCorpus,
        config: SearchConfig | None = None,
        *,
        rest: np.ndarray | None = None,
        closure: ClosureConfig | None = ClosureConfig(),
    ) -> None:
        self.corpus = corpus
        self.graph: UnitGraph = build_graph(corpus, config or SearchConfig())
        self.rest = np.zeros(corpus.n_dims) if rest is None else np.asarray(rest, dtype=np.float64)
        if self.rest.shape != (corpus.n_dims,):
            raise ConfigError(f"rest must be ({corpus.n_dims},) like a corpus frame, got {self.rest.shape}")
        self.available = corpus.visemes_present()
        self._sentence = corpus.phone_sentence()
        self._coefficient_map: np.ndarray | None = None  # fitted on first use (text + recording only)
        self.closure = closure
        self._mouth_open = corpus.dim_names.index("mouth_open") if "mouth_open" in corpus.dim_names else None
        self._closed = closed_pose(corpus, self._mouth_open) if closure and self._mouth_open is not None else None

    def target(self, phones: Sequence[tuple[str, float, float]], inventory: str) -> Target:
        return make_target(phones, inventory, self.available)

    def synthesize(
        self,
        phones: Sequence[tuple[str, float, float]],
        inventory: str,
        *,
        n_frames: int | None = None,
        n_best: int = 1,
        exclude: Sequence[str] = (),
        ensemble_gain: float = ENSEMBLE_GAIN,
        rest_pauses: RestPauses | None = None,
    ) -> UnitSynthesis:
        """Motion for ``phones`` (labels of ``inventory``: "arpabet", "espeak-en", "espeak-es").

        n_best: 1 = the paper (one unit sequence). k > 1 averages the warped motion of k unit
        sequences, each searched with the sentences of the previous ones excluded: recorded
        tokens of the same phones vary from one sentence to the next, and their mean (all warped
        onto the same target phones, so closures and openings stay aligned) follows an unseen
        token better than any one of them. Stops early when no further sequence exists. The mean
        of tokens that differ in timing and extent moves less than any one of them (mouth_open's
        standard deviation about 0.89 of the real one with ten), so the ensemble's deviation from
        the rest face is multiplied by ``ensemble_gain`` (1 = the plain mean; the default restores
        the range, chosen on the val split: docs/unit_selection.md). One sequence is never scaled.

        exclude: corpus sentence ids never to use (a leave-one-out evaluation of a corpus sentence).

        rest_pauses: for a synthesiser's phones (no in-breath before them), the leading and trailing
        pauses eased to the rest pose (:mod:`realtime_core.synthesis.rest`, :attr:`rest`); None = the
        recorded pauses as selected (phones aligned on a real recording, whose in-breath is real)."""
        if not isinstance(n_best, int) or n_best < 1:
            raise ConfigError(f"n_best must be an integer >= 1, got {n_best!r}")
        if not 0 < ensemble_gain <= 4:
            raise ConfigError(f"ensemble_gain must be in (0, 4], got {ensemble_gain!r}")
        target = self.target(phones, inventory)
        anchors = pause_anchors(target.visemes)
        sels: list[Selection] = []
        skip = set(exclude)
        banned = np.isin(self._sentence, [i for i, sid in enumerate(self.corpus.sentence_ids) if sid in skip])
        total = None
        for k in range(n_best):
            try:
                sel = select_units(
                    self.graph, target.visemes, target.durations_s, banned=banned if banned.any() else None
                )
            except NoPathError:
                if k == 0:
                    raise
                break
            frames = concatenate(
                self.corpus,
                sel.states,
                target.starts_s,
                target.ends_s,
                parent=self.graph.parent,
                n_frames=n_frames,
                fps=FPS,
                anchored=anchors,
            )
            total = frames if total is None else total + frames
            sels.append(sel)
            if k + 1 < n_best:
                banned |= np.isin(self._sentence, np.unique(self._sentence[sel.states]))
        assert total is not None
        frames = total / len(sels)
        if len(sels) > 1 and ensemble_gain != 1.0:
            frames = self.rest + ensemble_gain * (frames - self.rest)
        # after averaging and the gain: an ensemble smears closures most (docs/unit_selection.md)
        frames = self._close(frames, target)
        if rest_pauses is not None:
            frames = ease_to_rest(frames, target.visemes, target.starts_s, target.ends_s, self.rest, rest_pauses)
        return UnitSynthesis(frames=frames, target=target, selection=sels[0], alternatives=tuple(sels[1:]))

    def with_recording(
        self, result: UnitSynthesis, audio_params: np.ndarray, config: RecordingBlend = RecordingBlend()
    ) -> np.ndarray:
        """Text + recording: ``result.frames`` (n, K + 4) with the audio-driven model's parameters
        ``audio_params`` (m, 4) at 30 fps from the same recording mixed in, most in the leading pause
        (:mod:`realtime_core.synthesis.recording`). Only for phones aligned on a real recording
        (the in-breath before speech is in the audio, not in the text)."""
        if self._coefficient_map is None:
            self._coefficient_map = param_to_coefficient_map(self.corpus)
        tgt = result.target
        w = region_weights(tgt.visemes, tgt.starts_s, tgt.ends_s, len(result.frames), config)
        # the audio-driven model's lips, mixed in, reopen some closures: close them again
        return self._close(blend_recording(result.frames, audio_params, w, self._coefficient_map), tgt)

    def _close(self, frames: np.ndarray, target: Target) -> np.ndarray:
        """frames (n, D) with every /p b m/ of ``target`` closed (:mod:`realtime_core.synthesis.closure`)."""
        if self.closure is None or self._closed is None or self._mouth_open is None:
            return frames
        return close_bilabials(
            frames,
            target.visemes,
            target.starts_s,
            target.ends_s,
            self._closed,
            mouth_open_dim=self._mouth_open,
            config=self.closure,
        )
