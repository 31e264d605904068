"""Interpolation (paper 000 Sec. 5.2): every head vertex follows three control points.

Each head vertex k is assigned to the simple-model triangle that contains it in a 2D projection
(the texture map, or a frontal view of the face); with the triangle's control points z_1..z_3 its
displacement is eq. 8, dv_k = sum_i gamma_ki dz_ki, with gamma_k from eq. 9. We read eq. 9 in
homogeneous 2D coordinates, gamma_k = [z_1 z_2 z_3; 1 1 1]^-1 [p_k; 1], i.e. the barycentric
coordinates of p_k, which sum to one, so a rigid or similarity motion of the three control points
moves the vertex the same way. A frontal projection also puts the back of the head, the inside of
the mouth and the teeth "inside" face triangles, so an assignment is only accepted when the vertex
lies within ``max_depth`` of the triangle's plane. Vertices outside every triangle use eq. 10:
dv_k = beta * sum_i dz_ki exp(-(d_i - d_m)^2 / d_m^2) over the three nearest control points (d_m the
smallest distance). Far from the face eq. 10 would still copy the nearest (boundary) control
points; ``fallback_radius`` (a documented extension, None = the paper) fades it by
exp(-(d_m / radius)^2).

Connectivity (an extension in the spirit of the Sec. 5.1 geodesic check; used when the head's
triangles are given): distances d_i are measured along the mesh (Dijkstra over edges, up to
``geodesic_limit``), a vertex may only take a triangle whose nearest control point is reachable
within ``max_geodesic_ratio`` times the straight distance, and eq. 10 takes the three
*geodesically* closest control points. Without this, the inside of the upper lip, which projects
onto the lower lip's triangles in a frontal view, would follow the jaw. Parts with no path to
any control point (teeth, tongue, eyes) move rigidly: every vertex of such a part takes the eq. 10
weights of the part's centroid (Euclidean, as in the paper), so teeth are not torn apart by the
upper and lower lip. Control points themselves always follow their own simple vertex (gamma = e_i).

All weights go into one sparse (n_head, n_simple) matrix G; displacements follow as G @ dZ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from realtime_core.errors import ConfigError


@dataclass(frozen=True)
class InterpolationConfig:
    """beta: eq. 10 gain (paper: 0.5). max_depth: head units, how far off a triangle's plane a
    vertex may be and still be interpolated by it. fallback_radius: head units or None.
    barycentric_tolerance: how far outside a triangle (in barycentric units) still counts as inside.
    normalize_fallback: divide eq. 10's weights by their sum (then beta = 1 reproduces a motion the
    three control points share; the paper's form gives between beta and 3 beta of it)."""

    beta: float = 0.5
    max_depth: float = np.inf
    fallback_radius: float | None = None
    barycentric_tolerance: float = 1e-6
    max_geodesic_ratio: float = 2.0
    geodesic_limit: float = np.inf
    normalize_fallback: bool = False

    def __post_init__(self) -> None:
        if not 0 <= self.beta <= 1.5:
            raise ConfigError(f"beta must be in [0, 1.5], got {self.beta}")
        if not self.max_depth > 0:
            raise ConfigError(f"max_depth must be > 0, got {self.max_depth}")
        if self.fallback_radius is not None and not self.fallback_radius > 0:
            raise ConfigError(f"fallback_radius must be > 0 or None, got {self.fallback_radius}")


@dataclass(frozen=True)
class Interpolation:
    """weights: (n_head, n_simple) CSR; inside: (n_head,) bool, vertices interpolated by eq. 8-9."""

    weights: sp.csr_matrix
    inside: np.ndarray


