"""A learned readout after the HMM inversion (issue 10): eq. 7's estimate, refined.

Why: eq. 7 is the posterior-weighted average of per-component regressions fitted for the joint
likelihood, not for the estimate's error; the estimate shrinks towards the mean and follows the lips
with some sluggishness. A small map, fitted on the train split's live-path trajectories against the
real lips (``training.readout``), corrects it from what the frame already has:

    phi_t = [x_t, x_{t-1}, ..., x_{t-K+1}, a_t, p_t]
    y_t = W2^T relu(W1^T phi_t + b1) + b2     (hidden > 0)     or     y_t = W^T phi_t + b   (linear)

with ``x`` the inverter's raw eq. 7 estimate ``(Dv,)``, ``K`` = ``taps`` (causal: past outputs only;
frames before the utterance's first repeat it), ``a_t`` the frame's centred audio context vector
``(Da,)`` (the lookahead the frame already waited for; left out unless ``audio``) and ``p_t`` its
posteriors (``posteriors``: "state" ``(N,)``, "component" ``(N*M,)`` or "none"). No delay is added and
no frame is held back, so the readout is streaming, chunk-invariant and equal to :meth:`Readout.apply`
on the whole track. The output stage (closed-pose floor, closure band) runs after it.

Cost per frame: two small matrix-vector products (the shipped 5 taps, Da = 84, N = 16 and 192 hidden
units: about 23k multiply-adds). With the compiled kernel the readout runs inside the inverter's lag-0
kernel (:func:`realtime_core.inversion.compiled.filter_rows`) on this stream's feature vector, with the
component posteriors eq. 7 already computed; inputs under 1e-30 in size (most posterior features) and
hidden units the ReLU zeroed are skipped, which changes nothing beyond rounding.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from realtime_core.errors import ModelFormatError

POSTERIOR_KINDS = ("none", "state", "component")
_ARRAYS = ("w1", "b1", "w2", "b2")


@dataclass(frozen=True, kw_only=True, eq=False)
class Readout:
    """taps: K >= 1 causal taps of the raw estimate; audio: include the centred audio row; posteriors:
    "none", "state" or "component"; n_states, n_mix, n_audio, n_visual: the model's sizes.
    w1 ``(n_features, H)``, b1 ``(H,)``, w2 ``(H, n_visual)``, b2 ``(n_visual,)`` float64: a hidden ReLU layer
    of H units; H = 0 (w1 ``(n_features, 0)``, b1 ``(0,)``, w2 ``(n_features, n_visual)``) is a linear map.
    Input scaling is folded into w1 (or w2). metadata: JSON-able fit details."""

    taps: int
    audio: bool
    posteriors: str
    n_states: int
    n_mix: int
    n_audio: int
    n_visual: int
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.posteriors not in POSTERIOR_KINDS:
            raise ModelFormatError(f"readout posteriors must be one of {POSTERIOR_KINDS}, got {self.posteriors!r}")
        if not 1 <= self.taps <= 64:
            raise ModelFormatError(f"readout taps must be in 1..64, got {self.taps}")
        arrays = {k: _flush_subnormals(np.array(getattr(self, k), dtype=np.float64, order="C")) for k in _ARRAYS}
        hidden = arrays["b1"].shape[0] if arrays["b1"].ndim == 1 else -1
        f, dv = self.n_features, self.n_visual
        want = {
            "w1": (f, hidden),
            "b1": (hidden,),
            "w2": (hidden if hidden else f, dv),
            "b2": (dv,),
        }
        for k, shape in want.items():
            if arrays[k].shape != shape or not np.all(np.isfinite(arrays[k])):
                raise ModelFormatError(f"readout {k} must be finite with shape {shape}, got {arrays[k].shape}")
            object.__setattr__(self, k, arrays[k])

    @property
    def hidden(self) -> int:
        """Hidden units (0 = linear)."""
        return int(self.b1.shape[0])

    @property
    def n_post(self) -> int:
        """Posterior features per frame (0, N or N*M)."""
        return {"none": 0, "state": self.n_states, "component": self.n_states * self.n_mix}[self.posteriors]

    @property
    def n_features(self) -> int:
        return self.taps * self.n_visual + (self.n_audio if self.audio else 0) + self.n_post

    def posterior_features(self, component_post: np.ndarray) -> np.ndarray:
        """Component posteriors ``(..., N*M)`` -> this readout's posterior features ``(..., n_post)``."""
        return posterior_features(self.posteriors, component_post, self.n_states, self.n_mix)

    def features(self, raw: np.ndarray, component_post: np.ndarray, audio: np.ndarray) -> np.ndarray:
        """One utterance's features ``(T, n_features)`` from raw eq. 7 estimates ``(T, Dv)``, component
        posteriors ``(T, N*M)`` and centred audio rows ``(T, Da)`` (the frames in order, from the first)."""
        return readout_features(
            raw,
            np.asarray(audio, dtype=np.float64)[:, : self.n_audio if self.audio else 0],
            self.posterior_features(component_post),
            taps=self.taps,
        )

    def map(self, phi: np.ndarray) -> np.ndarray:
        """Features ``(T, n_features)`` -> estimates ``(T, Dv)``."""
        if self.hidden:
            return np.maximum(phi @ self.w1 + self.b1, 0.0) @ self.w2 + self.b2
        return phi @ self.w2 + self.b2

    def apply(self, raw: np.ndarray, component_post: np.ndarray, audio: np.ndarray) -> np.ndarray:
        """The readout over a whole utterance ``(T, Dv)``; equals :class:`ReadoutStream` frame by frame."""
        if len(raw) == 0:
            return np.zeros((0, self.n_visual))
        return self.map(self.features(raw, component_post, audio))

    def recentred(self, shift: np.ndarray) -> Readout:
        """This readout for audio rows centred ``shift (Da,)`` further (``a' = a - shift``): the same output for the
        same frame. Why: the inverter centres the audio row at its ``ConditionalForm.center``, a mean of the HMM's
        audio means and weights, so adapting those moved every row the readout saw (by up to 0.26 per feature with
        the shipped default model and 48 s of GRID s1), a side effect of an expansion point. The shift is folded into
        the first layer's bias: ``W^T a = W^T a' + W^T shift``."""
        if not self.audio:
            return self
        shift = np.asarray(shift, dtype=np.float64)
        if shift.shape != (self.n_audio,):
            raise ModelFormatError(f"readout centre shift must have shape ({self.n_audio},), got {shift.shape}")
        a0 = self.taps * self.n_visual
        if self.hidden:
            return replace(self, b1=self.b1 + shift @ self.w1[a0 : a0 + self.n_audio])
        return replace(self, b2=self.b2 + shift @ self.w2[a0 : a0 + self.n_audio])

    def stream(self, *, kernel: str = "numpy") -> ReadoutStream:
        """Per-session state (the past taps) for the live path (kernel: "numba" compiled or "numpy")."""
        return ReadoutStream(self, kernel=kernel)


