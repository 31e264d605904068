"""The one interface every audio-to-visual mapper of the live path satisfies.

A *visual mapper* turns the front end's audio features ``o_a (k, Da)`` (MFCCs with ``tc`` frames
of context on each side, see :mod:`realtime_core.features`) into visual parameter rows. It is a
streaming stage: ``push`` returns the rows now final, ``flush`` ends the utterance and returns the
rest, ``reset`` starts a new one; the output is the same for any chunking of the input.

Implementations: the HMM inverter (:class:`realtime_core.inversion.StreamingInverter`, paper 000
eq. 7) and the GMM-selected MLP bank (:class:`realtime_core.mapping.mlp.StreamingMlpMapper`,
paper 002 Sec. VI-A). A *speech model* is what :class:`realtime_core.pipeline.SpeechToParams` and
a server session need: a front end, a sample rate and fresh mappers (:class:`SpeechModel`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from realtime_core.features import FrontEnd, FrontEndConfig

MAPPER_KINDS: tuple[str, ...] = ("hmm", "mlp")
"""Values of ``--mapper`` and of a session's mapper choice."""


@runtime_checkable
class VisualMapper(Protocol):
    """``push(o_a (k, Da)) -> (j, Dv) float64`` rows now final; ``flush()``; ``reset()``.

    ``lag_frames``: rows the mapper holds back beyond the front end's context (0 = none)."""

    @property
    def lag_frames(self) -> int: ...

    def push(self, oa: np.ndarray) -> np.ndarray: ...

    def flush(self) -> np.ndarray: ...

    def reset(self) -> None: ...


@runtime_checkable
class SpeechModel(Protocol):
    """A trained audio-to-visual model: the front end it was trained with and fresh mappers.

    ``frontend`` and ``visual_names`` are read-only properties here so frozen dataclasses (whose
    fields are read-only) satisfy the protocol."""

    @property
    def frontend(self) -> FrontEndConfig: ...

    @property
    def visual_names(self) -> tuple[str, ...]: ...

    @property
    def sample_rate_hz(self) -> int: ...

    def front_end(self, *, kernel: str = "numba") -> FrontEnd: ...

    def visual_mapper(self, *, lag: int = 0, dtype: str = "float32") -> VisualMapper: ...
