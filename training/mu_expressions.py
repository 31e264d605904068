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
from training.facetrack import LIPS_INNER, LIPS_OUTER
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
    idx = list(indices)
    pts = placed[idx]
    pts = pts + np.exp(-((pts[:, None] - c[None]) ** 2).sum(-1) / r2) @ coef
    skin = np.flatnonzero(head.part == 0)
    # A lip landmark takes the nearest vertex *of its own lip*. At rest the lips touch, so the nearest
    # skin vertex of an inner-lip point is as often on the other lip: unconstrained, two of the three
    # pairs that measure the lip gap (LIP_GAP_PAIRS) landed on one lip (one pair on one vertex), and
    # the jaw drop that parts the lips on the head barely parted them on the speaker. Which lip a head
    # vertex belongs to is read with the head's own jaw fully open (jawOpen = 1), where the lips are
    # far apart: above or below the line through the open mouth's corners and inner-lip midpoint (at
    # rest the lips' meeting line is curved and no straight line splits them).
    v = head.mesh.vertices[skin]
    opened = head.mesh.vertices + head.targets["jawOpen"]
    corners = sorted((opened[head.landmarks[n]] for n in ("corner_right", "corner_left")), key=lambda p: p[0])
    mid = 0.5 * (opened[head.landmarks["upper_inner"]] + opened[head.landmarks["lower_inner"]])
    o = opened[skin]
    line_y = np.interp(o[:, 0], [corners[0][0], mid[0], corners[1][0]], [corners[0][1], mid[1], corners[1][1]])
    above = o[:, 1] > line_y
    upper = set(LIPS_OUTER[11:]) | set(LIPS_INNER[11:])
    lower = set(LIPS_OUTER[1:10]) | set(LIPS_INNER[1:10])
    out = np.empty(len(idx), dtype=np.int64)
    for side, pool in ((upper, above), (lower, ~above), (None, np.ones(len(v), bool))):
        rows = [j for j, i in enumerate(idx) if (i in side if side is not None else i not in upper | lower)]
        if rows:
            cand = np.flatnonzero(pool)
            _, nearest = cKDTree(v[cand]).query(pts[rows])
            out[rows] = skin[cand[nearest]]
    return out, sim


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

    from training.mapper import fit_within_budget

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
    fit_within_budget(mlp, (est_umup - xm) / xs, (y - ym) / ys)
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


def emu_readout(
    neutral: np.ndarray, indices: Sequence[int], ex: ExpressionUnits, emups: np.ndarray, *, n_samples: int = 4000
) -> tuple[np.ndarray, np.ndarray]:
    """``(P (4, Ak), q (4,))``: the four mouth parameters' change made by the EMU deformation
    ``m_k0 + M_k c_k`` of the speaker's rest face ``neutral (468, 3)``, as an affine least-squares fit of
    the parameters really measured (:func:`training.video.mouth_params`) over the EMUPs ``emups (T, Ak)`` of
    the expressive training frames (at most ``n_samples`` of them, evenly spaced).

    Not the Jacobian at rest (:func:`mouth_jacobian`): mouth_open is a distance between inner-lip points
    that touch at rest, where its gradient points along whatever tiny offset the lips happen to have; a
    jaw drop moving the lower lip down and back read through it changed the gap by -0.05 IOD where the
    measured gap grows by +0.11. The secant over the expression's own range has no such singularity."""
    from training.video import mouth_params

    c = np.asarray(emups, dtype=np.float64)
    c = c[np.linspace(0, len(c) - 1, min(n_samples, len(c))).astype(int)]
    base = np.asarray(neutral, dtype=np.float64)
    lm = np.repeat(base[None], len(c), axis=0)
    lm[:, list(indices)] += ex.basis.reconstruct(c).reshape(len(c), -1, 3)
    p = mouth_params(lm, base)
    a = np.hstack([c, np.ones((len(c), 1))])
    coef, *_ = np.linalg.lstsq(a, p, rcond=None)
    return coef[:-1].T, coef[-1]


def expression_stage(
    name: str,
    weights,
    mu: MotionUnits,
    ex: ExpressionUnits,
    jacobian: np.ndarray | None = None,
    *,
    emu: tuple[np.ndarray, np.ndarray] | None = None,
):
    """The run-time :class:`realtime_core.mapping.expression.ExpressionStage` of a fitted second stage; the
    EMUPs' effect on the four parameters is ``emu`` (:func:`emu_readout`) or else ``jacobian (4, 3 L)`` read
    on the EMUs (``J M_k``, ``J m_k0``)."""
    from realtime_core.mapping import ExpressionStage

    if emu is None:
        if jacobian is None:
            raise ValueError("expression_stage needs a jacobian or an emu readout")
        emu = (jacobian @ ex.basis.units.T, jacobian @ ex.basis.mean)
    w1, b1, w2, b2 = weights
    return ExpressionStage(name=name, w1=w1, b1=b1, w2=w2, b2=b2, emu_params=emu[0], emu_bias=emu[1])


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
