"""The GMM-selected bank of small MLPs (paper 002 Sec. VI-A), inference in numpy.

Theory of operation
-------------------
Input: the front end's features ``o_a,t (Da,)`` = ``2 tc + 1`` stacked MFCC frames (``tc = 3``: 3
back, the current one and 3 ahead, the paper's seven frames and its ~100 ms lookahead).

1. **Classify.** A diagonal-covariance Gaussian mixture over the *current* frame's coefficients
   (the centre slice of ``o_a``, :attr:`MlpBank.class_slice`) scores each of its K components;
   the frame goes to the best ``log w_k + log N(x; mu_k, diag(var_k))``. The K scores are one
   matrix product over ``[x^2, x, 1]`` (the quadratic form expanded).
2. **Map.** Expert ``k``, a three-layer perceptron ``y = W2_k act(W1_k o_a + b1_k) + b2_k`` (15-25
   hidden units), gives the Utterance MU parameters of the frame. Input standardisation and output
   scaling of training are folded into ``W1, b1, W2, b2`` so inference is two small products.
   Experts with fewer hidden units than the widest are zero-padded (a zero unit adds nothing).
3. **Read out** (optional): a fixed affine map from MUPs to the served visual parameters (the four
   mouth parameters), fitted by least squares on the training frames; it is folded into each
   expert's output layer, so serving the four parameters costs no more than serving the MUPs.

Each output row depends only on its own ``o_a`` row (the context is already in it), so the
streaming form returns every row at once and is chunk-invariant by construction. Arithmetic is
float32 (``dtype``); the argmax of step 1 is float32 too, so a stream and a batch agree bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError, ModelFormatError, StreamStateError
from realtime_core.output import OutputStage

ACTIVATIONS = ("relu", "tanh", "logistic", "identity")


def _act(name: str, h: np.ndarray) -> np.ndarray:
    if name == "relu":
        return np.maximum(h, 0, out=h)
    if name == "tanh":
        return np.tanh(h, out=h)
    if name == "logistic":
        return np.reciprocal(1 + np.exp(-h, out=h), out=h)
    return h


@dataclass(frozen=True, kw_only=True, eq=False)
class MlpBank:
    """K experts and their Gaussian-mixture selector.

    gmm_log_weights ``(K,)``, gmm_means ``(K, F)``, gmm_vars ``(K, F)``: the diagonal selector over
    ``o_a[class_slice]`` (``F`` = its width); w1 ``(K, H, Da)``, b1 ``(K, H)``, w2 ``(K, Dout, H)``,
    b2 ``(K, Dout)``: the experts; hidden ``(K,)`` int: each expert's real hidden-unit count (``<= H``);
    activation: one of :data:`ACTIVATIONS`; readout ``(Dv, Dout)`` and readout_bias ``(Dv,)``: MUPs ->
    served parameters (None: serve the MUPs themselves).
    """

    gmm_log_weights: np.ndarray
    gmm_means: np.ndarray
    gmm_vars: np.ndarray
    class_slice: tuple[int, int]
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    hidden: np.ndarray
    activation: str = "relu"
    readout: np.ndarray | None = None
    readout_bias: np.ndarray | None = None

    def __post_init__(self) -> None:
        def f64(a: object) -> np.ndarray:
            return np.asarray(a, dtype=np.float64)

        lw, mu, var = f64(self.gmm_log_weights), f64(self.gmm_means), f64(self.gmm_vars)
        w1, b1, w2, b2 = f64(self.w1), f64(self.b1), f64(self.w2), f64(self.b2)
        k = lw.shape[0] if lw.ndim == 1 else -1
        lo, hi = (int(v) for v in self.class_slice)
        checks = [
            (lw.ndim == 1 and k >= 1, f"gmm_log_weights must be (K,), got {lw.shape}"),
            (
                mu.shape == (k, hi - lo) and var.shape == mu.shape,
                f"gmm means/vars must be ({k}, {hi - lo}), got {mu.shape}, {var.shape}",
            ),
            (w1.ndim == 3 and w1.shape[0] == k, f"w1 must be ({k}, H, Da), got {w1.shape}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ModelFormatError(f"MLP bank: {msg}")
        _, h, da = w1.shape
        dout = w2.shape[1] if w2.ndim == 3 else -1
        checks = [
            (0 <= lo < hi <= da, f"class_slice {self.class_slice} outside 0..{da}"),
            (b1.shape == (k, h), f"b1 must be ({k}, {h}), got {b1.shape}"),
            (w2.shape == (k, dout, h) and dout >= 1, f"w2 must be ({k}, Dout, {h}), got {w2.shape}"),
            (b2.shape == (k, dout), f"b2 must be ({k}, {dout}), got {b2.shape}"),
            (np.asarray(self.hidden).shape == (k,), f"hidden must be ({k},), got {np.asarray(self.hidden).shape}"),
            (self.activation in ACTIVATIONS, f"activation must be one of {ACTIVATIONS}, got {self.activation!r}"),
            (bool(np.all(var > 0)), "gmm variances must be positive"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ModelFormatError(f"MLP bank: {msg}")
        arrays = {"gmm_log_weights": lw, "gmm_means": mu, "gmm_vars": var, "w1": w1, "b1": b1, "w2": w2, "b2": b2}
        if self.readout is not None:
            r, rb = f64(self.readout), f64(self.readout_bias)
            if r.ndim != 2 or r.shape[1] != dout or rb.shape != (r.shape[0],):
                raise ModelFormatError(
                    f"MLP bank: readout must be (Dv, {dout}) with bias (Dv,), got {r.shape}, {rb.shape}"
                )
            arrays.update(readout=r, readout_bias=rb)
        for name, arr in arrays.items():
            if not np.isfinite(arr).all():
                raise ModelFormatError(f"MLP bank: {name} contains NaN or inf")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "class_slice", (lo, hi))
        object.__setattr__(self, "hidden", np.asarray(self.hidden, dtype=np.int64))

    @property
    def n_classes(self) -> int:
        return int(self.gmm_log_weights.shape[0])

    @property
    def n_audio(self) -> int:
        return int(self.w1.shape[2])

    @property
    def n_mups(self) -> int:
        return int(self.w2.shape[1])

    @property
    def n_visual(self) -> int:
        return self.n_mups if self.readout is None else int(self.readout.shape[0])


@dataclass(frozen=True, eq=False)
class _Plan:
    """The per-frame matrices of a bank in the working dtype (shared by every session of a model)."""

    score: np.ndarray  # (2F + 1, K): [x^2, x, 1] @ score = log w_k + log N_k(x)
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    w2_out: np.ndarray  # (K, Dv, H): the readout folded into the output layer (= w2 without a readout)
    b2_out: np.ndarray  # (K, Dv)

    @classmethod
    def build(cls, bank: MlpBank, dtype: str) -> _Plan:
        dt = np.dtype(dtype)
        prec = 1.0 / bank.gmm_vars
        const = bank.gmm_log_weights - 0.5 * (np.log(2 * np.pi * bank.gmm_vars) + bank.gmm_means**2 * prec).sum(axis=1)
        score = np.vstack([-0.5 * prec.T, (bank.gmm_means * prec).T, const[None, :]])

        def cast(a: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(a, dtype=dt)

        if bank.readout is None:
            w2o, b2o = bank.w2, bank.b2
        else:  # R (W2 h + b2) + r0 = (R W2) h + (R b2 + r0): one product fewer per frame
            w2o = np.einsum("vo,koh->kvh", bank.readout, bank.w2)
            b2o = bank.b2 @ bank.readout.T + bank.readout_bias
        return cls(cast(score), cast(bank.w1), cast(bank.b1), cast(bank.w2), cast(bank.b2), cast(w2o), cast(b2o))


class MlpMapper:
    """Batch inference of a bank: ``classify``, ``mups`` and ``predict`` on ``o_a (T, Da)``.

    dtype: "float32" (default, the live path) or "float64"."""

    def __init__(self, bank: MlpBank, *, dtype: str = "float32", plan: _Plan | None = None) -> None:
        if dtype not in ("float32", "float64"):
            raise ConfigError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
        self.bank = bank
        self.dtype = np.dtype(dtype)
        self.plan = _Plan.build(bank, dtype) if plan is None else plan
        self._lo, self._hi = bank.class_slice

    def _check(self, oa: np.ndarray) -> np.ndarray:
        x = np.asarray(oa)
        if x.ndim != 2 or x.shape[1] != self.bank.n_audio:
            raise InvalidFeaturesError(f"audio features must be (k, {self.bank.n_audio}), got {x.shape}")
        if not np.isfinite(np.add.reduce(x, axis=None)):
            raise InvalidFeaturesError("audio features contain NaN or inf")
        return x.astype(self.dtype, copy=False)

    def _classify(self, x: np.ndarray) -> np.ndarray:
        c = x[:, self._lo : self._hi]
        feats = np.hstack([c * c, c, np.ones((len(x), 1), dtype=self.dtype)])
        return np.argmax(feats @ self.plan.score, axis=1)

    def classify(self, oa: np.ndarray) -> np.ndarray:
        """``(T,)`` int expert index of each frame."""
        return self._classify(self._check(oa))

    def _forward(self, x: np.ndarray, cls: np.ndarray, w2: np.ndarray, b2: np.ndarray) -> np.ndarray:
        # One matrix-vector product pair per row, whatever the batch: the live path pushes one row at
        # a time and a stream must equal the batch bit for bit (a batched GEMM rounds differently).
        p, act = self.plan, self.bank.activation
        out = np.empty((len(x), b2.shape[1]), dtype=self.dtype)
        for t, k in enumerate(cls):
            out[t] = w2[k] @ _act(act, p.w1[k] @ x[t] + p.b1[k]) + b2[k]
        return out

    def mups(self, oa: np.ndarray) -> np.ndarray:
        """``(T, n_mups)`` float64 MU parameters."""
        x = self._check(oa)
        if len(x) == 0:
            return np.zeros((0, self.bank.n_mups))
        return self._forward(x, self._classify(x), self.plan.w2, self.plan.b2).astype(np.float64)

    def predict(self, oa: np.ndarray) -> np.ndarray:
        """``(T, n_visual)`` float64 served parameters (the MUPs read out, if the bank has a readout)."""
        x = self._check(oa)
        if len(x) == 0:
            return np.zeros((0, self.bank.n_visual))
        return self._forward(x, self._classify(x), self.plan.w2_out, self.plan.b2_out).astype(np.float64)

    def predict_with_mups(self, oa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(``predict(oa)``, ``mups(oa)``) from one hidden layer per row (bit for bit the same values)."""
        x = self._check(oa)
        p = self.plan
        out = np.empty((len(x), self.bank.n_visual), dtype=self.dtype)
        mups = np.empty((len(x), self.bank.n_mups), dtype=self.dtype)
        for t, k in enumerate(self._classify(x) if len(x) else ()):
            h = _act(self.bank.activation, p.w1[k] @ x[t] + p.b1[k])
            out[t] = p.w2_out[k] @ h + p.b2_out[k]
            mups[t] = p.w2[k] @ h + p.b2[k]
        return out.astype(np.float64), mups.astype(np.float64)


