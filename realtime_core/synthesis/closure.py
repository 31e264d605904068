"""Bilabial closures: the lips meet inside every /p b m/ of a unit-selection output.

Recorded units do not always close: 16 % of the corpus's own /p b m/ tokens never bring mouth_open
below 0.03 IOD inside their phone label (the label and the lips disagree by a frame or two, or the
talker barely closed), and a warped, crossfaded or averaged unit closes less still. A viewer reads
an open /m/ as a mispronunciation, so every target phone of the PBM class is pulled towards the
corpus's **closed pose** (:func:`closed_pose`: the mean frame at the lips' minimum of the corpus's
closing PBM tokens, landmark coefficients and mouth parameters together), by just enough that
mouth_open reaches ``ClosureConfig.mouth_open_iod`` at the phone's most closed frame(s), and the
pull fades in and out over a few frames (the junctions' smoothstep blend). The whole frame vector is blended,
so the lips in the landmark frames close with the parameter. A phone that already closes is left
as it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import FPS, MotionCorpus
from realtime_core.synthesis.search import crossfade
from realtime_core.synthesis.visemes import VISEME_ID

CLOSED_IOD = 0.03
"""mouth_open (IOD) at or below which a /p b m/ counts as closed (:func:`bilabials_closed`)."""

BILABIAL = VISEME_ID["PBM"]


@dataclass(frozen=True, kw_only=True)
class ClosureConfig:
    """mouth_open_iod: the opening the pulled frames reach (IOD, <= :data:`CLOSED_IOD`);
    hold_frames: frames on each side of a phone's most closed frame (inside the phone) that reach
    it too; ramp_frames: frames over which the pull fades in before and out after (smoothstep).

    Defaults chosen on the val split (docs/unit_selection.md, "Bilabial closures"): 0.01 IOD puts the
    landmarks' inner lips as close as the corpus's own closed frames (a landmark gap of ~0.017 IOD,
    their median 0.016); a longer hold or ramp closes as often but costs more r(mouth_open), as the
    real lips close for only a frame or two."""

    mouth_open_iod: float = 0.01
    hold_frames: int = 0
    ramp_frames: int = 1

    def __post_init__(self) -> None:
        if not 0.0 <= self.mouth_open_iod <= CLOSED_IOD:
            raise ConfigError(f"mouth_open_iod must be in [0, {CLOSED_IOD}], got {self.mouth_open_iod!r}")
        if not (isinstance(self.hold_frames, int) and 0 <= self.hold_frames <= 5):
            raise ConfigError(f"hold_frames must be an integer in 0..5, got {self.hold_frames!r}")
        if not (isinstance(self.ramp_frames, int) and 1 <= self.ramp_frames <= 10):
            raise ConfigError(f"ramp_frames must be an integer in 1..10, got {self.ramp_frames!r}")


def phone_frame_spans(starts_s: np.ndarray, ends_s: np.ndarray, n_frames: int, fps: float = FPS) -> np.ndarray:
    """(T, 2) int64 [first, stop) output frames (frame k at k / fps) inside each phone; a phone
    shorter than a frame gets the frame nearest its midpoint. Clipped to ``n_frames``."""
    starts_s, ends_s = np.asarray(starts_s, np.float64), np.asarray(ends_s, np.float64)
    lo = np.ceil(starts_s * fps - 1e-9).astype(np.int64)
    hi = np.ceil(ends_s * fps - 1e-9).astype(np.int64)
    mid = np.rint(0.5 * (starts_s + ends_s) * fps).astype(np.int64)
    empty = hi <= lo
    lo, hi = np.where(empty, mid, lo), np.where(empty, mid + 1, hi)
    lo = np.clip(lo, 0, max(n_frames - 1, 0))
    return np.stack([lo, np.clip(hi, lo + 1, n_frames)], axis=1)


def bilabials_closed(
    mouth_open: np.ndarray, visemes: np.ndarray, starts_s: np.ndarray, ends_s: np.ndarray, fps: float = FPS
) -> np.ndarray:
    """(n_pbm,) bool: whether mouth_open (n,) IOD at ``k / fps`` comes to <= :data:`CLOSED_IOD`
    inside each PBM target phone (visemes, starts_s, ends_s: (T,) as in a synthesis target)."""
    mouth_open = np.asarray(mouth_open, np.float64)
    spans = phone_frame_spans(starts_s, ends_s, len(mouth_open), fps)[np.asarray(visemes) == BILABIAL]
    return np.array([mouth_open[a:b].min() <= CLOSED_IOD for a, b in spans], dtype=bool)


def closed_pose(corpus: MotionCorpus, mouth_open_dim: int) -> np.ndarray | None:
    """(D,) the corpus's closed lips: the mean frame at mouth_open's minimum inside each recorded
    PBM phone that closes (<= :data:`CLOSED_IOD`); None when no recorded /p b m/ closes."""
    picks = []
    fo = corpus.frame_offsets
    sent = corpus.phone_sentence()
    for q in np.flatnonzero(np.asarray(corpus.phone_visemes) == BILABIAL):
        s = sent[q]
        n = int(fo[s + 1] - fo[s])
        ((a, b),) = phone_frame_spans(corpus.phone_start_s[q : q + 1], corpus.phone_end_s[q : q + 1], n)
        f = corpus.frames[fo[s] + a : fo[s] + b]
        k = int(np.argmin(f[:, mouth_open_dim]))
        if f[k, mouth_open_dim] <= CLOSED_IOD:
            picks.append(f[k])
    if not picks:
        return None
    return np.mean(np.asarray(picks, dtype=np.float64), axis=0)


def close_bilabials(
    frames: np.ndarray,
    visemes: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    closed: np.ndarray,
    *,
    mouth_open_dim: int,
    config: ClosureConfig = ClosureConfig(),
    fps: float = FPS,
) -> np.ndarray:
    """frames (n, D) at ``k / fps`` with every PBM target phone (visemes, starts_s, ends_s: (T,))
    pulled towards ``closed`` (D,) so that mouth_open (column ``mouth_open_dim``, IOD) reaches
    ``config.mouth_open_iod`` at the phone's most closed frame and the ``hold_frames`` beside it
    (inside the phone), fading over ``ramp_frames`` on each side. Returns a new (n, D) array."""
    frames = np.asarray(frames, np.float64)
    closed = np.asarray(closed, np.float64)
    n = len(frames)
    mo, mo_closed = frames[:, mouth_open_dim], float(closed[mouth_open_dim])
    target = config.mouth_open_iod
    if mo_closed >= target:
        raise ConfigError(f"the closed pose's mouth_open {mo_closed:.4f} is not below the target {target}")
    weight = np.zeros(n)
    k = np.arange(n)
    for a, b in phone_frame_spans(starts_s, ends_s, n, fps)[np.asarray(visemes) == BILABIAL]:
        c = a + int(np.argmin(mo[a:b]))
        h0, h1 = max(a, c - config.hold_frames), min(b, c + config.hold_frames + 1)
        # the blend weight that brings each held frame exactly to the target opening
        need = float(np.max(np.clip((mo[h0:h1] - target) / (mo[h0:h1] - mo_closed), 0.0, 1.0)))
        if need <= 0.0:
            continue
        # 1 over the held frames, the junctions' blend down to 0 at ramp_frames + 1 frames outside them
        dist = np.maximum(np.maximum(h0 - k, k - (h1 - 1)), 0)
        shape = crossfade(1.0 - dist / (config.ramp_frames + 1))
        weight = np.maximum(weight, need * shape)
    return frames + weight[:, None] * (closed - frames)
