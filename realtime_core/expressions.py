"""Facial expressions at run time (paper 002 Sec. VI-B, eq. 2 with an intensity), sans-I/O.

What an expression is
---------------------
There is no real expressive audio-visual recording in this project, so each expression is a
*prototype* built from ARKit face units: FACS's prototypes of the basic emotions (EMFACS, Friesen &
Ekman 1983) written in ARKit's names (:data:`EXPRESSION_RECIPES`): smile = AU6 + AU12 (cheek raiser,
lip-corner puller), sad = AU1 + AU4 + AU15 + AU17, surprise = AU1 + AU2 + AU5 + AU26, anger = AU4 +
AU5 + AU7 + AU23 (+ AU9). On the built-in head these recipes are its own ARKit morph targets; what
they do to the four mouth parameters (:data:`realtime_core.fitted_maps.EXPRESSION_PARAMS`, IOD) was
measured on that head by ``facecast fit-maps``. A user's own expressive recordings replace the
prototypes through ``facecast extract`` -> Expression MUs (:mod:`realtime_core.motion_units`).

How speech and an expression combine (at intensity ``alpha`` in [0, 1])
----------------------------------------------------------------------
``p = p_speech + alpha * dp_k`` for ``upper_lip_raise, lip_stretch, lip_corner_depress`` (eq. 2: the
expression adds its own deformation to the utterance's), so speech excursions are kept as they are:
a rounded /u/ under a smile is narrower than the smile by exactly as much as without it. The inner-lip
gap is the exception: ``mouth_open = m + alpha * dp_k[open] * g(m)`` with ``g(m) = clip(m / open_ref,
0, 1)``: an expression never parts lips that speech holds closed (bilabial closures /p b m/ stay
closed under any expression), and scales an open mouth only where speech opens it. Each parameter then
saturates: the sum goes no further than the furthest of :data:`SPEECH_REACH` (how far speech goes), the frame's
speech and the expression alone, so a smile on a spread /i/ is as wide as the smile or the /i/, not their sum
(excursions the other way, a rounded /u/ under a smile, are kept as they are). Summed, a full smile on speech's
ends reached lip_stretch 0.25 with the corners at -0.19, where rigs that hold every speech pose and the smile
alone folded (docs/animation.md, "Which poses, and why").

Scheduling
----------
:class:`ExpressionTrack` holds expression changes stamped with media time (seconds of session audio);
every expression's intensity eases from where it is to its new target over ``ease_s`` seconds
(smoothstep), so a change of expression cross-fades. Intensities are a pure function of the media
time of a frame, so any chunking of the audio gives the same frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.errors import ConfigError, RealtimeCoreError

NEUTRAL = "neutral"

EXPRESSION_RECIPES = MappingProxyType(
    {
        "smile": MappingProxyType(
            {
                "mouthSmileLeft": 0.5,
                "mouthSmileRight": 0.5,
                "cheekSquintLeft": 0.5,
                "cheekSquintRight": 0.5,
                "eyeSquintLeft": 0.2,
                "eyeSquintRight": 0.2,
            }
        ),
        "sad": MappingProxyType(
            {
                "browInnerUp": 0.7,
                "browDownLeft": 0.2,
                "browDownRight": 0.2,
                "mouthFrownLeft": 0.6,
                "mouthFrownRight": 0.6,
                "mouthShrugLower": 0.2,
            }
        ),
        "surprise": MappingProxyType(
            {
                "browInnerUp": 0.7,
                "browOuterUpLeft": 0.7,
                "browOuterUpRight": 0.7,
                "eyeWideLeft": 0.6,
                "eyeWideRight": 0.6,
                "jawOpen": 0.2,
            }
        ),
        "anger": MappingProxyType(
            {
                "browDownLeft": 0.7,
                "browDownRight": 0.7,
                "eyeSquintLeft": 0.4,
                "eyeSquintRight": 0.4,
                "eyeWideLeft": 0.15,
                "eyeWideRight": 0.15,
                "mouthPressLeft": 0.5,
                "mouthPressRight": 0.5,
                "noseSneerLeft": 0.3,
                "noseSneerRight": 0.3,
            }
        ),
    }
)
"""Expression -> ARKit weights at full intensity (EMFACS prototypes in ARKit names)."""

EXPRESSIONS: tuple[str, ...] = tuple(EXPRESSION_RECIPES)
"""Known expressions (besides "neutral"), in the column order of every intensity array."""


def face_shapes(name: str) -> dict[str, float]:
    """The ARKit weights of expression ``name``'s recipe at full intensity that the four mouth parameters do not
    carry: every shape but ``mouth*`` and ``jaw*`` (cheeks, eyes, brows, nose), which a renderer adds from a head's
    own ARKit targets beside the expressed parameters; ``{}`` for "neutral". Raises :class:`ExpressionError`."""
    if name == NEUTRAL:
        return {}
    if name not in EXPRESSION_RECIPES:
        raise ExpressionError(f"unknown expression {name!r}; known: {[NEUTRAL, *EXPRESSIONS]}")
    return {k: w for k, w in EXPRESSION_RECIPES[name].items() if not k.startswith(("mouth", "jaw"))}


OPEN_REF_IOD = 0.05
"""Inner-lip gap (IOD) above which an expression's own mouth-opening change applies fully."""

