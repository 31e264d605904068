"""Training the GMM-selected MLP bank (paper 002 Sec. VI-A) and the single-MLP baseline.

scikit-learn does the fitting (``GaussianMixture`` for the selector, ``MLPRegressor`` for each
expert); the fitted weights are exported into a :class:`realtime_core.mapping.MlpBank`, whose numpy
inference is what runs live (the tests check it against scikit-learn's own ``predict``).

Classes. The paper splits its data by 44 phoneme classes, each modelled by a Gaussian mixture. GRID
comes with word alignments only, so our classes are the K components of one diagonal Gaussian
mixture fitted, unsupervised, to the current frame's MFCCs; K is chosen on the validation split
(``facecast mu train --classes``). An expert whose class holds fewer than ``min_frames`` frames also
learns from the frames its component explains best, so no expert is trained on a handful of rows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from sklearn.mixture import GaussianMixture
from sklearn.neural_network import MLPRegressor

from realtime_core.mapping import MlpBank
from training.errors import ConfigError

Progress = Callable[[int, int], None]


@dataclass(frozen=True, kw_only=True)
class MapperRecipe:
    """n_classes: K experts (1 = one MLP for everything); hidden: hidden units per expert (the paper:
    15-25); activation: MLPRegressor's; l2: its ``alpha``; max_iter / early stopping: MLPRegressor's;
    min_frames: the smallest training set an expert gets; gmm_frames: frames (sampled) the selector is
    fitted on; seed: every random choice."""

    n_classes: int = 16
    hidden: int = 20
    activation: str = "tanh"
    l2: float = 1e-3
    max_iter: int = 200
    min_frames: int = 400
    gmm_frames: int = 30000
    seed: int = 0

    def __post_init__(self) -> None:
        if not 1 <= self.n_classes <= 256:
            raise ConfigError(f"n_classes must be in 1..256, got {self.n_classes}")
        if not 1 <= self.hidden <= 4096:
            raise ConfigError(f"hidden must be in 1..4096, got {self.hidden}")
        if self.activation not in ("relu", "tanh", "logistic"):
            raise ConfigError(f"activation must be relu, tanh or logistic, got {self.activation!r}")
        if not self.l2 >= 0 or self.max_iter < 1 or self.min_frames < 10 or self.gmm_frames < 100:
            raise ConfigError("l2 >= 0, max_iter >= 1, min_frames >= 10, gmm_frames >= 100 required")

    def as_json(self) -> dict:
        return {
            "n_classes": self.n_classes,
            "hidden": self.hidden,
            "activation": self.activation,
            "l2": self.l2,
            "max_iter": self.max_iter,
            "min_frames": self.min_frames,
            "gmm_frames": self.gmm_frames,
            "seed": self.seed,
        }


def export_mlp(
    mlp: MLPRegressor, x_mean: np.ndarray, x_scale: np.ndarray, y_mean: np.ndarray, y_scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A fitted one-hidden-layer MLPRegressor on standardised data -> ``w1 (H, Da), b1 (H,), w2 (Dout, H),
    b2 (Dout,)`` on raw data (the standardisation folded into the weights)."""
    if len(mlp.coefs_) != 2:
        raise ConfigError(f"expected one hidden layer, got {len(mlp.coefs_) - 1}")
    w1 = mlp.coefs_[0].T / x_scale[None, :]
    b1 = mlp.intercepts_[0] - w1 @ x_mean
    w2 = mlp.coefs_[1].T * y_scale[:, None]
    b2 = mlp.intercepts_[1] * y_scale + y_mean
    return w1, b1, w2, b2


def _fit_mlp(x: np.ndarray, y: np.ndarray, recipe: MapperRecipe, hidden: int, seed: int) -> MLPRegressor:
    mlp = MLPRegressor(
        hidden_layer_sizes=(hidden,),
        activation=recipe.activation,
        alpha=recipe.l2,
        max_iter=recipe.max_iter,
        early_stopping=len(x) >= 200,
        validation_fraction=0.1,
        n_iter_no_change=10,
        random_state=seed,
        learning_rate_init=1e-3,
        batch_size=min(256, len(x)),
    )
    return fit_within_budget(mlp, x, y)


