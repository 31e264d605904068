"""Streaming HMM inversion: the live path (paper Sec. 4.2 and 6.3).

Theory of operation
-------------------
Once audio up to frame ``t + tc`` has arrived, the front end releases ``o_a,t``. The
inverter then

1. evaluates every (state, mixture) component's **audio-marginal** likelihood
   ``c_jk N(o_a,t; mu_a, Sigma_aa)`` with one matrix-vector product over the shared
   quadratic features of the frame, and the conditional means ``m_jk(o_a,t)`` with a
   second, smaller one (see :mod:`realtime_core.inversion.conditional`);
2. advances the normalised forward recursion (filtered state posteriors);
3. outputs ``o~_v,t`` by eq. 7 under the component posteriors.

With ``lag = L > 0`` the output for frame t waits for frames up to ``t + L`` and uses
fixed-lag smoothed posteriors (a backward pass over the last L frames), adding
``L x 33 ms`` of delay. ``flush()`` ends the utterance and smooths the frames still
waiting with the backward pass from the last frame, so with ``L >= T`` the stream equals
the batch audio-posterior estimate (forward-backward over the whole utterance), and with
``L = 0`` it equals batch forward filtering.

The matrix-vector product runs in float32 by default (``dtype``); the small per-component
arithmetic after it stays in float64.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dposv as _posv

from realtime_core.errors import ConfigError, InvalidFeaturesError, StreamStateError
from realtime_core.inversion.conditional import ConditionalForm
from realtime_core.output import KNEE, OutputStage
from realtime_core.readout import Readout, ReadoutStream

SKIP_POSTERIOR = 1e-30
"""Components whose normalised posterior is below this are left out of eq. 7's weighted sums (both
kernels). Their total share is under ``N M x 1e-30``, some fourteen orders below float64's resolution,
so the estimate is the same to rounding; and cast to float32 they would be subnormal numbers, which
this CPU multiplies some hundred times slower than normal ones (at N=28, M=5 on speech-like input
about 90 of the 140 posteriors are: the float32 product over them cost ~30 us per frame). The
compiled readout skips its inputs under this size alike. (Compiled into the numba kernels: their
on-disk cache keys on compiled.py, so a change here needs that cache cleared.)"""


@dataclass(frozen=True, kw_only=True)
class StreamConfig:
    """lag: extra frames of fixed-lag smoothing (0 = pure filtering, lowest delay).
    dtype: "float32" or "float64" for the per-frame matrix-vector product.
    kernel: "numba" (default: the per-frame steps compiled, :mod:`realtime_core.inversion.compiled`)
    or "numpy" (the reference implementation; the two agree to rounding).
    likelihood_scale: exponent kappa on the audio likelihoods (None = the model's own, else
    1). The 77 stacked dims share 7 overlapping frames, so the raw likelihoods are far
    over-confident; kappa < 1 softens the posteriors, which then average several components'
    regressions instead of jumping between them (the "acoustic scale" of speech recognisers).
    """

    lag: int = 0
    dtype: str = "float32"
    likelihood_scale: float | None = None
    kernel: str = "numba"

    def __post_init__(self) -> None:
        if self.kernel not in ("numba", "numpy"):
            raise ConfigError(f"kernel must be 'numba' or 'numpy', got {self.kernel!r}")
        if not 0 <= self.lag <= 100000:
            raise ConfigError(f"lag must be in 0..100000 frames, got {self.lag}")
        if self.dtype not in ("float32", "float64"):
            raise ConfigError(f"dtype must be 'float32' or 'float64', got {self.dtype!r}")
        if self.likelihood_scale is not None and not 0 < self.likelihood_scale <= 1:
            raise ConfigError(f"likelihood_scale must be in (0, 1], got {self.likelihood_scale}")


@dataclass(frozen=True, eq=False)
class StreamPlan:
    """The read-only per-frame matrices of a streaming inverter, derived once from a
    :class:`ConditionalForm` and a :class:`StreamConfig`.

    Every live session of a model can share one plan: besides saving memory, the sessions then
    read the same ~1-2 MB of matrices, which stay in cache instead of each session evicting the
    others' copies. quad: ``(C, K)`` pre-scaled by ``-kappa/2``; const: ``(N, M)``; G: ``(C, Dv*Da)``;
    h, phi_flat: ``(C, Dv)``, ``(C, Dv*Dv)``; A: ``(N, N)``; start: ``(N,)``; center: ``(Da,)``.
    """

    quad: np.ndarray
    const: np.ndarray
    center: np.ndarray
    G: np.ndarray
    h: np.ndarray
    phi_flat: np.ndarray
    A: np.ndarray
    start: np.ndarray
    i0: np.ndarray
    i1: np.ndarray

    @classmethod
    def build(cls, form: ConditionalForm, config: StreamConfig) -> StreamPlan:
        dt = np.dtype(config.dtype)
        kappa = 1.0 if config.likelihood_scale is None else config.likelihood_scale
        n, m, da, dv = form.n_states, form.n_mix, form.n_audio, form.n_visual
        c = n * m
        # Eq. 7 numerator: sum_c r_c Phi_c m_c(a) = (sum_c r_c G_c) a + sum_c r_c h_c with
        # G_c = Phi_c R_c and h_c = Phi_c reg0_c, so conditional means are never formed per frame.
        reg = form.reg.reshape(c, dv, da)
        i0, i1 = np.triu_indices(da)
        return cls(
            quad=np.ascontiguousarray(form.quad * (-0.5 * kappa), dtype=dt),
            # log c_jk - 0.5 kappa const_jk: the frame-independent part of each component's log-likelihood.
            const=(-0.5 * kappa * form.quad0).reshape(n, m) + form.log_weights,
            center=form.center.astype(dt),
            G=np.einsum("cij,cjk->cik", form.phi_v, reg).reshape(c, dv * da).astype(dt),
            h=np.einsum("cij,cj->ci", form.phi_v, form.reg0.reshape(c, dv)),
            phi_flat=form.phi_v.reshape(c, -1),
            A=np.exp(form.log_transmat),
            start=np.exp(form.log_startprob),
            i0=i0,
            i1=i1,
        )


class StreamingInverter:
    """``push(o_a (k, Da)) -> o_v (j, Dv) float64`` for the frames now final; ``flush()`` ends.

    plan: the shared read-only matrices (built from ``form`` and ``config`` when not given;
    it must have been built from the same two). output: the model's output stage
    (:class:`realtime_core.output.OutputStage`: closed-pose floor and closure band), applied to
    every emitted frame; None = raw eq. 7 estimates. readout: the model's learned readout
    (:mod:`realtime_core.readout`), applied to every emitted frame's eq. 7 estimate before the output
    stage, in emission order; None = none."""

    def __init__(
        self,
        form: ConditionalForm,
        *,
        config: StreamConfig = StreamConfig(),
        plan: StreamPlan | None = None,
        output: Callable[[np.ndarray], np.ndarray] | None = None,
        readout: Readout | None = None,
    ) -> None:
        self.form = form
        self._output = output
        self._readout: ReadoutStream | None = None if readout is None else readout.stream(kernel=config.kernel)
        self.config = config
        p = StreamPlan.build(form, config) if plan is None else plan
        self.plan = p
        self._quad, self._const, self._center = p.quad, p.const, p.center
        self._G, self._h, self._phi_flat, self._A, self._start = p.G, p.h, p.phi_flat, p.A, p.start
        self._i0, self._i1 = p.i0, p.i1
        self._nq = self._i0.size
        self._feat = np.empty(self._nq + form.n_audio, dtype=p.quad.dtype)  # per-session scratch
        self._da, self._dv = form.n_audio, form.n_visual
        self._n, self._m = form.n_states, form.n_mix
        self._filter_rows: Callable[..., tuple[np.ndarray, int]] | None = None
        if config.kernel == "numba":
            # Imported here: numba's import costs ~0.5 s, paid only by inverters that use it.
            from realtime_core.inversion import compiled

            self._forward_step = compiled.forward_step
            self._combine_step = compiled.combine_step
            self._filter_rows = compiled.filter_rows
            # The model's arrays every compiled forward step takes, in the kernels' order (fixed per inverter).
            self._step_model = (self._center, self._quad, self._const, self._feat, self._A)
            # The readout's and the output stage's arrays for the fused lag-0 kernel (0-length: none).
            ro = self._readout
            self._ro_args = (
                (np.zeros(0), np.zeros(0, dtype=np.int64), *(np.zeros((0, 0)), np.zeros(0)) * 2)
                if ro is None
                else ro.kernel_arrays()
            )
            self._out_args = (
                (output.floor, output.band, KNEE) if isinstance(output, OutputStage) else (np.zeros(0), 0.0, KNEE)
            )
            self._output_in_kernel = isinstance(output, OutputStage)
            self._forward = self._forward_compiled  # type: ignore[method-assign]
            self._raw = self._combine_raw  # type: ignore[method-assign]
        self.reset()

    @property
    def lag_frames(self) -> int:
        """Rows held back for fixed-lag smoothing (the :class:`realtime_core.mapping.VisualMapper` interface)."""
        return self.config.lag

    def reset(self) -> None:
        """Start a new utterance."""
        self._f: np.ndarray | None = None  # filtered posterior of the newest frame
        # (filtered, scaled b, within-state mix, centred audio) per frame not yet final
        self._pending: deque[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = deque()
        self._finished = False
        if self._readout is not None:
            self._readout.reset()

    def push(self, oa: np.ndarray) -> np.ndarray:
        if self._finished:
            raise StreamStateError("StreamingInverter.push() after flush(); call reset() first")
        oa = np.asarray(oa)
        if oa.ndim != 2 or oa.shape[1] != self._da:
            raise InvalidFeaturesError(f"audio features must be (k, {self._da}), got {oa.shape}")
        if not np.isfinite(np.add.reduce(oa, axis=None)):  # any NaN/inf makes the sum non-finite
            raise InvalidFeaturesError("audio features contain NaN or inf")
        if not self.config.lag and self._filter_rows is not None:
            return self._push_filter_compiled(oa)
        out = []
        if not self.config.lag:  # pure filtering: each frame is final at once, no queue
            for row in oa:
                f, _, mix, a = self._forward(row)
                out.append(self._combine(f, mix, a))
            return np.array(out).reshape(len(out), self._dv)
        for row in oa:
            self._pending.append(self._forward(row))
            if len(self._pending) > self.config.lag:
                out.append(self._emit_oldest())
        return np.array(out).reshape(len(out), self._dv)

    def flush(self) -> np.ndarray:
        if self._finished:
            raise StreamStateError("StreamingInverter.flush() called twice; call reset() first")
        self._finished = True
        if not self._pending:
            return np.zeros((0, self._dv))
        # One backward pass from the last frame over everything still waiting.
        items = list(self._pending)
        betas = [np.ones(self._n)]
        for _f, b, _, _ in reversed(items[1:]):
            beta = self._A @ (b * betas[-1])
            betas.append(beta / beta.sum())
        betas.reverse()
        out = [self._combine(f * beta, mix, cond) for (f, _, mix, cond), beta in zip(items, betas)]
        self._pending.clear()
        return np.array(out)

    def _forward(self, row: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        a = row.astype(self._feat.dtype) - self._center
        feat = self._feat
        np.multiply(a[self._i0], a[self._i1], out=feat[: self._nq])
        feat[self._nq :] = a
        logc = (self._quad @ feat).reshape(self._n, self._m) + self._const
        # One global shift (not per state) keeps this to a handful of numpy calls per frame.
        e = np.exp(logc - logc.max())
        b = e.sum(axis=1)  # state likelihoods, all scaled by the same factor (N,)
        mix = e / np.maximum(b, 1e-300)[:, None]  # within-state mixture posteriors (N, M)
        prior = self._start if self._f is None else self._f @ self._A
        f = prior * b
        total = f.sum()
        if not total > 0:  # every state impossible: restart the filter from the prior
            f = b / b.sum()
        else:
            f = f / total
        self._f = f
        return f, b, mix, a

    def _push_filter_compiled(self, oa: np.ndarray) -> np.ndarray:
        """Lag 0: all rows of a push in one compiled call (eq. 7, the readout and the output stage), then
        the row-wise path from a row it cannot solve."""
        assert self._filter_rows is not None  # set with kernel="numba"
        out = np.empty((len(oa), self._dv))
        prev = self._f
        ro = self._readout
        phi, sizes, w1, b1, w2, b2 = self._ro_args
        f, stop = self._filter_rows(
            oa,
            *self._step_model,
            self._start if prev is None else prev,
            prev is not None,
            self._start,
            self._G,
            self._h,
            self._phi_flat,
            out,
            phi,
            ro is not None and ro.started,
            sizes,
            w1,
            b1,
            w2,
            b2,
            *self._out_args,
        )
        done = len(oa) if stop < 0 else stop
        if done:
            self._f = f
            if ro is not None:
                ro.started = True
        if not self._output_in_kernel and self._output is not None:  # an output stage of another kind
            for t in range(done):
                out[t] = self._output(out[t])
        for t in range(done, len(oa)):
            f_t, _, mix, a = self._forward(oa[t])
            out[t] = self._combine(f_t, mix, a)
        return out

    def trace(self, oa: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The readout's inputs for one utterance at lag 0 (what it sees live; for fitting one):
        ``oa (T, Da)`` -> raw eq. 7 estimates ``(T, Dv)``, component posteriors ``(T, N*M)``, centred
        audio ``(T, Da)``. Starts a new utterance (:meth:`reset`) and leaves the inverter reset."""
        self.reset()
        oa = np.asarray(oa)
        if oa.ndim != 2 or oa.shape[1] != self._da:
            raise InvalidFeaturesError(f"audio features must be (k, {self._da}), got {oa.shape}")
        raw, post, audio = np.empty((len(oa), self._dv)), np.empty((len(oa), self._n * self._m)), []
        for t, row in enumerate(oa):
            f, _, mix, a = self._forward(row)
            raw[t] = self._raw(f, mix, a)
            post[t] = _component_posteriors(f, mix)
            audio.append(a)
        self.reset()
        return raw, post, np.array(audio, dtype=np.float64).reshape(len(oa), self._da)

    def _forward_compiled(self, row: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_forward` in one compiled call."""
        prev = self._f
        f, b, mix, a = self._forward_step(
            row,
            *self._step_model,
            self._start if prev is None else prev,
            prev is not None,
            self._start,
        )
        self._f = f
        return f, b, mix, a

    def _combine_raw(self, state_post: np.ndarray, mix: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Eq. 7 compiled, before the output stage."""
        x, ok = self._combine_step(state_post, mix, a, self._G, self._h, self._phi_flat)
        if not ok:
            P = (((state_post[:, None] * mix).reshape(-1) / (state_post @ mix.sum(axis=1))) @ self._phi_flat).reshape(
                self._dv, self._dv
            )
            x = np.linalg.lstsq(P, x, rcond=None)[0]
        return x

    def _emit_oldest(self) -> np.ndarray:
        f, _, mix, cond = self._pending[0]
        if self.config.lag:
            beta = np.ones(self._n)
            for _, b, _, _ in list(self._pending)[:0:-1]:
                beta = self._A @ (b * beta)
                beta /= beta.sum()
            f = f * beta
        self._pending.popleft()
        return self._combine(f, mix, cond)

    def _combine(self, state_post: np.ndarray, mix: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Eq. 7 for one frame, then the readout and the output stage: posteriors ``(N,), (N, M)``,
        centred audio ``a (Da,)`` -> ``(Dv,)``."""
        x = self._raw(state_post, mix, a)
        if self._readout is not None:
            x = self._readout.step(x, _component_posteriors(state_post, mix), a)
        return x if self._output is None else self._output(x)

    def _raw(self, state_post: np.ndarray, mix: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Eq. 7 for one frame (the numpy reference), before the readout and the output stage."""
        r = (state_post[:, None] * mix).reshape(-1)
        r = r / r.sum()
        # Components under SKIP_POSTERIOR are left out (as in the compiled kernel, which says why);
        # the sums over the rest run in float64 (G's float32 entries promote exactly).
        keep = np.flatnonzero(r >= SKIP_POSTERIOR)
        rk = r[keep]
        P = (rk @ self._phi_flat[keep]).reshape(self._dv, self._dv)
        Gr = (rk @ self._G[keep]).reshape(self._dv, self._da)
        rhs = Gr @ a.astype(np.float64) + rk @ self._h[keep]
        # P is a positive combination of SPD matrices: Cholesky solve straight from LAPACK
        # (np.linalg.solve's Python overhead is ~10x the arithmetic at this size).
        _, x, info = _posv(P, rhs)
        return x if info == 0 else np.linalg.lstsq(P, rhs, rcond=None)[0]


def _component_posteriors(state_post: np.ndarray, mix: np.ndarray) -> np.ndarray:
    """``(N,)`` state and ``(N, M)`` within-state posteriors -> normalised component posteriors ``(N*M,)``
    (the weights eq. 7 combines with)."""
    r = (state_post[:, None] * mix).reshape(-1)
    return r / r.sum()
