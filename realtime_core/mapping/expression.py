"""Paper 002's second-stage mappers at run time (Sec. VI-B): UMUPs -> UMUPs + EMUPs, one MLP per expression.

Theory of operation
-------------------
The audio-to-UMUP mapper (:mod:`realtime_core.mapping.mlp`) estimates a frame's Utterance MU
parameters ``c_0``. For expression ``k`` the paper trains one small MLP ``Upsilon_k`` (one hidden
layer; 30 units) that maps those estimated UMUPs to the expressive frame's ``(c'_0, c_k)``: the UMUPs
as the expression changes them, and the Expression MUPs of eq. 2. Both are turned into the four mouth
parameters every output of facecast speaks:

* ``c'_0`` through the same affine UMUP readout as the speech (``R c + r``, fitted on the train frames);
* ``c_k`` through ``P_k c_k + q_k``: the four parameters the Expression MUs' landmark displacement
  ``M_k c_k + m_k0`` makes at the speaker's neutral face (fitted by training over the expression's
  range, ``training.mu_expressions.emu_readout``; the EMUs live outside the UMUs' span, where the UMUP
  readout sees nothing).

The expression's change of the four parameters in a frame is then
``delta_k = R (c'_0 - c_0) + P_k c_k + q_k``, and a session at intensities ``alpha_k`` (eq. 2's
``alpha_k``, eased in [0, 1]) adds ``sum_k alpha_k delta_k`` to the speech parameters it serves, through
:func:`realtime_core.expressions.add_expression` (which never parts lips that speech holds closed).
So the expression's effect follows the speech frame by frame, as the paper's second stage does,
instead of the fixed per-expression offset used when a mapper emits no MUPs (the HMM).

Weights are float64 here; the per-frame cost is two small products per active expression.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.errors import ModelFormatError
from realtime_core.expressions import EXPRESSIONS


def _dot(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``x (n, i) @ w.T`` for ``w (j, i)`` with the same rounding for every row whatever ``n`` (einsum's own
    loop, not BLAS, whose blocking depends on the batch): a stream equals the batch bit for bit."""
    return np.einsum("ni,ji->nj", x, w)


STAGE_ARRAYS = ("w1", "b1", "w2", "b2", "emu_params", "emu_bias")
"""The arrays of one :class:`ExpressionStage` (a mapper file stores them as ``expr_<name>_<array>``)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class ExpressionStage:
    """``Upsilon_k`` of one expression (tanh hidden layer, input/output standardisation folded in).

    w1 ``(H, A0)``, b1 ``(H,)``, w2 ``(A0 + Ak, H)``, b2 ``(A0 + Ak,)``: estimated UMUPs -> (UMUPs, EMUPs);
    emu_params ``(4, Ak)`` and emu_bias ``(4,)``: EMUPs -> their change of the four mouth parameters (IOD).
    """

    name: str
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    emu_params: np.ndarray
    emu_bias: np.ndarray

    def __post_init__(self) -> None:
        if self.name not in EXPRESSIONS:
            raise ModelFormatError(f"expression stage {self.name!r}: unknown expression (known: {EXPRESSIONS})")
        arrays = {k: np.asarray(getattr(self, k), dtype=np.float64) for k in STAGE_ARRAYS}
        w1, b1, w2, b2, pe, qe = (arrays[k] for k in STAGE_ARRAYS)
        h = w1.shape[0] if w1.ndim == 2 else -1
        ak = pe.shape[1] if pe.ndim == 2 else -1
        ok = (
            w1.ndim == 2
            and b1.shape == (h,)
            and w2.ndim == 2
            and w2.shape[1] == h
            and b2.shape == (w2.shape[0],)
            and pe.shape == (len(VISUAL_PARAMS), ak)
            and qe.shape == (len(VISUAL_PARAMS),)
            and w2.shape[0] == w1.shape[1] + ak
        )
        if not ok:
            raise ModelFormatError(
                f"expression stage {self.name!r}: shapes w1 {w1.shape}, b1 {b1.shape}, w2 {w2.shape}, b2 {b2.shape}, "
                f"emu_params {pe.shape}, emu_bias {qe.shape} do not fit (H, A0), (H,), (A0 + Ak, H), (A0 + Ak,), "
                "(4, Ak), (4,)"
            )
        for k, a in arrays.items():
            if not np.isfinite(a).all():
                raise ModelFormatError(f"expression stage {self.name!r}: {k} contains NaN or inf")
            a.setflags(write=False)
            object.__setattr__(self, k, a)

    @property
    def n_umups(self) -> int:
        return int(self.w1.shape[1])

    def __call__(self, umup: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Estimated UMUPs ``(n, A0)`` -> (expressive UMUPs ``(n, A0)``, EMUPs ``(n, Ak)``)."""
        y = _dot(np.tanh(_dot(umup, self.w1) + self.b1), self.w2) + self.b2
        return y[:, : self.n_umups], y[:, self.n_umups :]