def barycentric_2d(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of 2D points p (..., 2) in triangles (a, b, c) (..., 2) each."""
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[..., 0] * v1[..., 1] - v1[..., 0] * v0[..., 1]
    # A degenerate triangle (den 0) gives inf/nan coordinates, which no inside test accepts: no warning for them.
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (v2[..., 0] * v1[..., 1] - v1[..., 0] * v2[..., 1]) / den
        l2 = (v0[..., 0] * v2[..., 1] - v2[..., 0] * v0[..., 1]) / den
        return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)


def interpolation_weights(
    head_vertices: np.ndarray,
    head_2d: np.ndarray,
    control: np.ndarray,
    simple_triangles: np.ndarray,
    *,
    config: InterpolationConfig = InterpolationConfig(),
    triangle_mask: np.ndarray | None = None,
    head_triangles: np.ndarray | None = None,
) -> Interpolation:
    """Sparse interpolation matrix for a head.

    head_vertices (n_h, 3) and head_2d (n_h, 2) (texture or frontal coordinates, any unit);
    control (n_s,) head vertex index of each simple vertex; simple_triangles (m_s, 3);
    triangle_mask (m_s,) bool, triangles allowed (e.g. those passing the geodesic check);
    head_triangles (m_h, 3): enables the connectivity rules (see the module docstring).
    """
    h = np.asarray(head_vertices, dtype=np.float64)
    q = np.asarray(head_2d, dtype=np.float64)
    ctrl = np.asarray(control, dtype=np.int64)
    tri = np.asarray(simple_triangles, dtype=np.int64)
    if q.shape != (len(h), 2):
        raise ConfigError(f"head_2d must be ({len(h)}, 2), got {q.shape}")
    if triangle_mask is not None:
        tri = tri[np.asarray(triangle_mask, dtype=bool)]
    n_h, n_s = len(h), len(ctrl)
    best_tri = np.full(n_h, -1, dtype=np.int64)
    best_gamma = np.zeros((n_h, 3))
    best_depth = np.full(n_h, np.inf)
    tol = config.barycentric_tolerance
    # Length tolerance relative to the head's size: ties (seam twins, shared triangle edges) must
    # resolve the same way whatever the head's scale and orientation.
    eps = 1e-9 * max(float(np.ptp(h, axis=0).max()), 1e-300)
    q_eps = 1e-9 * max(float(np.ptp(q, axis=0).max()), 1e-300)
    z2 = q[ctrl]  # (n_s, 2) control points in 2D
    z3 = h[ctrl]
    geo = None
    if head_triangles is not None:
        geo = _geodesic_from_controls(h, head_triangles, ctrl, config.geodesic_limit)  # (n_s, n_h)
    for t_i, (a, b, c) in enumerate(tri):
        lo = np.minimum(np.minimum(z2[a], z2[b]), z2[c])
        hi = np.maximum(np.maximum(z2[a], z2[b]), z2[c])
        cand = np.flatnonzero(np.all((q >= lo - q_eps) & (q <= hi + q_eps), axis=1))
        if cand.size == 0:
            continue
        g = barycentric_2d(q[cand], z2[a], z2[b], z2[c])
        ok = np.all(g >= -tol, axis=1) & np.all(np.isfinite(g), axis=1)
        cand, g = cand[ok], g[ok]
        if cand.size == 0:
            continue
        # Depth: distance from the vertex to the 3D point with the same barycentric coordinates.
        p3 = g @ np.stack([z3[a], z3[b], z3[c]])
        depth = np.linalg.norm(h[cand] - p3, axis=1)
        ok_depth = depth <= config.max_depth
        if geo is not None:
            tv = np.array([a, b, c])
            eu = np.linalg.norm(h[cand][:, None, :] - z3[tv][None, :, :], axis=2).min(1)
            gd = geo[tv][:, cand].min(0)
            ok_depth &= gd <= config.max_geodesic_ratio * eu + eps
            # Score by path length too: on a cut seam both copies of a vertex sit on the shared
            # edge of an upper and a lower triangle; each must take the one on its own side.
            depth = depth + gd
        better = (depth < best_depth[cand] - eps) & ok_depth
        sel = cand[better]
        best_tri[sel] = t_i
        best_gamma[sel] = g[better]
        best_depth[sel] = depth[better]
    inside = best_tri >= 0
    # A control point is a triangle corner: eq. 9 gives it gamma = e_i, whatever triangle it is in.
    own = np.zeros(n_h, dtype=bool)
    own[ctrl] = True
    inside &= ~own
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    idx = np.flatnonzero(inside)
    rows.append(np.repeat(idx, 3))
    cols.append(tri[best_tri[idx]].reshape(-1))
    vals.append(best_gamma[idx].reshape(-1))
    rows.append(ctrl)
    cols.append(np.arange(n_s))
    vals.append(np.ones(n_s))
    out = np.flatnonzero(~inside & ~own)
    anchor = h.copy()
    if geo is not None and head_triangles is not None and out.size:
        from realtime_core.face.welding import mesh_pieces

        # The head was welded by the caller (a cut seam's copies kept apart): its pieces as they are.
        comp = mesh_pieces(len(h), head_triangles)
        has_ctrl = np.zeros(comp.max() + 1, dtype=bool)
        has_ctrl[comp[ctrl]] = True
        loose = ~has_ctrl[comp]
        if loose.any():
            cnt = np.bincount(comp[loose], minlength=len(has_ctrl)).astype(np.float64)
            cen: np.ndarray = np.stack(
                [np.bincount(comp[loose], weights=h[loose, j], minlength=len(has_ctrl)) for j in range(3)], 1
            )
            cen /= np.maximum(cnt, 1)[:, None]
            anchor[loose] = cen[comp[loose]]
    if out.size and config.beta > 0:
        k = min(3, n_s)
        d, nn = cKDTree(z3).query(anchor[out], k=min(k + 2, n_s))
        d = d.reshape(len(out), -1)
        nn = nn.reshape(len(out), -1)
        order = np.lexsort((nn, np.round(d / eps)), axis=-1)[:, :k] if d.size else np.zeros((0, k), int)
        d = np.take_along_axis(d, order, axis=1)
        nn = np.take_along_axis(nn, order, axis=1)
        if geo is not None:
            g_out = geo[:, out].T  # (n_out, n_s)
            # Same gate as for triangles: a control point whose mesh path is much longer than the
            # straight line (the other lip, reached round the mouth corner) is not a neighbour.
            eu_out = np.empty_like(g_out)
            for lo in range(0, len(out), 2048):  # bounded memory on big heads
                eu_out[lo : lo + 2048] = np.linalg.norm(h[out[lo : lo + 2048]][:, None, :] - z3[None], axis=2)
            gated = np.where(g_out <= config.max_geodesic_ratio * eu_out + eps, g_out, np.inf)
            enough = np.isfinite(gated).sum(1) >= k
            g_out[enough] = gated[enough]
            reach = np.isfinite(g_out).sum(1) >= k
            if reach.any():
                # Stable sort of quantised distances: mirror-symmetric ties go to the lower index.
                gn = np.argsort(np.round(g_out[reach] / eps), axis=1, kind="stable")[:, :k]
                nn[reach] = gn
                d[reach] = np.take_along_axis(g_out[reach], gn, axis=1)
        dm = np.maximum(d[:, :1], 1e-12)
        w = config.beta * np.exp(-((d - dm) ** 2) / dm**2)
        if config.normalize_fallback:  # extension: a weighted mean, so beta = 1 copies a uniform motion
            w /= w.sum(1, keepdims=True) / config.beta
        if config.fallback_radius is not None:
            w *= np.exp(-((dm / config.fallback_radius) ** 2))
        keep = w > 1e-3 * config.beta  # drop negligible weights: fewer moving vertices, cheaper frames
        rows.append(np.repeat(out, k)[keep.reshape(-1)])
        cols.append(nn.reshape(-1)[keep.reshape(-1)])
        vals.append(w.reshape(-1)[keep.reshape(-1)])
    g_mat = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_h, n_s))
    g_mat.sum_duplicates()
    return Interpolation(weights=g_mat, inside=inside)


def _geodesic_from_controls(h: np.ndarray, triangles: np.ndarray, ctrl: np.ndarray, limit: float) -> np.ndarray:
    """Edge-path distances (n_s, n_h) from every control point (inf beyond ``limit`` or unreachable)."""
    from scipy.sparse.csgraph import dijkstra

    from realtime_core.face.projection import edge_length_graph

    return dijkstra(edge_length_graph(h, triangles), indices=ctrl, limit=limit)
