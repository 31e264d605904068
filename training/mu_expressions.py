"""Expressions for paper 002's numbers: expression deformations at the MU landmarks, Expression MUs
(eq. 1), the second-stage mappers (Sec. VI-B), and the closure / rounding checks under a smile.

No real expressive recording exists here, so an expression's deformation of the speaker's lower face
is the built-in head's ARKit recipe (:data:`realtime_core.expressions.EXPRESSION_RECIPES`) carried
onto the speaker's landmarks: the speaker's neutral face (IOD units) is placed on the head by a
similarity fit of the 12 shared named landmarks (eye corners, nose tip, mouth corners, lip midpoints,
chin) plus a Gaussian RBF warp of the residuals, every lower-face landmark takes the nearest skin
vertex, and the recipe's displacement there is brought back into the speaker's frame and units.
An expressive sentence is then the sentence's real deformation plus that expression deformation
(eq. 2 with alpha = 1). With real expressive recordings (``facecast extract`` of a user's smiling
or sad videos), ``D_k`` is simply their measured deformations and every later step is unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.expressions import EXPRESSION_RECIPES, EXPRESSIONS, apply_expression
from realtime_core.fitted_maps import EXPRESSION_PARAMS
from realtime_core.motion_units import ExpressionUnits, MotionUnits, analyse, compose, fit_expression_units
from training.motion_units import Clip

NAMED = (
    "eye_outer_left",
    "eye_inner_left",
    "eye_outer_right",
    "eye_inner_right",
    "nose_tip",
    "corner_left",
    "corner_right",
    "upper_lip",
    "lower_lip",
    "upper_inner",
    "lower_inner",
    "chin",
)


def head_correspondence(neutral: np.ndarray, indices: Sequence[int], head, mp_landmarks: dict[str, int]):
    """The built-in head's skin vertex of each speaker landmark in ``indices``, and the similarity
    speaker -> head: ``(vertices (L,), similarity)``.

    neutral: ``(468, 3)`` the speaker's rest face (IOD, face frame); head: the built-in head;
    mp_landmarks: named MediaPipe indices (``assets/heads/landmarks/mediapipe_canonical.json``)."""
    from scipy.spatial import cKDTree

    from realtime_core.face.registration import fit_similarity

    src = np.array([neutral[mp_landmarks[n]] for n in NAMED], dtype=np.float64)
    dst = np.array([head.mesh.vertices[head.landmarks[n]] for n in NAMED])
    sim = fit_similarity(src, dst)
    placed = sim.apply(np.asarray(neutral, dtype=np.float64))
    # RBF warp of the 12 residuals so lips, corners and chin land on the head's own.
    c = placed[[mp_landmarks[n] for n in NAMED]]
    r2 = float(((c - c.mean(0)) ** 2).sum(1).mean())
    k = np.exp(-((c[:, None] - c[None]) ** 2).sum(-1) / r2)
    coef = np.linalg.solve(k + 1e-9 * np.eye(len(c)), dst - c)
    pts = placed[list(indices)]
    pts = pts + np.exp(-((pts[:, None] - c[None]) ** 2).sum(-1) / r2) @ coef
    skin = np.flatnonzero(head.part == 0)
    _, nearest = cKDTree(head.mesh.vertices[skin]).query(pts)
    return skin[nearest], sim


def carried(head, verts: np.ndarray, sim, weights: Mapping[str, float]) -> np.ndarray:
    """ARKit ``weights`` on the head, read at ``verts`` and brought into the speaker's frame: ``(3 L,)`` IOD."""
    disp = sum(w * head.targets[n][verts] for n, w in weights.items())  # head units
    return (disp @ sim.rotation / sim.scale).reshape(-1)  # rotation^T, then the speaker's units


def expression_deformations(neutral: np.ndarray, indices: Sequence[int], head, mp_landmarks: dict[str, int]) -> dict:
    """Each expression's deformation ``(3 L,)`` of the speaker's landmarks ``indices`` (IOD units)."""
    verts, sim = head_correspondence(neutral, indices, head, mp_landmarks)
    return {e: carried(head, verts, sim, EXPRESSION_RECIPES[e]) for e in EXPRESSIONS}


def expressive(clips: Sequence[Clip], delta: np.ndarray) -> list[Clip]:
    """The clips as if spoken under an expression of deformation ``delta (3 L,)``."""
    return [
        Clip(
            c.sentence_id,
            c.split,
            c.samples,
            c.sample_rate_hz,
            (c.deform + delta).astype(np.float32),
            c.params,
            c.neutral,
            None,
            c.features,
        )
        for c in clips
    ]


def fit_units(mu: MotionUnits, train_k: Sequence[Clip], name: str, n_units: int = 2) -> ExpressionUnits:
    return fit_expression_units(
        mu, np.concatenate([c.deform for c in train_k]).astype(np.float64), name=name, n_units=n_units
    )