@dataclass(frozen=True, kw_only=True, eq=False)
class ExpressionMapper:
    """The second stages of one speech model: readout ``(4, A0)`` and readout_bias ``(4,)`` (the UMUP
    readout of the speech mapper) and one :class:`ExpressionStage` per expression it was trained for."""

    readout: np.ndarray
    readout_bias: np.ndarray
    stages: Mapping[str, ExpressionStage]

    def __post_init__(self) -> None:
        r = np.asarray(self.readout, dtype=np.float64)
        rb = np.asarray(self.readout_bias, dtype=np.float64)
        if r.ndim != 2 or r.shape[0] != len(VISUAL_PARAMS) or rb.shape != (len(VISUAL_PARAMS),):
            raise ModelFormatError(
                f"expression mapper: readout must be (4, A0) with bias (4,), got {r.shape}, {rb.shape}"
            )
        for name, st in self.stages.items():
            if name != st.name or st.n_umups != r.shape[1]:
                raise ModelFormatError(f"expression stage {name!r} does not fit a readout of {r.shape[1]} UMUPs")
        r.setflags(write=False)
        rb.setflags(write=False)
        object.__setattr__(self, "readout", r)
        object.__setattr__(self, "readout_bias", rb)
        object.__setattr__(self, "stages", dict(self.stages))

    @property
    def n_umups(self) -> int:
        return int(self.readout.shape[1])

    def stage_delta(self, name: str, umup: np.ndarray) -> np.ndarray:
        """``delta_k (n, 4)``: expression ``name``'s change of the four parameters for UMUPs ``(n, A0)``."""
        c0 = np.asarray(umup, dtype=np.float64)
        c0e, ck = self.stages[name](c0)
        st = self.stages[name]
        return _dot(c0e - c0, self.readout) + _dot(ck, st.emu_params) + st.emu_bias

    def deltas(self, umup: np.ndarray, alpha: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """``sum_k alpha_k delta_k`` ``(n, 4)`` for UMUPs ``(n, A0)`` and intensities ``alpha (n, E)`` (columns:
        :data:`realtime_core.expressions.EXPRESSIONS`); an expression without a stage adds its fixed
        parameter change ``fallback[k] (4,)`` (:data:`realtime_core.fitted_maps.EXPRESSION_PARAMS`)."""
        a = np.asarray(alpha, dtype=np.float64)
        c0 = np.asarray(umup, dtype=np.float64)
        if c0.ndim != 2 or c0.shape[1] != self.n_umups or a.shape != (len(c0), len(EXPRESSIONS)):
            raise ModelFormatError(
                f"UMUPs (n, {self.n_umups}) and intensities (n, {len(EXPRESSIONS)}) expected, got {c0.shape}, {a.shape}"
            )
        out = np.zeros((len(c0), len(VISUAL_PARAMS)))
        for k, name in enumerate(EXPRESSIONS):
            col = a[:, k]
            if not col.any():
                continue
            d = self.stage_delta(name, c0) if name in self.stages else np.broadcast_to(fallback[k], out.shape)
            out += col[:, None] * d
        return out


def express(
    params: np.ndarray, alpha: np.ndarray, *, mups: np.ndarray | None = None, mapper: ExpressionMapper | None = None
) -> np.ndarray:
    """Served speech parameters ``(n, 4)`` under expression intensities ``alpha (n, E)`` -> ``(n, 4)``.

    With a model's second stages (``mapper``) and the frames' estimated UMUPs (``mups (n, A0)``), each
    expression's change is ``Upsilon_k``'s per frame (the paper's path); otherwise the fixed change each
    expression makes on the built-in head (:data:`realtime_core.fitted_maps.EXPRESSION_PARAMS`). Either
    way through :func:`realtime_core.expressions.add_expression`."""
    from realtime_core.expressions import add_expression
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    a = np.asarray(alpha, dtype=np.float64)
    if mapper is not None and mups is not None:
        delta = mapper.deltas(mups, a, EXPRESSION_PARAMS)
    else:
        delta = _dot(a, EXPRESSION_PARAMS.T)
    return add_expression(params, delta)
