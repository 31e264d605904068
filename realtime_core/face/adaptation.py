"""Per-vertex affine adaptation of morph targets between two meshes of one topology (paper 001 Sec. 3.9).

For each triangle p = (i, j, k) the affine map A_p solves y_q = A_p x_q for q = i, j, k, with
x_q = v_q - v_C (generic model) and y_q = v~_q - v~_C (specific model), v_C and v~_C the centres
(vertex means) of the two models. A vertex's map is the area-weighted mean of its triangles' maps,
A^_i = sum s_p A_p / sum s_p (eq. 3); a triangle whose X = [x_i x_j x_k] is singular (zero area, or
its vertices coplanar with the centre) gets weight zero. A displacement moves as dv~_i = A^_i dv_i.
"""

from __future__ import annotations

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.normals import triangle_normals


def affine_adaptation(
    generic: np.ndarray,
    specific: np.ndarray,
    triangles: np.ndarray,
    *,
    max_cond: float = 1e6,
    max_gain: float | None = None,
) -> np.ndarray:
    """Per-vertex affine maps (n, 3, 3) taking generic (n, 3) displacements to the specific (n, 3) mesh.

    Vertices none of whose triangles is regular get the isotropic map s * I, s the ratio of the
    two models' RMS radii.
    """
    g = np.asarray(generic, dtype=np.float64)
    s = np.asarray(specific, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if g.shape != s.shape or g.ndim != 2 or g.shape[1] != 3:
        raise ConfigError(f"generic {g.shape} and specific {s.shape} must both be (n, 3)")
    x = g - g.mean(0)
    y = s - s.mean(0)
    xt = np.transpose(x[t], (0, 2, 1))  # (m, 3, 3) columns x_i, x_j, x_k
    yt = np.transpose(y[t], (0, 2, 1))
    area = 0.5 * np.linalg.norm(triangle_normals(g, t), axis=1)
    cond = np.linalg.cond(xt)
    regular = np.isfinite(cond) & (cond < max_cond) & (area > 0)
    a = np.zeros_like(xt)
    a[regular] = yt[regular] @ np.linalg.inv(xt[regular])
    w = np.where(regular, area, 0.0)
    acc = np.zeros((len(g), 3, 3))
    wsum = np.zeros(len(g))
    for c in range(3):
        np.add.at(acc, t[:, c], w[:, None, None] * a)
        np.add.at(wsum, t[:, c], w)
    ratio = float(np.sqrt((y**2).sum(1).mean() / max((x**2).sum(1).mean(), 1e-300)))
    out = np.broadcast_to(ratio * np.eye(3), acc.shape).copy()
    ok = wsum > 0
    out[ok] = acc[ok] / wsum[ok, None, None]
    if max_gain is not None:
        out = _gain_capped(out, max_gain * ratio)
    return out


def _gain_capped(maps: np.ndarray, cap: float) -> np.ndarray:
    """``maps`` (n, 3, 3) with every singular value above ``cap`` lowered to it (directions kept); maps within the cap
    are returned as they are, to the bit."""
    out = maps.copy()
    u, sv, vt = np.linalg.svd(maps)
    over = sv[:, 0] > cap
    if over.any():
        out[over] = u[over] @ (np.minimum(sv[over], cap)[:, :, None] * vt[over])
    return out


def adapt_displacements(maps: np.ndarray, displacements: np.ndarray) -> np.ndarray:
    """dv~_i = A^_i dv_i: maps (n, 3, 3), displacements (n, 3) -> (n, 3)."""
    return np.einsum("nij,nj->ni", maps, np.asarray(displacements, dtype=np.float64))
