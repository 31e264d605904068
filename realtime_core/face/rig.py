"""A rig: everything precomputed so that one animation frame is one sparse product.

Build (once per head): the simple face model is already placed on the head (registration); its
vertices are projected to control points (Sec. 5.1), every head vertex gets interpolation weights
(Sec. 5.2, or the RBF map of paper 001 for comparison) and the chain

    params (4,) --basis (n_s*3, 4)--> simple displacement (n_s*3,) --S (n_moving*3, n_s*3)--> head

is stored with S = kron(G, I_3) restricted to the head vertices that can move. Frame cost: a
(n_s*3, 4) dense product (~1k flops) and one CSR product with 3 non-zeros per row for Sec. 5.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from realtime_core.errors import ConfigError
from realtime_core.face.interpolation import InterpolationConfig, interpolation_weights
from realtime_core.face.model import FaceFrame, FaceModel, MouthCalibration, MouthLandmarks
from realtime_core.face.projection import project
from realtime_core.face.rbf import rbf_map

RIG_ALGORITHM = 11
HARMONIC_MARGIN = 0.0
"""IOD: how far the harmonic field extends beyond the vertices Sec. 5.2 moves (0: the same region;
0.5 did not remove the chin-line folds of Lee Perry-Smith and widened the moving region)."""
"""Bumped whenever rig building changes its output, so cached rigs are rebuilt."""


@dataclass(frozen=True)
class RigConfig:
    """Lengths are in inter-ocular distances (IOD) of the head so one config fits any scale.

    method: "sec5" (projection + interpolation, paper 000), "harmonic" (the region Sec. 5 moves, with
    a harmonic field inside it, :mod:`realtime_core.face.harmonic`; the default) or "rbf" (paper 001 Sec. 3.5).
    projection_2d: "frontal" (face-frame x, y) or "uv" (the head's texture coordinates).
    beta: eq. 10 gain. max_depth: off-plane tolerance for eq. 8-9. fallback_radius: fade of eq. 10
    (None = the paper's unbounded form). rbf_radius: None = paper 001's r. geodesic_check: Sec. 5.1,
    with geodesic_walk "greedy" (the paper) or "shortest" and geodesic_slack (see projection).
    connectivity / max_geodesic_ratio: mesh-path rules of the interpolation (see interpolation).
    normalize_fallback: eq. 10 as a weighted mean (extension; use with beta = 1).
    """

    method: Literal["sec5", "rbf", "harmonic"] = "harmonic"
    projection_2d: Literal["frontal", "uv"] = "frontal"
    beta: float = 0.5
    max_depth: float = 0.25
    fallback_radius: float | None = 0.6
    rbf_radius: float | None = None
    geodesic_check: bool = True
    geodesic_walk: Literal["greedy", "shortest"] = "greedy"
    geodesic_slack: float = 0.3
    connectivity: bool = True
    normalize_fallback: bool = False
    max_geodesic_ratio: float = 2.0
    candidates: int = 24

    def __post_init__(self) -> None:
        if self.method not in ("sec5", "rbf", "harmonic"):
            raise ConfigError(f"method must be 'sec5', 'rbf' or 'harmonic', got {self.method!r}")
        if self.geodesic_walk not in ("greedy", "shortest"):
            raise ConfigError(f"geodesic_walk must be 'greedy' or 'shortest', got {self.geodesic_walk!r}")
        if not 0 <= self.geodesic_slack < 1:
            raise ConfigError(f"geodesic_slack must be in [0, 1), got {self.geodesic_slack}")
        if self.projection_2d not in ("frontal", "uv"):
            raise ConfigError(f"projection_2d must be 'frontal' or 'uv', got {self.projection_2d!r}")
        InterpolationConfig(beta=self.beta, max_depth=self.max_depth, fallback_radius=self.fallback_radius)


@dataclass(frozen=True)
class Rig:
    """A head rigged for the four mouth parameters.

    neutral: (n_h, 3) float32 head vertices; triangles (m, 3) int32; moving (n_moving,) int64
    head vertices that can move; matrix: CSR float32 (n_moving*3, n_s*3); basis: (n_s*3, 4)
    float32 simple-model displacement per mouth parameter (IOD units in, head units out);
    control (n_s,) int64 head vertex of each simple vertex; simple: the placed simple model;
    calibration: its mouth calibration; meta: JSON-able description.
    """

    neutral: np.ndarray
    triangles: np.ndarray
    moving: np.ndarray
    matrix: sp.csr_matrix
    basis: np.ndarray
    control: np.ndarray
    simple: FaceModel
    calibration: MouthCalibration
    meta: dict[str, Any] = field(default_factory=dict)
    # Set in __post_init__: the folded dense (n_moving*3, 4) map, or None to use the sparse product.
    _folded: np.ndarray | None = field(init=False, default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n_h = len(self.neutral)
        n_s = self.simple.n_vertices
        if self.matrix.shape != (len(self.moving) * 3, n_s * 3):
            raise ConfigError(
                f"rig matrix {self.matrix.shape} does not match {len(self.moving)} moving, {n_s} simple vertices"
            )
        if self.basis.shape != (n_s * 3, 4):
            raise ConfigError(f"rig basis {self.basis.shape} must be ({n_s * 3}, 4)")
        if len(self.moving) and (self.moving.min() < 0 or self.moving.max() >= n_h):
            raise ConfigError("rig moving-vertex index out of range")
        object.__setattr__(self, "matrix", sp.csr_matrix(self.matrix, dtype=np.float32))
        object.__setattr__(self, "basis", np.ascontiguousarray(self.basis, dtype=np.float32))
        # A dense map (the RBF method: every control point reaches every vertex) costs more as a
        # sparse product than its folded (n_moving*3, 4) form; Sec. 5 rigs (3 per row) stay sparse.
        rows = max(self.matrix.shape[0], 1)
        folded = None
        if self.matrix.nnz > 12 * rows:
            folded = np.ascontiguousarray(self.matrix @ self.basis, dtype=np.float32)
        object.__setattr__(self, "_folded", folded)

    def displacements(self, params: np.ndarray) -> np.ndarray:
        """Head displacement (n_moving, 3) float32 (head units) of the moving vertices for params (4,) (IOD).

        One CSR product S @ (basis @ p); for dense (RBF) rigs the precomputed S @ basis instead.
        """
        p = np.asarray(params, dtype=np.float32).reshape(4)
        if self._folded is not None:
            return (self._folded @ p).reshape(-1, 3)
        return (self.matrix @ (self.basis @ p)).reshape(-1, 3)

    def deformed(self, params: np.ndarray) -> np.ndarray:
        """All head vertices (n_h, 3) float32 for params (4,)."""
        out = np.array(self.neutral, dtype=np.float32, copy=True)
        out[self.moving] += self.displacements(params)
        return out


def head_weights(
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    simple: FaceModel,
    frame: FaceFrame,
    *,
    config: RigConfig = RigConfig(),
    head_uvs: np.ndarray | None = None,
    training: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    seam_pairs: np.ndarray | None = None,
    lower_lip: np.ndarray | None = None,
) -> tuple[sp.csr_matrix, np.ndarray, dict[str, Any]]:
    """Weights G (n_h, n_s) CSR from simple-vertex to head-vertex displacement, control points (n_s,)
    and a dict of diagnostics. head_vertices (n_h, 3), head_triangles (m, 3); ``simple`` already
    placed in head coordinates; ``frame`` the head's face frame (IOD scale); ``training`` (n_s, c)
    displacement fields for the RBF's GCV; ``allowed`` (n_h,) bool control-point candidates;
    ``seam_pairs`` (k, 2) the (upper, lower) sides of a cut lip seam, coincident at rest, and
    ``lower_lip`` (n_s,) bool the simple vertices that open with the jaw: a control point that
    landed on the wrong side of the seam (both sides are equally close) moves to the other side."""
    h = np.asarray(head_vertices, dtype=np.float64)
    proj = project(
        simple.vertices,
        simple.triangles,
        h,
        head_triangles,
        candidates=config.candidates,
        geodesic_check=config.geodesic_check,
        allowed=allowed,
        walk=config.geodesic_walk,
        slack=config.geodesic_slack,
    )
    iod = frame.iod
    if seam_pairs is not None and lower_lip is not None and len(seam_pairs):
        ctrl = proj.control.copy()
        to_lower = dict(zip(seam_pairs[:, 0].tolist(), seam_pairs[:, 1].tolist()))
        to_upper = dict(zip(seam_pairs[:, 1].tolist(), seam_pairs[:, 0].tolist()))
        taken = set(ctrl.tolist())
        for i, c in enumerate(ctrl.tolist()):
            other = to_lower.get(c) if lower_lip[i] else to_upper.get(c)
            if other is not None and other not in taken:
                taken.discard(c)
                taken.add(other)
                ctrl[i] = other
        proj = replace(proj, control=ctrl)
    info = {
        "bad_triangles": int(proj.bad_triangles.sum()),
        "replacements": int(proj.replacements),
        "control_rms_offset_iod": float(np.sqrt(((h[proj.control] - simple.vertices) ** 2).sum(1).mean()) / iod),
    }
    if config.method in ("sec5", "harmonic"):
        if config.projection_2d == "uv":
            if head_uvs is None:
                raise ConfigError("projection_2d='uv' needs head texture coordinates")
            q = np.asarray(head_uvs, dtype=np.float64)
        else:
            q = (h - frame.origin) @ frame.axes[:2].T
        icfg = InterpolationConfig(
            beta=config.beta,
            max_depth=config.max_depth * iod,
            fallback_radius=None if config.fallback_radius is None else config.fallback_radius * iod,
            max_geodesic_ratio=config.max_geodesic_ratio,
            normalize_fallback=config.normalize_fallback,
            geodesic_limit=3.0 * (config.fallback_radius or 1.0) * iod,
        )
        it = interpolation_weights(
            h,
            q,
            proj.control,
            simple.triangles,
            config=icfg,
            triangle_mask=~proj.bad_triangles,
            head_triangles=head_triangles if config.connectivity else None,
        )
        g = it.weights
        info["inside"] = int(it.inside.sum())
        if config.method == "harmonic":
            from realtime_core.face.harmonic import harmonic_weights

            g = harmonic_weights(h, head_triangles, proj.control, g.tocsr(), margin=HARMONIC_MARGIN * iod)
    else:
        y = training if training is not None else np.zeros((simple.n_vertices, 1))
        fit = rbf_map(h, h[proj.control], y, radius=None if config.rbf_radius is None else config.rbf_radius * iod)
        w = fit.weights
        if config.fallback_radius is not None:
            from scipy.spatial import cKDTree

            dm, _ = cKDTree(h[proj.control]).query(h)
            w = w * np.exp(-((dm / (config.fallback_radius * iod)) ** 2))[:, None]
        w[np.abs(w) < 1e-4 * max(np.abs(w).max(), 1e-300)] = 0.0
        g = sp.csr_matrix(w)
        info.update(rbf_lambda=fit.lam, rbf_radius_iod=fit.radius / iod)
    return g.tocsr(), proj.control, info


def build_rig(
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    simple: FaceModel,
    calibration: MouthCalibration,
    frame: FaceFrame,
    *,
    config: RigConfig = RigConfig(),
    head_uvs: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    meta: dict[str, Any] | None = None,
    keep_apart: np.ndarray | None = None,
) -> Rig:
    """Rig a head (n_h, 3)/(m, 3) with a placed simple model and its mouth calibration (see head_weights).

    Coincident vertices are welded for the connectivity tests and share weights, except those in
    ``keep_apart`` (indices, e.g. the copies made by cutting a lip seam), which stay separate.
    """
    basis = calibration.basis(simple)  # (n_s*3, 4)
    h = np.asarray(head_vertices, dtype=np.float64)
    canon, welded = weld(h, keep_apart=keep_apart)
    seam_w = lower = None
    if keep_apart is not None and len(keep_apart):
        # The copies of a cut seam and the vertices they were copied from (coincident at rest).
        from scipy.spatial import cKDTree

        ka = np.asarray(keep_apart, dtype=np.int64)
        others = np.setdiff1d(np.arange(len(h)), ka)
        d, j = cKDTree(h[others]).query(h[ka])
        ok = d <= 1e-9 * max(float(np.ptp(h, axis=0).max()), 1e-300)
        seam_w = np.column_stack([canon[others[j[ok]]], canon[ka[ok]]])
        # Simple vertices that the mouth-open column moves down (relative to its largest motion): lower lip.
        dy = basis[:, 2].reshape(-1, 3) @ frame.axes[1]
        lower = dy < -0.3 * max(float(np.abs(dy).max()), 1e-300)
    t_w = canon[np.asarray(head_triangles, dtype=np.int64)]
    allowed_w = None
    if allowed is not None:
        allowed_w = np.zeros(len(welded), dtype=bool)
        np.logical_or.at(allowed_w, canon, np.asarray(allowed, dtype=bool))
    uv_w = None
    if head_uvs is not None:
        uv_w = np.zeros((len(welded), 2))
        uv_w[canon] = head_uvs  # one of the twins' texture coordinates
    g_w, control_w, info = head_weights(
        welded,
        t_w,
        simple,
        frame,
        config=config,
        head_uvs=uv_w,
        training=basis.reshape(simple.n_vertices, 3 * 4),
        allowed=allowed_w,
        seam_pairs=seam_w,
        lower_lip=lower,
    )
    # Every original vertex (texture-seam twins included) takes its welded vertex's weights.
    g = g_w[canon]
    first = np.full(len(welded), -1, dtype=np.int64)
    first[canon[::-1]] = np.arange(len(h))[::-1]
    control = first[control_w]
    info["welded_vertices"] = int(len(h) - len(welded))
    moving = np.flatnonzero(np.diff(g.indptr) > 0)
    s = sp.kron(g[moving], sp.identity(3, format="csr"), format="csr")
    m = dict(meta or {})
    m.update(
        info,
        algorithm=RIG_ALGORITHM,
        method=config.method,
        projection_2d=config.projection_2d,
        beta=config.beta,
        iod=frame.iod,
    )
    return Rig(
        neutral=np.asarray(head_vertices, dtype=np.float32),
        triangles=np.asarray(head_triangles, dtype=np.int32),
        moving=moving.astype(np.int64),
        matrix=s,
        basis=basis,
        control=control,
        simple=simple,
        calibration=calibration,
        meta=m,
    )


def weld(
    vertices: np.ndarray, *, tolerance: float = 1e-9, keep_apart: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident vertices (texture seams split them in most files).

    vertices (n, 3) -> canon (n,) index of each vertex's welded copy, welded (n_w, 3). Positions
    are compared after rounding to ``tolerance`` times the mesh extent.
    """
    v = np.asarray(vertices, dtype=np.float64)
    scale = max(float(np.ptp(v, axis=0).max()), 1e-300) * tolerance
    key = np.round(v / scale).astype(np.int64)
    if keep_apart is not None and len(keep_apart):
        # A fourth key column that is unique for the listed vertices and 0 for all others.
        tag = np.zeros((len(v), 1), dtype=np.int64)
        tag[np.asarray(keep_apart, dtype=np.int64), 0] = np.arange(1, len(keep_apart) + 1)
        key = np.hstack([key, tag])
    _, first, canon = np.unique(key, axis=0, return_index=True, return_inverse=True)
    # Keep the file's vertex order (np.unique sorts by position, which a rotation would change).
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[canon.reshape(-1)], v[first[order]]


def head_response(rig: Rig, landmarks: MouthLandmarks, *, probe: float = 0.05) -> np.ndarray:
    """(4, 4) mouth parameters measured on the rigged head (its own landmarks, IOD units) per unit
    of each requested parameter: column j = measure(deformed(probe * e_j)) / probe."""
    from realtime_core.face.model import measure_mouth

    landmarks.check(len(rig.neutral))
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    r = np.zeros((4, 4))
    for j in range(4):
        p = np.zeros(4)
        p[j] = probe
        r[:, j] = measure_mouth(v0, rig.deformed(p).astype(np.float64), landmarks) / probe
    return r


def recalibrate(rig: Rig, landmarks: MouthLandmarks, *, probe: float = 0.05, max_cond: float = 20.0) -> Rig:
    """The rig with its basis corrected so the *head* shows the requested parameters.

    The simple model is calibrated on its own geometry, but the interpolation (eq. 10's beta, the
    fading) changes how far the head's own lips move. Measuring the head's response R (4, 4) with
    :func:`head_response` and using basis @ R^-1 makes the parameters geometric on the target head
    (to first order). Skipped (meta "head_calibration": "skipped ...") when R is ill-conditioned or
    a diagonal entry is not positive (landmarks that do not see the motion).
    """
    r = head_response(rig, landmarks, probe=probe)
    meta = dict(rig.meta)
    meta["head_response"] = r.round(4).tolist()
    cond = float(np.linalg.cond(r))
    if not np.isfinite(cond) or cond > max_cond or np.any(np.diag(r) <= 0):
        meta["head_calibration"] = f"skipped (condition {cond:.3g}, diagonal {np.diag(r).round(3).tolist()})"
        return replace(rig, meta=meta)
    meta["head_calibration"] = "applied"
    return replace(rig, basis=rig.basis.astype(np.float64) @ np.linalg.inv(r), meta=meta)
