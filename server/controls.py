"""Session controls: a registry of named control handlers and the per-frame state they set.

A control message ``{"type": "control", NAME: VALUE, ...}`` is applied atomically: every ``NAME`` is
looked up in :data:`CONTROLS`, its handler validates ``VALUE`` and writes it into a draft copy of the
session's :class:`ControlState`; only if every handler accepts does the draft replace the state
(a rejected message changes nothing). :meth:`ControlState.apply` is what a session runs on each
frame's parameters after the model.

The session's expression (:mod:`realtime_core.expressions`) is one: ``expression`` schedules an
eased change on the media clock (validated against the session's media time, passed in as
``now_s``), ``expression_ease_s`` sets the easing; :meth:`ControlState.expression_at` gives the
intensities of frames, which the session applies after :meth:`ControlState.apply`.

To add a control, add a field to :class:`ControlState` with its effect in
:meth:`ControlState.apply` and its public form in :meth:`ControlState.describe`, and register a
handler with :func:`control`. No I/O here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, TypeGuard

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.expressions import ExpressionError, ExpressionTrack, check_request
from server.errors import ControlError, reason_value

MAX_GAIN = 10.0
MAX_SMOOTHING_MS = 1000.0
MAX_EASE_S = 10.0


@dataclass
class ControlState:
    """gains: (4,) float64 factor per visual parameter; smoothing_ms: one-pole low-pass time
    constant (0 = off); _smoothed: the filter's last output (4,) (None before the first frame)."""

    gains: np.ndarray = field(default_factory=lambda: np.ones(len(VISUAL_PARAMS)))
    smoothing_ms: float = 0.0
    expressions: ExpressionTrack = field(default_factory=ExpressionTrack)
    now_s: float = 0.0  # media time of the next frame when a message is applied (for expression times)
    _smoothed: np.ndarray | None = None

    def apply(self, row: np.ndarray, fps: float) -> np.ndarray:
        """One frame's raw parameters (4,) -> the controlled parameters (4,): gain, then smoothing."""
        p = row * self.gains
        if self.smoothing_ms > 0 and self._smoothed is not None:
            a = math.exp(-1000.0 / (fps * self.smoothing_ms))
            p = a * self._smoothed + (1.0 - a) * p
        self._smoothed = p
        return p

    def expression_at(self, times_s: np.ndarray) -> np.ndarray | None:
        """Frames' media times ``(n,)`` -> expression intensities ``(n, len(EXPRESSIONS))``, or None when no
        expression was ever set (the frames are speech only)."""
        return self.expressions.intensities(times_s) if self.expressions.events else None

    def describe(self) -> dict:
        """The JSON form sent in acks and session descriptions."""
        return {
            "gain": dict(zip(VISUAL_PARAMS, map(float, self.gains))),
            "smoothing_ms": self.smoothing_ms,
            "expression": [{"at": t, "intensity": v} for t, v in self.expressions.events[-8:]],
            "expression_ease_s": self.expressions.config.ease_s,
        }


ControlHandler = Callable[[ControlState, object], None]
"""Validate one control's value and write it into the draft state; raise ControlError to refuse."""

CONTROLS: dict[str, ControlHandler] = {}
"""Control name -> handler (insertion order = the order error messages list them)."""


def control(name: str) -> Callable[[ControlHandler], ControlHandler]:
    """Register ``handler`` for the control ``name`` (a decorator)."""

    def register(handler: ControlHandler) -> ControlHandler:
        CONTROLS[name] = handler
        return handler

    return register


def _number(value: object) -> TypeGuard[float]:
    """A finite JSON number. An integer is always finite: math.isfinite of one beyond a float's range (a
    400-digit JSON integer) raised OverflowError, which the session took for an internal error."""
    if isinstance(value, bool):
        return False
    return isinstance(value, int) or (isinstance(value, float) and math.isfinite(value))