def fit_second_stage(
    est_umup: np.ndarray, mu: MotionUnits, ex: ExpressionUnits, d_k: np.ndarray, *, hidden: int = 30, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sec. VI-B: an MLP ``Upsilon_k`` (one tanh hidden layer, 30 units, scikit-learn) from estimated UMUPs
    to the expressive frames' (UMUPs, EMUPs). Returns its weights with the standardisation folded in,
    ``(w1 (H, A0), b1 (H,), w2 (A0 + Ak, H), b2 (A0 + Ak,))`` as
    :class:`realtime_core.mapping.expression.ExpressionStage` takes them."""
    from sklearn.neural_network import MLPRegressor

    c0, ck = analyse(mu, ex, d_k)
    y = np.hstack([c0, ck])
    xm, xs = est_umup.mean(0), np.maximum(est_umup.std(0), 1e-9)
    ym, ys = y.mean(0), np.maximum(y.std(0), 1e-9)
    mlp = MLPRegressor(
        hidden_layer_sizes=(hidden,),
        activation="tanh",
        alpha=1e-3,
        max_iter=200,
        early_stopping=True,
        n_iter_no_change=10,
        random_state=seed,
    )
    mlp.fit((est_umup - xm) / xs, (y - ym) / ys)
    w1, w2 = mlp.coefs_
    b1, b2 = mlp.intercepts_
    # tanh(((x - xm) / xs) W1 + b1) = tanh(x (W1 / xs) + (b1 - (xm / xs) W1)); y = (h W2 + b2) ys + ym
    return (w1 / xs[:, None]).T, b1 - (xm / xs) @ w1, (w2 * ys).T, b2 * ys + ym


def mouth_jacobian(neutral: np.ndarray, indices: Sequence[int], eps: float = 1e-4) -> np.ndarray:
    """``J (4, 3 L)``: how the four mouth parameters (:func:`training.video.mouth_params`) change per IOD of
    displacement of each coordinate of the landmarks ``indices``, at the rest face ``neutral (468, 3)``
    (central differences; the parameters are smooth there)."""
    from training.video import mouth_params

    base = np.asarray(neutral, dtype=np.float64)
    idx = list(indices)
    out = np.zeros((len(VISUAL_PARAMS), 3 * len(idx)))
    for j, v in enumerate(idx):
        for c in range(3):
            lm = np.repeat(base[None], 2, axis=0)
            lm[0, v, c] += eps
            lm[1, v, c] -= eps
            p = mouth_params(lm, base)
            out[:, 3 * j + c] = (p[0] - p[1]) / (2 * eps)
    return out


def expression_stage(name: str, weights, mu: MotionUnits, ex: ExpressionUnits, jacobian: np.ndarray):
    """The run-time :class:`realtime_core.mapping.expression.ExpressionStage` of a fitted second stage."""
    from realtime_core.mapping import ExpressionStage

    w1, b1, w2, b2 = weights
    return ExpressionStage(
        name=name,
        w1=w1,
        b1=b1,
        w2=w2,
        b2=b2,
        emu_params=jacobian @ ex.basis.units.T,
        emu_bias=jacobian @ ex.basis.mean,
    )


def second_stage_predict(weights, x: np.ndarray) -> np.ndarray:
    """``(T, A0)`` estimated UMUPs -> ``(T, A0 + Ak)`` with folded weights (as at run time)."""
    w1, b1, w2, b2 = weights
    return np.tanh(x @ w1.T + b1) @ w2.T + b2


def reconstruct(mu: MotionUnits, ex: ExpressionUnits, out: np.ndarray) -> np.ndarray:
    """``(T, A0 + Ak)`` second-stage output -> deformations ``(T, 3 L)`` (eq. 2)."""
    return compose(mu, out[:, : mu.n_units], ex, out[:, mu.n_units :])


BILABIAL_WORDS = frozenset({"bin", "blue", "by", "place", "please", "b", "p"})
"""GRID words that begin with a bilabial closure (/b/ or /p/)."""


def closure_windows(
    words: Sequence[tuple[float, float, str]], fps: float = 30.0, *, before_s: float = 0.06, after_s: float = 0.12
) -> list[tuple[int, int]]:
    """Frame ranges ``[lo, hi)`` around the start of each bilabial-initial word."""
    out = []
    for start, _end, w in words:
        if w.lower() in BILABIAL_WORDS:
            out.append((max(0, int(np.floor((start - before_s) * fps))), int(np.ceil((start + after_s) * fps)) + 1))
    return out


def closure_rate(tracks: Sequence[np.ndarray], windows: Sequence[Sequence[tuple[int, int]]], threshold: float) -> float:
    """Fraction of bilabial windows whose smallest ``mouth_open`` is at most ``threshold`` (IOD)."""
    hit = tot = 0
    j = VISUAL_PARAMS.index("mouth_open")
    for tr, ws in zip(tracks, windows):
        for lo, hi in ws:
            seg = tr[lo : min(hi, len(tr)), j]
            if len(seg):
                tot += 1
                hit += int(seg.min() <= threshold)
    return hit / tot if tot else float("nan")


def under_expression(tracks: Sequence[np.ndarray], name: str, intensity: float = 1.0) -> list[np.ndarray]:
    """Speech parameter tracks with ``name`` applied at a constant ``intensity`` (the run-time rule)."""
    a = np.zeros(len(EXPRESSIONS))
    a[EXPRESSIONS.index(name)] = intensity
    return [apply_expression(t, np.tile(a, (len(t), 1)), EXPRESSION_PARAMS) for t in tracks]