def _flush_subnormals(a: np.ndarray) -> np.ndarray:
    """``a`` (a fresh contiguous float64 array) with its subnormal values (0 < |x| < 2.2e-308) set to 0.

    Why: the L2 penalty drives the weights of a dead ReLU unit towards 0 until they are subnormal, and
    arithmetic on subnormals is many times slower on x86: two such units of the fourth-round default
    readout made every live frame about 15 us slower. Their contribution is below 1e-307, so this changes
    no estimate."""
    a[(a != 0) & (np.abs(a) < np.finfo(np.float64).tiny)] = 0.0
    return a


def posterior_features(kind: str, component_post: np.ndarray, n_states: int, n_mix: int) -> np.ndarray:
    """Component posteriors ``(..., N*M)`` -> the posterior features of ``kind`` (POSTERIOR_KINDS):
    themselves, the state posteriors ``(..., N)`` (summed over mixtures) or none ``(..., 0)``."""
    if kind == "component":
        return component_post
    if kind == "state":
        return component_post.reshape(*component_post.shape[:-1], n_states, n_mix).sum(axis=-1)
    return component_post[..., :0]


def readout_features(raw: np.ndarray, audio: np.ndarray, post: np.ndarray, *, taps: int) -> np.ndarray:
    """``[x_t .. x_{t-K+1}, a_t, p_t]`` per frame of one utterance, ``(T, F)``: raw ``(T, Dv)``,
    audio ``(T, Da')`` and posteriors ``(T, P)`` (either may have 0 columns). Frames before the first
    repeat it (the utterance's first estimate is all the readout knows of its past)."""
    T = len(raw)
    padded = np.concatenate([np.repeat(raw[:1], taps - 1, axis=0), raw]) if T else raw
    cols = [padded[taps - 1 - k : taps - 1 - k + T] for k in range(taps)]
    return np.concatenate([*cols, audio, post], axis=1)