def _as_float(value: Any, what: str) -> Any:
    """A JSON integer as a float (ControlError beyond a float's range); any other value as it is."""
    if isinstance(value, int) and not isinstance(value, bool):
        try:
            return float(value)
        except OverflowError:
            raise ControlError(f"expression: {what} {reason_value(value)} is out of range") from None
    return value


@control("gain")
def _gain(state: ControlState, value: object) -> None:
    """gain: {parameter name: factor in [0, 10]}; parameters not named keep their gain."""
    if not isinstance(value, dict) or not value:
        raise ControlError("gain must be an object {parameter: factor}")
    gains = state.gains.copy()
    for name, g in value.items():
        if name not in VISUAL_PARAMS:
            raise ControlError(f"gain: unknown parameter {reason_value(name)} (known: {', '.join(VISUAL_PARAMS)})")
        if not _number(g) or not 0 <= g <= MAX_GAIN:
            raise ControlError(f"gain for {name} must be a number in 0..{MAX_GAIN:g}, got {reason_value(g)}")
        gains[VISUAL_PARAMS.index(name)] = float(g)
    state.gains = gains


@control("smoothing_ms")
def _smoothing(state: ControlState, value: object) -> None:
    """smoothing_ms: time constant of a one-pole low-pass on the parameters, 0..1000 ms (0 = off)."""
    if not _number(value) or not 0 <= value <= MAX_SMOOTHING_MS:
        raise ControlError(f"smoothing_ms must be a number in 0..{MAX_SMOOTHING_MS:g}, got {reason_value(value)}")
    state.smoothing_ms = float(value)


@control("expression")
def _expression(state: ControlState, value: object) -> None:
    """expression: {"name": smile|sad|surprise|anger|neutral, "intensity": 0..1 (default 1), "at": media time
    s (default the next frame)}; a time in the past or absurdly far ahead is refused."""
    if not isinstance(value, dict) or "name" not in value:
        raise ControlError('expression must be an object {"name": ..., "intensity": 0..1, "at": seconds}')
    unknown = set(value) - {"name", "intensity", "at"}
    if unknown:
        raise ControlError(f"expression: unknown field(s) {sorted(unknown)} (known: name, intensity, at)")
    try:
        # JSON integers as floats: the track's np.isfinite raised TypeError on one beyond int64 (an internal
        # error), and its reasons quoted every digit of a huge one.
        at, intensity = (_as_float(value.get(k, d), k) for k, d in (("at", state.now_s), ("intensity", 1.0)))
        name, intensity = check_request(value["name"], intensity)
        state.expressions.schedule(name, intensity, at, now_s=state.now_s)
    except ExpressionError as exc:
        raise ControlError(f"expression: {exc}") from None


@control("expression_ease_s")
def _expression_ease(state: ControlState, value: object) -> None:
    """expression_ease_s: seconds an expression change takes, 0..10."""
    if not _number(value) or not 0 <= value <= MAX_EASE_S:
        raise ControlError(f"expression_ease_s must be a number in 0..{MAX_EASE_S:g}, got {reason_value(value)}")
    state.expressions = state.expressions.copy(replace(state.expressions.config, ease_s=float(value)))


def apply_controls(state: ControlState, msg: dict, *, now_s: float | None = None) -> ControlState:
    """A control message -> the new state (a copy); ControlError (naming the control) if any part is refused.

    now_s: media time of the session's next frame (expression times are checked against it)."""
    # A copy of exactly what handlers write (not copy.deepcopy: a tenth of a millisecond per
    # message, which a client sending thousands of controls would take from the event loop).
    draft = replace(
        state,
        gains=state.gains.copy(),
        expressions=state.expressions.copy(),
        _smoothed=None if state._smoothed is None else state._smoothed.copy(),
    )
    if now_s is not None:
        draft.now_s = float(now_s)
    for key, value in msg.items():
        if key == "type":
            continue
        handler = CONTROLS.get(key)
        if handler is None:
            raise ControlError(f"unknown control {reason_value(key)} (known: {', '.join(CONTROLS)})")
        handler(draft, value)
    return draft