SPEECH_REACH: tuple[tuple[float, float], ...] = ((-0.084, 0.054), (-0.123, 0.094), (0.0, 0.465), (-0.103, 0.039))
"""IOD, (low, high) per parameter in VISUAL_PARAMS order: how far speech takes the mouth, the ends of what the
shipped models produce on real speech or of the articulatory targets, whichever is further (measured by
``scripts/measure_param_box.py``; docs/animation.md, "Which poses, and why"). An expression on speech saturates
there (:func:`add_expression`); the rig checks test each parameter alone at these ends
(:data:`realtime_core.face.checks.SINGLE_POSES`)."""

_OPEN = VISUAL_PARAMS.index("mouth_open")


class ExpressionError(RealtimeCoreError, ValueError):
    """An expression request is invalid (unknown name, intensity outside [0, 1], bad time)."""


@dataclass(frozen=True, kw_only=True)
class ExpressionConfig:
    """ease_s: seconds an intensity change takes (0 = instant); max_ahead_s: how far ahead of the
    newest frame a change may be scheduled; late_tolerance_s: how far behind the newest frame a change
    may be stamped (network jitter) before it is refused as being in the past."""

    ease_s: float = 0.3
    max_ahead_s: float = 600.0
    late_tolerance_s: float = 0.5

    def __post_init__(self) -> None:
        if not 0 <= self.ease_s <= 10:
            raise ConfigError(f"ease_s must be in 0..10 s, got {self.ease_s}")
        if not 0 < self.max_ahead_s <= 86400:
            raise ConfigError(f"max_ahead_s must be in (0, 86400] s, got {self.max_ahead_s}")
        if not 0 <= self.late_tolerance_s <= 10:
            raise ConfigError(f"late_tolerance_s must be in 0..10 s, got {self.late_tolerance_s}")


def parse_expression(spec: str) -> tuple[str, float, float]:
    """``"smile:0.7@1.2"`` -> ("smile", 0.7, 1.2); intensity defaults to 1 and time to 0 (``"sad"``,
    ``"sad@2"``, ``"sad:0.5"``). Raises :class:`ExpressionError` naming the problem."""
    text = spec.strip()
    at = 0.0
    if "@" in text:
        text, t = text.split("@", 1)
        try:
            at = float(t)
        except ValueError:
            raise ExpressionError(f"expression {spec!r}: time after '@' must be seconds, got {t!r}") from None
    intensity = 1.0
    if ":" in text:
        text, i = text.split(":", 1)
        try:
            intensity = float(i)
        except ValueError:
            raise ExpressionError(f"expression {spec!r}: intensity after ':' must be a number, got {i!r}") from None
    check_request(text, intensity)
    if not np.isfinite(at) or at < 0:
        raise ExpressionError(f"expression {spec!r}: time must be >= 0 s, got {at}")
    return text, intensity, at


def check_request(name: object, intensity: object) -> tuple[str, float]:
    """Validate a name and an intensity; returns them (intensity as float)."""
    if not isinstance(name, str) or (name != NEUTRAL and name not in EXPRESSIONS):
        raise ExpressionError(f"unknown expression {name!r} (known: {', '.join((NEUTRAL, *EXPRESSIONS))})")
    if isinstance(intensity, bool) or not isinstance(intensity, (int, float)) or not 0 <= intensity <= 1:
        raise ExpressionError(f"expression intensity must be a number in [0, 1], got {intensity!r}")
    return name, float(intensity)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3 - 2 * u)


