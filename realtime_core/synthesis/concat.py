"""Time warping and junction smoothing of selected units (seed 001 Sec. 3.8): selection -> 30 fps motion.

Theory of operation
-------------------
**Warping.** Target phone ``m`` spans ``[S_m, E_m)`` seconds; its selected corpus phone ``q_m``
spans ``[s, e)`` on its sentence's clock. An output instant ``t`` in the target phone is mapped
linearly, ``tau = (t - S_m) / (E_m - S_m)``, to the source instant ``s + tau (e - s)``, and the
recorded motion is read there (linear interpolation between recorded frames). Every unit is
therefore stretched or squeezed to exactly the target phone's duration, and consecutive phones of
one recorded stretch stay continuous because their boundaries map onto each other.

**Junction smoothing.** Where the path jumps after phone ``m`` (``q_{m+1}`` is not the recorded
successor of ``q_m``), the output over phone ``m`` crossfades from ``q_m``'s motion into the motion
of ``parent(q_{m+1})`` (same viseme, warped onto the same interval) with the smoothstep weight
``w(tau)`` of :func:`realtime_core.synthesis.search.crossfade`: it starts exactly on ``q_m`` and
ends exactly where the recorded motion leading into ``q_{m+1}`` ends, with zero slope on the
weight at both ends. The unit search prices exactly this blended trajectory (its acceleration
cost C), so the smoothness the search optimised is the smoothness rendered. A jump whose
``q_{m+1}`` has no recorded parent (a sentence's first phone) is joined by the same crossfade into
``q_{m+1}``'s first frame.

**Pauses keep their recorded pace.** Lips move before speech starts (an in-breath, the opening
for the first sound) and settle after it ends, at a pace tied to the speech, not to the length
of the pause. Stretching a whole recorded pause onto a longer target pause would slow those
gestures and move them away from the speech. So a pause before speech (the first target phone)
is read backwards from its end at the recorded pace, and a pause after speech (the last) forwards
from its start; what the target pause has beyond the recording holds the recording's far end
value, and a shorter target pause cuts the far end off. Pauses inside an utterance, with speech
on both sides, are warped linearly like phones.

Output frames are at ``k / 30`` s, ``k = 0 .. ceil(E_last * 30) - 1``; instants before the first
target phone or after the last hold the first/last value.
"""

from __future__ import annotations

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import FPS, MotionCorpus, sample_motion
from realtime_core.synthesis.search import crossfade


def warp_sources(
    corpus: MotionCorpus,
    states: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    times_s: np.ndarray,
    anchored: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For output instants ``times_s`` (n,): (target phone index (n,), tau in [0, 1] (n,), source
    time (n,) on the clock of the selected phone's sentence).

    anchored: (T,) int8 per target phone: 0 = linear warp; -1 = keep the recorded pace counted
    back from the phone's end (a pause before speech); +1 = counted on from its start (a pause
    after speech); the recording's far end is held or cut (see the module doc)."""
    m = np.clip(np.searchsorted(ends_s, times_s, side="right"), 0, len(states) - 1)
    span = ends_s[m] - starts_s[m]
    tau = np.clip((times_s - starts_s[m]) / span, 0.0, 1.0)
    q = states[m]
    s0, s1 = corpus.phone_start_s[q], corpus.phone_end_s[q]
    src = s0 + tau * (s1 - s0)
    if anchored is not None:
        a = np.asarray(anchored)[m]
        src = np.where(a < 0, np.clip(s1 - (ends_s[m] - times_s), s0, s1), src)
        src = np.where(a > 0, np.clip(s0 + (times_s - starts_s[m]), s0, s1), src)
    return m, tau, src


def concatenate(
    corpus: MotionCorpus,
    states: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    *,
    parent: np.ndarray,
    n_frames: int | None = None,
    fps: float = FPS,
    anchored: np.ndarray | None = None,
) -> np.ndarray:
    """Motion of the selected units warped onto the target phones and smoothed at the junctions.

    states: (T,) corpus phone per target phone; starts_s, ends_s: (T,) target phone boundaries in
    seconds (contiguous: ends_s[m] == starts_s[m + 1], strictly increasing); parent: (N,) the
    graph's parent array; n_frames: output length (default ``ceil(ends_s[-1] * fps)``); anchored:
    (T,) per phone 0 / -1 / +1, see :func:`warp_sources` (default: all linear).
    Returns (n_frames, D) float64 at instants ``k / fps``.
    """
    states = np.asarray(states, dtype=np.int64)
    starts_s, ends_s = np.asarray(starts_s, dtype=np.float64), np.asarray(ends_s, dtype=np.float64)
    if states.ndim != 1 or starts_s.shape != states.shape or ends_s.shape != states.shape or len(states) == 0:
        raise ConfigError("states, starts_s and ends_s must be equal-length non-empty (T,) arrays")
    if np.any(ends_s <= starts_s) or np.any(np.abs(starts_s[1:] - ends_s[:-1]) > 1e-9):
        raise ConfigError("target phones must be contiguous with positive durations")
    if n_frames is None:
        n_frames = int(np.ceil(ends_s[-1] * fps - 1e-9))
    t = np.arange(n_frames) / fps
    m, tau, src = warp_sources(corpus, states, starts_s, ends_s, t, anchored)
    sent = corpus.phone_sentence()
    out = sample_motion(corpus, sent[states[m]], src)
    # junctions: phone m is followed by a jump
    nxt = np.append(states[1:], -1)
    jump = (np.arange(len(states)) < len(states) - 1) & (parent[np.maximum(nxt, 0)] != states)
    blend = jump[m]
    if blend.any():
        mb = m[blend]
        nq = nxt[mb]
        p = parent[nq]
        has_p = p >= 0
        # the parent's motion warped onto the same target interval; a parentless successor is
        # represented by its own first instant
        pq = np.where(has_p, p, nq)
        p_src = np.where(
            has_p,
            corpus.phone_start_s[pq] + tau[blend] * (corpus.phone_end_s[pq] - corpus.phone_start_s[pq]),
            corpus.phone_start_s[pq],
        )
        other = sample_motion(corpus, sent[pq], p_src)
        w = crossfade(tau[blend])[:, None]
        out[blend] = (1.0 - w) * out[blend] + w * other
    return out