class StreamingMlpMapper:
    """:class:`realtime_core.mapping.VisualMapper` over a bank: every pushed row is final at once
    (``lag_frames = 0``), ``flush()`` returns nothing new. output: the output stage every estimate goes
    through (:class:`realtime_core.output.OutputStage`: the closed-pose floor; None = none), as the HMM path.
    with_mups: also keep the MU parameters of the rows each push/flush returns in :attr:`last_mups`
    (``(j, n_mups)`` float64; what paper 002's second-stage expression mappers read)."""

    lag_frames = 0

    def __init__(self, mapper: MlpMapper, *, output: OutputStage | None = None, with_mups: bool = False) -> None:
        self._m = mapper
        self._output = output
        self._with_mups = with_mups
        self.reset()

    def reset(self) -> None:
        self._finished = False
        self.last_mups: np.ndarray | None = np.zeros((0, self._m.bank.n_mups)) if self._with_mups else None

    def push(self, oa: np.ndarray) -> np.ndarray:
        if self._finished:
            raise StreamStateError("StreamingMlpMapper.push() after flush(); call reset() first")
        if self._with_mups:
            y, self.last_mups = self._m.predict_with_mups(oa)
        else:
            y = self._m.predict(oa)
        return y if self._output is None else self._output(y)

    def flush(self) -> np.ndarray:
        if self._finished:
            raise StreamStateError("StreamingMlpMapper.flush() called twice; call reset() first")
        self._finished = True
        if self._with_mups:
            self.last_mups = np.zeros((0, self._m.bank.n_mups))
        return np.zeros((0, self._m.bank.n_visual))