def fit_within_budget(mlp: MLPRegressor, x: np.ndarray, y: np.ndarray) -> MLPRegressor:
    """``mlp.fit(x, y)`` for a scikit-learn net whose ``max_iter`` is a budget, not a convergence promise: early
    stopping on a validation tenth ends most fits before it, and one that reaches it is kept as it is (its epochs are
    ``mlp.n_iter_``). sklearn's ConvergenceWarning said so in traceback-like lines in the middle of `facecast mu` and
    `facecast readout` output; it is not shown."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return mlp.fit(x, y)


def fit_selector(centre: np.ndarray, recipe: MapperRecipe) -> GaussianMixture:
    """The diagonal Gaussian mixture over the current frame's features ``centre (N, F)``."""
    rng = np.random.default_rng(recipe.seed)
    sub = (
        centre
        if len(centre) <= recipe.gmm_frames
        else centre[rng.choice(len(centre), recipe.gmm_frames, replace=False)]
    )
    gmm = GaussianMixture(
        n_components=recipe.n_classes, covariance_type="diag", random_state=recipe.seed, max_iter=200, reg_covar=1e-4
    )
    gmm.fit(sub)
    return gmm


def fit_bank(
    x: np.ndarray,
    y: np.ndarray,
    recipe: MapperRecipe,
    *,
    class_slice: tuple[int, int],
    readout: tuple[np.ndarray, np.ndarray] | None = None,
    progress: Progress | None = None,
) -> MlpBank:
    """Train on frames ``x (N, Da)`` (front-end features) -> targets ``y (N, Dout)`` (UMUPs).

    class_slice: the columns of ``x`` the selector sees (the current frame); readout: optional
    ``(matrix (Dv, Dout), bias (Dv,))`` stored in the bank."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 2 or len(x) != len(y) or len(x) < recipe.min_frames:
        raise ConfigError(
            f"need (N >= {recipe.min_frames}, Da) features and (N, Dout) targets, got {x.shape}, {y.shape}"
        )
    lo, hi = class_slice
    x_mean, x_scale = x.mean(0), np.maximum(x.std(0), 1e-6)
    y_mean, y_scale = y.mean(0), np.maximum(y.std(0), 1e-9)
    xs, ys = (x - x_mean) / x_scale, (y - y_mean) / y_scale
    k = recipe.n_classes
    if k == 1:
        log_w, means, var = np.zeros(1), x[:1, lo:hi] * 0, np.ones((1, hi - lo))
        resp = np.ones((len(x), 1))
    else:
        gmm = fit_selector(x[:, lo:hi], recipe)
        log_w, means, var = np.log(gmm.weights_), gmm.means_, gmm.covariances_
        resp = gmm.predict_proba(x[:, lo:hi])
    label = resp.argmax(1)
    w1 = np.zeros((k, recipe.hidden, x.shape[1]))
    b1 = np.zeros((k, recipe.hidden))
    w2 = np.zeros((k, y.shape[1], recipe.hidden))
    b2 = np.zeros((k, y.shape[1]))
    for c in range(k):
        rows = np.flatnonzero(label == c)
        if len(rows) < recipe.min_frames:
            rows = np.union1d(rows, np.argsort(-resp[:, c])[: recipe.min_frames])
        mlp = _fit_mlp(xs[rows], ys[rows], recipe, recipe.hidden, recipe.seed + c)
        w1[c], b1[c], w2[c], b2[c] = export_mlp(mlp, x_mean, x_scale, y_mean, y_scale)
        if progress is not None:
            progress(c + 1, k)
    r, rb = (None, None) if readout is None else readout
    return MlpBank(
        gmm_log_weights=log_w,
        gmm_means=means,
        gmm_vars=var,
        class_slice=(lo, hi),
        w1=w1,
        b1=b1,
        w2=w2,
        b2=b2,
        hidden=np.full(k, recipe.hidden),
        activation=recipe.activation,
        readout=r,
        readout_bias=rb,
    )


def fit_readout(mups: np.ndarray, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares affine map MUPs ``(N, A)`` -> parameters ``(N, Dv)``: ``(matrix (Dv, A), bias (Dv,))``."""
    a = np.hstack([mups, np.ones((len(mups), 1))])
    coef = np.linalg.lstsq(a, params, rcond=None)[0]
    return coef[:-1].T.copy(), coef[-1].copy()