class ExpressionTrack:
    """Expression changes on the media clock -> per-frame intensities ``(n, len(EXPRESSIONS))``."""

    def __init__(self, config: ExpressionConfig = ExpressionConfig()) -> None:
        self.config = config
        self._events: list[tuple[float, np.ndarray]] = []  # (media time s, target intensities (E,))

    def reset(self) -> None:
        self._events.clear()

    def copy(self, config: ExpressionConfig | None = None) -> ExpressionTrack:
        """The same scheduled changes, with ``config`` (default: this track's)."""
        out = ExpressionTrack(self.config if config is None else config)
        out._events = list(self._events)
        return out

    @property
    def events(self) -> list[tuple[float, dict[str, float]]]:
        """Scheduled changes: (time s, {expression: target intensity})."""
        return [(t, dict(zip(EXPRESSIONS, map(float, v)))) for t, v in self._events]

    def schedule(self, name: str, intensity: float, at_s: float, *, now_s: float = 0.0) -> None:
        """Ease ``name`` to ``intensity`` (every other expression to 0) from media time ``at_s``.

        ``now_s``: media time of the newest frame already produced; ``at_s`` may not be more than
        ``late_tolerance_s`` before it (those frames are gone) nor more than ``max_ahead_s`` after it.
        "neutral" (any intensity) eases every expression to 0. Changes are kept in time order."""
        name, intensity = check_request(name, intensity)
        if isinstance(at_s, bool) or not isinstance(at_s, (int, float)) or not np.isfinite(at_s):
            raise ExpressionError(f"expression time must be a number of seconds, got {at_s!r}")
        if at_s < now_s - self.config.late_tolerance_s:
            raise ExpressionError(f"expression time {at_s:.6g} s is in the past (media time is now {now_s:.3f} s)")
        if at_s > now_s + self.config.max_ahead_s:
            raise ExpressionError(
                f"expression time {at_s:.6g} s is more than {self.config.max_ahead_s:g} s ahead "
                f"of the media time {now_s:.3f} s"
            )
        target = np.zeros(len(EXPRESSIONS))
        if name != NEUTRAL:
            target[EXPRESSIONS.index(name)] = intensity
        t = max(float(at_s), 0.0)
        self._events.append((t, target))
        self._events.sort(key=lambda e: e[0])  # stable: equal times keep their arrival order

    def intensities(self, times_s: np.ndarray) -> np.ndarray:
        """``(n,)`` media times -> ``(n, len(EXPRESSIONS))`` intensities in [0, 1]."""
        t = np.asarray(times_s, dtype=np.float64).reshape(-1)
        out = np.zeros((t.size, len(EXPRESSIONS)))
        level = np.zeros(len(EXPRESSIONS))  # intensity at the start of the current event
        ease = self.config.ease_s
        for i, (t0, target) in enumerate(self._events):
            t1 = self._events[i + 1][0] if i + 1 < len(self._events) else np.inf
            u = _smoothstep((t - t0) / ease) if ease > 0 else (t >= t0).astype(float)
            mask = (t >= t0) & (t < t1)
            out[mask] = level + (target - level) * u[mask, None]
            # Where the next change starts from: this ramp evaluated at its time.
            if np.isfinite(t1):
                u1 = float(_smoothstep(np.array((t1 - t0) / ease))) if ease > 0 else 1.0
                level = level + (target - level) * u1
        return out


def apply_expression(params: np.ndarray, alpha: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Speech parameters ``(n, 4)`` under intensities ``alpha (n, E)`` of expressions whose parameter
    changes are ``offsets (E, 4)`` (IOD) -> ``(n, 4)`` (see the module docstring for the rule)."""
    p = np.asarray(params, dtype=np.float64)
    a = np.asarray(alpha, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != len(VISUAL_PARAMS) or a.shape != (len(p), offsets.shape[0]):
        raise ExpressionError(
            f"params (n, 4) and intensities (n, {offsets.shape[0]}) expected, got {p.shape}, {a.shape}"
        )
    return add_expression(p, a @ offsets)


def add_expression(params: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Speech parameters ``(n, 4)`` plus an expression's change ``delta (n, 4)`` (IOD, already scaled by the
    intensity): added as it is, except that the change of ``mouth_open`` is scaled by
    ``clip(mouth_open / OPEN_REF_IOD, 0, 1)`` so lips that speech holds closed stay closed. Used with fixed
    offsets (:func:`apply_expression`) and with the per-frame changes of paper 002's second-stage MLPs
    (:class:`realtime_core.mapping.expression.ExpressionMapper`)."""
    p = np.asarray(params, dtype=np.float64)
    d = np.array(delta, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != len(VISUAL_PARAMS) or d.shape != p.shape:
        raise ExpressionError(f"params (n, 4) and changes (n, 4) expected, got {p.shape}, {d.shape}")
    d[:, _OPEN] *= np.clip(p[:, _OPEN] / OPEN_REF_IOD, 0.0, 1.0)
    # Saturation: the sum goes no further than the furthest of speech's reach, this frame's speech and the
    # expression alone. A full smile (lip_stretch +0.159, corners -0.086) on speech's own ends reached lip_stretch
    # 0.25 and corners -0.19; rigs that every speech pose and the smile alone leave clean folded there (the
    # built-in head's own ARKit targets, whose fold no repair reaches: mouthUpperUp 1.0 with mouthSmile 0.75).
    reach = np.asarray(SPEECH_REACH, dtype=np.float64).T  # (2, 4)
    lo = np.minimum(np.minimum(reach[0], p), d)
    hi = np.maximum(np.maximum(reach[1], p), d)
    return np.clip(p + d, lo, hi)


def expression_arkit(alpha: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """Intensities ``(n, E)`` -> the expressions' own ARKit weights ``(n, len(names))`` (recipes scaled)."""
    a = np.asarray(alpha, dtype=np.float64)
    index = {n: i for i, n in enumerate(names)}
    m = np.zeros((len(EXPRESSIONS), len(names)))
    for k, e in enumerate(EXPRESSIONS):
        for shape, w in EXPRESSION_RECIPES[e].items():
            m[k, index[shape]] = w
    return a @ m