class ReadoutStream:
    """The readout of one stream: ``step(raw (Dv,), component_post (N*M,), audio (Da,)) -> (Dv,)``.

    kernel: "numba" (one compiled call per frame, :func:`realtime_core.inversion.compiled.readout_step`)
    or "numpy" (the reference below; the two agree to rounding)."""

    def __init__(self, readout: Readout, *, kernel: str = "numpy") -> None:
        self.readout = readout
        ro = readout
        nx = ro.taps * ro.n_visual
        self._phi = np.zeros(ro.n_features)  # [taps | audio | posteriors], filled in place
        self._hist = self._phi[:nx].reshape(ro.taps, ro.n_visual)
        self._a0, self._a1 = nx, nx + (ro.n_audio if ro.audio else 0)
        self._post_kind = POSTERIOR_KINDS.index(ro.posteriors)
        self.started = False
        """Whether a frame of this utterance went through (before the first, the taps repeat it)."""
        self._compiled: Any = None
        if kernel == "numba":
            # Imported here: numba's import is paid only by streams that use it.
            from realtime_core.inversion.compiled import readout_step

            self._compiled = readout_step

    def kernel_arrays(self) -> tuple[np.ndarray, ...]:
        """``(phi, sizes, w1, b1, w2, b2)``: this stream's feature vector (updated in place) and the
        readout's sizes ``[taps, a0, a1, post_kind, n_mix]`` and weights, for the compiled inverter that
        runs the readout inside its lag-0 kernel (the inverter then sets :attr:`started`)."""
        ro = self.readout
        sizes = np.array([ro.taps, self._a0, self._a1, self._post_kind, ro.n_mix], dtype=np.int64)
        return self._phi, sizes, ro.w1, ro.b1, ro.w2, ro.b2

    def reset(self) -> None:
        """A new utterance: forget the past taps."""
        self.started = False

    def step(self, raw: np.ndarray, component_post: np.ndarray, audio: np.ndarray) -> np.ndarray:
        ro = self.readout
        if self._compiled is not None:
            started, self.started = self.started, True
            y: np.ndarray = self._compiled(
                np.asarray(raw, dtype=np.float64),
                np.asarray(component_post, dtype=np.float64),
                audio,
                self._phi,
                started,
                ro.taps,
                self._a0,
                self._a1,
                self._post_kind,
                ro.n_mix,
                ro.w1,
                ro.b1,
                ro.w2,
                ro.b2,
            )
            return y
        h = self._hist
        if not self.started:
            h[:] = raw  # frames before the first repeat it (as readout_features pads)
            self.started = True
        else:
            h[1:] = h[:-1].copy()
            h[0] = raw
        if ro.audio:
            self._phi[self._a0 : self._a1] = audio
        if ro.n_post:
            self._phi[self._a1 :] = ro.posterior_features(component_post)
        if ro.hidden:
            return np.maximum(self._phi @ ro.w1 + ro.b1, 0.0) @ ro.w2 + ro.b2
        return self._phi @ ro.w2 + ro.b2


def encode_readout(ro: Readout) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(JSON config, arrays) of a readout for a model file."""
    config = {
        "taps": ro.taps,
        "audio": ro.audio,
        "posteriors": ro.posteriors,
        "n_states": ro.n_states,
        "n_mix": ro.n_mix,
        "n_audio": ro.n_audio,
        "n_visual": ro.n_visual,
        "metadata": ro.metadata,
    }
    return config, {f"readout_{k}": getattr(ro, k) for k in _ARRAYS}


def decode_readout(config: dict[str, Any], arrays: dict[str, np.ndarray]) -> Readout:
    """The readout of a model file's config and arrays (:class:`ModelFormatError` naming the problem)."""
    for k in _ARRAYS:
        if f"readout_{k}" not in arrays:
            raise ModelFormatError(f"model archive has a readout but lacks the array 'readout_{k}'")
    try:
        return Readout(
            taps=int(config["taps"]),
            audio=bool(config["audio"]),
            posteriors=str(config["posteriors"]),
            n_states=int(config["n_states"]),
            n_mix=int(config["n_mix"]),
            n_audio=int(config["n_audio"]),
            n_visual=int(config["n_visual"]),
            metadata=dict(config.get("metadata", {})),
            **{k: arrays[f"readout_{k}"] for k in _ARRAYS},
        )
    except (KeyError, TypeError) as exc:
        raise ModelFormatError(f"invalid readout configuration: {exc}") from None
