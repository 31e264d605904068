"""Session controls: a registry of named control handlers and the per-frame state they set.

A control message ``{"type": "control", NAME: VALUE, ...}`` is applied atomically: every ``NAME`` is
looked up in :data:`CONTROLS`, its handler validates ``VALUE`` and writes it into a draft copy of the
session's :class:`ControlState`; only if every handler accepts does the draft replace the state
(a rejected message changes nothing). :meth:`ControlState.apply` is what a session runs on each
frame's parameters after the model.

To add a control (e.g. expressions), add a field to :class:`ControlState` with its effect in
:meth:`ControlState.apply` and its public form in :meth:`ControlState.describe`, and register a
handler with :func:`control`. No I/O here.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from realtime_core import VISUAL_PARAMS
from server.errors import ControlError

MAX_GAIN = 10.0
MAX_SMOOTHING_MS = 1000.0


@dataclass
class ControlState:
    """gains: (4,) float64 factor per visual parameter; smoothing_ms: one-pole low-pass time
    constant (0 = off); _smoothed: the filter's last output (4,) (None before the first frame)."""

    gains: np.ndarray = field(default_factory=lambda: np.ones(len(VISUAL_PARAMS)))
    smoothing_ms: float = 0.0
    _smoothed: np.ndarray | None = None

    def apply(self, row: np.ndarray, fps: float) -> np.ndarray:
        """One frame's raw parameters (4,) -> the controlled parameters (4,): gain, then smoothing."""
        p = row * self.gains
        if self.smoothing_ms > 0 and self._smoothed is not None:
            a = math.exp(-1000.0 / (fps * self.smoothing_ms))
            p = a * self._smoothed + (1.0 - a) * p
        self._smoothed = p
        return p

    def describe(self) -> dict:
        """The JSON form sent in acks and session descriptions."""
        return {"gain": dict(zip(VISUAL_PARAMS, map(float, self.gains))), "smoothing_ms": self.smoothing_ms}


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


def _number(value: object) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


@control("gain")
def _gain(state: ControlState, value: object) -> None:
    """gain: {parameter name: factor in [0, 10]}; parameters not named keep their gain."""
    if not isinstance(value, dict) or not value:
        raise ControlError("gain must be an object {parameter: factor}")
    gains = state.gains.copy()
    for name, g in value.items():
        if name not in VISUAL_PARAMS:
            raise ControlError(f"gain: unknown parameter {name!r} (known: {', '.join(VISUAL_PARAMS)})")
        if not _number(g) or not 0 <= g <= MAX_GAIN:
            raise ControlError(f"gain for {name} must be a number in 0..{MAX_GAIN:g}, got {g!r}")
        gains[VISUAL_PARAMS.index(name)] = float(g)
    state.gains = gains


@control("smoothing_ms")
def _smoothing(state: ControlState, value: object) -> None:
    """smoothing_ms: time constant of a one-pole low-pass on the parameters, 0..1000 ms (0 = off)."""
    if not _number(value) or not 0 <= value <= MAX_SMOOTHING_MS:
        raise ControlError(f"smoothing_ms must be a number in 0..{MAX_SMOOTHING_MS:g}, got {value!r}")
    state.smoothing_ms = float(value)


def apply_controls(state: ControlState, msg: dict) -> ControlState:
    """A control message -> the new state (a copy); ControlError (naming the control) if any part is refused."""
    draft = copy.deepcopy(state)
    for key, value in msg.items():
        if key == "type":
            continue
        handler = CONTROLS.get(key)
        if handler is None:
            raise ControlError(f"unknown control {key!r} (known: {', '.join(CONTROLS)})")
        handler(draft, value)
    return draft
