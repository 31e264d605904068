"""Derive a simple face model (the role Candide-3 plays in paper 000) from a head with morph targets.

Given a dense head mesh, its per-vertex morph targets (e.g. the 52 ARKit face units) and named
landmark vertices, pick ~100-300 vertices over the face by farthest-point sampling (denser around
the mouth, landmarks always included), triangulate them by a Delaunay triangulation of their frontal
projection, and drop every triangle that is not a patch of the surface: an edge whose shortest path
over the head mesh is much longer than the straight line (e.g. from the upper to the lower lip, the
path has to go round the mouth corner) or a sliver on the outline. The units of the simple model
are the targets sampled at the chosen vertices, so its motion is the head's own.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import Delaunay

from realtime_core.errors import ConfigError
from realtime_core.face.model import FaceFrame, FaceModel
from realtime_core.face.projection import vertex_adjacency


@dataclass(frozen=True)
class SimpleModelConfig:
    """Sizes in IOD. n_mouth: samples within mouth_radius of the mouth centre; n_total: all samples;
    region: face box in the face frame (x half-width, y min, y max, z min relative to the eye line);
    max_geodesic_ratio: drop triangle edges whose mesh path exceeds this multiple of their length."""

    n_mouth: int = 90
    n_total: int = 220
    mouth_radius: float = 0.75
    half_width: float = 1.15
    y_min: float = -2.3
    y_max: float = 0.9
    z_min: float = -0.45
    max_geodesic_ratio: float = 1.6
    max_edge: float = 0.7

    def __post_init__(self) -> None:
        if not 3 <= self.n_mouth <= self.n_total:
            raise ConfigError(f"need 3 <= n_mouth <= n_total, got {self.n_mouth}, {self.n_total}")


def frontal_visible(q: np.ndarray, *, cell: float = 0.03, tolerance: float = 0.05) -> np.ndarray:
    """(n,) bool: vertices q (n, 3) (face frame, IOD) on the front-most surface, by a coarse z-buffer.

    A vertex counts as visible if its depth is within ``tolerance`` of the largest depth of any
    vertex in its (x, y) grid cell or the 8 neighbouring cells; this drops the mouth cavity behind
    closed lips, the back of the head and the inside of the nostrils.
    """
    ij = np.floor(q[:, :2] / cell).astype(np.int64)
    ij -= ij.min(0)
    shape = tuple(ij.max(0) + 3)
    zbuf = np.full(shape, -np.inf)
    np.maximum.at(zbuf, (ij[:, 0] + 1, ij[:, 1] + 1), q[:, 2])
    best = zbuf.copy()
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            best = np.maximum(best, np.roll(np.roll(zbuf, dx, 0), dy, 1))
    return q[:, 2] >= best[ij[:, 0] + 1, ij[:, 1] + 1] - tolerance


def _fps(points: np.ndarray, seeds: list[int], n: int) -> list[int]:
    """Farthest-point sampling of n indices into points (k, 3), starting from ``seeds``."""
    chosen = list(dict.fromkeys(seeds))
    d = np.full(len(points), np.inf)
    for s in chosen:
        d = np.minimum(d, np.linalg.norm(points - points[s], axis=1))
    while len(chosen) < min(n, len(points)):
        i = int(np.argmax(d))
        if d[i] <= 0:
            break
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(points - points[i], axis=1))
    return chosen


def derive_simple_model(
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    targets: Mapping[str, np.ndarray],
    frame: FaceFrame,
    landmark_vertices: Mapping[str, int],
    *,
    mouth_centre: np.ndarray,
    candidates: np.ndarray | None = None,
    extra: np.ndarray | None = None,
    config: SimpleModelConfig = SimpleModelConfig(),
) -> tuple[FaceModel, np.ndarray]:
    """A simple face model and the head vertex (n_s,) each of its vertices was taken from.

    head_vertices (n_h, 3), head_triangles (m, 3), targets name -> (n_h, 3) displacement;
    frame: the head's face frame; landmark_vertices: name -> head vertex (always kept);
    mouth_centre (3,) head units; candidates (n_h,) bool: vertices that may be sampled (skin);
    extra: head vertices to keep like landmarks (e.g. the lip contact lines, which sit just behind
    the front-most surface).
    """
    h = np.asarray(head_vertices, dtype=np.float64)
    q = (h - frame.origin) @ frame.axes.T / frame.iod  # face frame, IOD units
    ok = (np.abs(q[:, 0]) <= config.half_width) & (q[:, 1] >= config.y_min) & (q[:, 1] <= config.y_max)
    ok &= q[:, 2] >= config.z_min
    if candidates is not None:
        ok &= np.asarray(candidates, dtype=bool)
    vis = np.zeros(len(h), dtype=bool)
    vis[ok] = frontal_visible(q[ok])
    lm_set = np.zeros(len(h), dtype=bool)
    lm_set[[int(x) for x in landmark_vertices.values()]] = True
    extra_idx = [] if extra is None else [int(x) for x in extra]
    lm_set[extra_idx] = True
    ok &= vis | lm_set  # the inner-lip landmarks sit just behind the lip surface
    pool = np.flatnonzero(ok)
    lm = [int(v) for v in landmark_vertices.values()]
    missing = [v for v in lm if not ok[v]]
    if missing:
        raise ConfigError(f"landmark vertices {missing} lie outside the face region")
    pos = {int(v): i for i, v in enumerate(pool)}
    seeds = [pos[v] for v in lm] + [pos[v] for v in extra_idx if v in pos]
    mc = (np.asarray(mouth_centre, dtype=np.float64) - frame.origin) @ frame.axes.T / frame.iod
    near_mouth = np.linalg.norm(q[pool] - mc, axis=1) <= config.mouth_radius
    mouth_pool = np.flatnonzero(near_mouth)
    mouth_seeds = [int(np.flatnonzero(mouth_pool == s)[0]) for s in seeds if near_mouth[s]]
    chosen_mouth = [int(mouth_pool[i]) for i in _fps(q[pool][mouth_pool], mouth_seeds, config.n_mouth)]
    chosen = _fps(q[pool], list(dict.fromkeys(seeds + chosen_mouth)), config.n_total)
    verts = pool[np.array(chosen)]

    tri = Delaunay(q[verts][:, :2]).simplices
    # Mesh-path lengths between the chosen vertices, bounded for speed.
    adj = vertex_adjacency(len(h), head_triangles).tocoo()
    w = np.linalg.norm(h[adj.row] - h[adj.col], axis=1)
    graph = sp.csr_matrix((w, (adj.row, adj.col)), shape=adj.shape)
    limit = config.max_edge * frame.iod * config.max_geodesic_ratio * 1.5
    geo = dijkstra(graph, indices=verts, limit=limit)[:, verts]
    keep = []
    for a, b, c in tri:
        good = True
        for u, v in ((a, b), (b, c), (c, a)):
            e = np.linalg.norm(h[verts[u]] - h[verts[v]])
            if e > config.max_edge * frame.iod or geo[u, v] > config.max_geodesic_ratio * e:
                good = False
                break
        if good:
            keep.append((a, b, c))
    if not keep:
        raise ConfigError("no triangle of the simple model survived the surface checks")
    triangles = np.array(keep, dtype=np.int64)
    units = {name: np.asarray(d, dtype=np.float64)[verts] for name, d in targets.items()}
    model = FaceModel(vertices=h[verts], triangles=triangles, animation_units=units, name="simple")
    return model, verts


def regional_shape_units(
    vertices: np.ndarray, frame: FaceFrame, centres: Mapping[str, np.ndarray], *, sigma: float = 0.45
) -> dict[str, np.ndarray]:
    """Candide-like shape units for a face model without any: smooth regional moves.

    vertices (n, 3) head units; centres: region name -> (3,) point (e.g. "eyes_left", "nose",
    "mouth", "chin"); sigma: Gaussian falloff in IOD. For each region: vertical and depth
    translation, and (for eyes and mouth) a horizontal stretch about the face midline; plus a global
    depth scale. Unit weight 1 moves the region's centre by 0.1 IOD.
    """
    v = np.asarray(vertices, dtype=np.float64)
    q = (v - frame.origin) @ frame.axes.T / frame.iod
    x_ax, y_ax, z_ax = frame.axes
    step = 0.1 * frame.iod
    units: dict[str, np.ndarray] = {}
    for name, c in centres.items():
        cq = (np.asarray(c, dtype=np.float64) - frame.origin) @ frame.axes.T / frame.iod
        w = np.exp(-((q - cq) ** 2).sum(1) / sigma**2)[:, None]
        units[f"{name} vertical"] = step * w * y_ax
        units[f"{name} depth"] = step * w * z_ax
        if name in ("eyes", "mouth", "cheeks"):
            units[f"{name} width"] = step * w * (q[:, :1] / max(abs(cq[0]), 0.5)) * x_ax
    units["face depth"] = step * q[:, 2:3] * z_ax
    units["face width"] = step * q[:, 0:1] * x_ax
    return units


def lip_contact_vertices(
    vertices: np.ndarray,
    jaw: np.ndarray,
    frame: FaceFrame,
    *,
    mouth_centre: np.ndarray,
    candidates: np.ndarray | None = None,
    gap: float = 0.04,
    spacing: float = 0.07,
) -> np.ndarray:
    """Vertices along the two lip contact lines of a closed mouth, about ``spacing`` IOD apart.

    vertices (n, 3); jaw (n, 3) a jaw-opening morph target (it moves the lower lip, not the upper);
    a contact vertex is a skin vertex within 0.8 IOD of the mouth centre that lies within ``gap``
    IOD of a vertex of the other lip. Returns head vertex indices (k,).
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    m = np.linalg.norm(np.asarray(jaw, dtype=np.float64), axis=1)
    near = np.linalg.norm(v - np.asarray(mouth_centre), axis=1) <= 0.8 * frame.iod
    if candidates is not None:
        near &= np.asarray(candidates, dtype=bool)
    if not near.any() or m[near].max() <= 0:
        return np.zeros(0, dtype=np.int64)
    rel = m / m[near].max()
    upper = np.flatnonzero(near & (rel < 0.15))
    lower = np.flatnonzero(near & (rel > 0.5))
    if len(upper) == 0 or len(lower) == 0:
        return np.zeros(0, dtype=np.int64)
    d_u, _ = cKDTree(v[lower]).query(v[upper])
    d_l, _ = cKDTree(v[upper]).query(v[lower])
    out = []
    for side in (upper[d_u <= gap * frame.iod], lower[d_l <= gap * frame.iod]):
        if len(side) == 0:
            continue
        q = v[side] / frame.iod
        chosen = [int(np.argmin(q[:, 0]))]
        d = np.linalg.norm(q - q[chosen[0]], axis=1)
        while d.max() > spacing:
            i = int(np.argmax(d))
            chosen.append(i)
            d = np.minimum(d, np.linalg.norm(q - q[i], axis=1))
        out.extend(side[chosen].tolist())
    return np.array(sorted(set(out)), dtype=np.int64)
