"""Dense heads (scans of 50k-500k triangles) rigged through a coarser copy of the same surface.

The rig's field, its fold repair and its checks cost time in the number of vertices: on Lee Perry-Smith subdivided
once (70,736 triangles) the whole rig took 666-1,107 s and 1.7 GB, 87% of it in the fold repair, and failed (3 flips
at mouth_open 0.465, stretch 3.38), while the same surface as shipped (17,519 triangles) rigs in 10 s and passes. So
(``rig_checked``, ``dense_proxy``) a head above :data:`DENSE_TRIANGLES` is decimated outside its mouth
(:func:`proxy_mesh`: the faces within MOUTH_KEEP of the mouth kept as they are, the rest to PROXY_TRIANGLES), the
proxy rigged and checked as any head, the dense mesh cut exactly as the proxy was (``rigging.cut_as_proxy``), and
each dense vertex given the proxy's displacement rows at its nearest point on the proxy surface, barycentrically
(:func:`carried_rows`; a kept vertex its own proxy vertex's rows), a vertex on one lip's side of the cut from that
lip's side of the proxy only (:func:`lip_sides`: closed lips touch, so the nearest proxy face of an upper-lip vertex
may be the lower lip's, and a blend across the cut tears the lip at every opening). The checks then run on the dense
rig: the once-subdivided head PASSES (0 flips, stretch 3.43) in 160 s and 1.24 GB (docs/animation.md, "A dense scan
through a decimated proxy").
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from trimesh.triangles import closest_point, points_to_barycentric

from assets.heads.mesh import HeadMesh
from realtime_core.face import Rig
from realtime_core.face.projection import edge_length_graph
from realtime_core.face.rig import modelled_rest
from realtime_core.face.welding import weld

DENSE_TRIANGLES = 40_000
"""Triangles above which a head is rigged through a decimated proxy (Lee Perry-Smith as shipped, 17,519, the full-body
avatar, 27,676, and every other head of the test set and the held-out table lie below it and rig as before)."""
MOUTH_KEEP = 0.6
"""Eye-corner distances: the proxy keeps the dense mesh's own faces within this of the mouth's centre (the lips, the
crease and the corners; :func:`proxy_mesh`)."""
PROXY_TRIANGLES = 6_000
"""The proxy's triangles outside the mouth region (MOUTH_KEEP). Decimated whole, the once-subdivided Lee Perry-Smith's
proxies failed their own checks at 17,500 and 9,000 triangles (2-30 flips) and passed at 4,000, whose long lip faces
then saw-toothed the dense lips; with the mouth kept, 6,000 + 14,450 kept passes (docs/animation.md, "A dense scan
through a decimated proxy")."""
SIDE_REACH = 0.3
"""IOD: how far along the surface from the cut a vertex counts as on a lip's side (an upper lip is about 0.3 IOD
tall); farther, the two lips' surfaces lie far apart and the nearest proxy face is on the right side anyway."""
CANDIDATE_FACES = 8
"""Proxy faces (nearest centroids) among which each dense vertex's nearest point is looked for, besides the faces
round its CORNER_FANS nearest proxy vertices."""
CORNER_FANS = 3

NO_SIDE, UPPER, LOWER = 0, 1, 2

CUT_DIP_WINDOW = 0.08
"""IOD: the proxy's closed-lip cut is levelled (``rigging.level_path``) from where the sides of its V stop rising, up
to this far along it either side of the front contact, not from its next vertices. The kept mouth has the scan's
short edges, which spread the cut's V down onto the lower lip's front over several of them: on the once-subdivided
Lee Perry-Smith 0.0145 IOD below the next vertices (under ``CONTACT_DIP``, 0.015, so kept), 0.029 below those 0.06
IOD away and 0.036 below the crease's row 0.1 IOD away, and the wedge of lower lip inside the V, on the upper side,
hung from the upper lip's middle into every small opening (the shipped head's neighbours are 0.05 IOD away and its
0.028 dip is bypassed). At 0.05 the detour joined the V's shoulders a row of faces below the crease: a thin pink strip
was left hanging there; at 0.08 it runs along the crease. The dense mesh is cut as the proxy (``cut_as_proxy``)."""

PROXY_AGGRESSIVENESS = 7.0
"""fast-simplification's ``agg`` (0-10; its default): at 17,500 triangles, 2 kept the lip line better (a cut of 51
vertices against 30 at 7; the shipped head's 49) and its rig nearer passing (2 flips against 30), but left faces
without area; at 4,000, 7 passes."""


def proxy_mesh(
    mesh: HeadMesh,
    triangles: int = PROXY_TRIANGLES,
    *,
    mouth: np.ndarray | None = None,
    keep: float = 0.0,
) -> HeadMesh:
    """``mesh`` decimated to about ``triangles`` triangles (fast-simplification's quadric decimation of the
    welded surface, so texture seams do not open): positions and triangles, each vertex's part that of the nearest
    vertex of ``mesh``; no UVs, texture or colours (the proxy is rigged, never drawn). ``mouth`` (3,) and ``keep``
    (head units): the faces within ``keep`` of ``mouth`` are kept as they are (the lips, where the rig's field
    changes fastest and the proxy's cut must be the dense mesh's) and only the rest is decimated, its border with
    them kept (``triangles`` then counts the rest only)."""
    import fast_simplification

    canon, welded = weld(mesh.vertices)
    t = canon[np.asarray(mesh.triangles, dtype=np.int64)]
    t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
    kept = np.zeros(len(t), dtype=bool)
    if mouth is not None and keep > 0:
        kept = (np.linalg.norm(welded - np.asarray(mouth, dtype=np.float64), axis=1) < keep)[t].all(axis=1)
    rest = t[~kept]
    used = np.unique(rest)
    remap = np.full(len(welded), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    if len(rest) > int(triangles):
        points, faces = fast_simplification.simplify(
            welded[used].astype(np.float64),
            remap[rest].astype(np.int32),
            target_count=int(triangles),
            agg=PROXY_AGGRESSIVENESS,
            preserve_border=bool(kept.any()),
        )
    else:  # already as coarse as asked (a scan dense at its mouth only): the rest kept as it is
        points, faces = welded[used], remap[rest]
    own = np.unique(t[kept])
    at = np.full(len(welded), -1, dtype=np.int64)
    at[own] = np.arange(len(own))
    v = np.vstack([welded[own], np.asarray(points, dtype=np.float64)])
    f = np.vstack([at[t[kept]], np.asarray(faces, dtype=np.int64) + len(own)])
    joined, v = weld(v)  # the kept border's vertices, once in each part
    f = joined[f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    v, f = v[used], remap[f]
    part = None
    if mesh.part is not None:
        _, j = cKDTree(np.asarray(mesh.vertices, dtype=np.float64)).query(v)
        part = np.asarray(mesh.part)[j]
    return HeadMesh(vertices=v, triangles=f, name=mesh.name, part=part, part_names=mesh.part_names)


def lip_sides(
    vertices: np.ndarray, triangles: np.ndarray, copies: np.ndarray, originals: np.ndarray, reach: float
) -> np.ndarray:
    """(n,) int8 each vertex's side of a cut lip seam: UPPER or LOWER when nearer (along the mesh's edges, within
    ``reach`` head units) to the seam's upper side ``originals`` than to its lower side ``copies`` (k,) or the other
    way round, else NO_SIDE. The two sides are welded apart, so a path crosses the lips at the mouth corners only."""
    v = np.asarray(vertices, dtype=np.float64)
    copies = np.asarray(copies, dtype=np.int64)
    canon, welded = weld(v, keep_apart=copies)
    t_w = canon[np.asarray(triangles, dtype=np.int64)]
    graph = edge_length_graph(welded, t_w)
    sides = np.zeros(len(v), dtype=np.int8)
    if not len(copies):
        return sides
    up = dijkstra(graph, indices=np.unique(canon[np.asarray(originals, dtype=np.int64)]), min_only=True, limit=reach)
    low = dijkstra(graph, indices=np.unique(canon[copies]), min_only=True, limit=reach)
    up, low = up[canon], low[canon]
    sides[np.isfinite(up) & (up < low)] = UPPER
    sides[np.isfinite(low) & (low < up)] = LOWER
    return sides


def seam_of(rig_vertices: np.ndarray, cut: int, cavity: int) -> tuple[np.ndarray, np.ndarray]:
    """A rigged mesh's cut seam: (copies, originals) (k,) each, the lower side's copies (appended after the mesh's
    own vertices, before the cavity's) and the upper side's vertices at their positions (as
    :func:`assets.heads.head.head_check_inputs` pairs them)."""
    v = np.asarray(rig_vertices, dtype=np.float64)
    n0 = len(v) - cut - cavity
    copies = np.arange(n0, n0 + cut)
    d, j = cKDTree(v[:n0]).query(v[copies])
    ok = d <= 1e-9 * float(np.ptp(v, axis=0).max())
    return copies[ok], j[ok]


def carried_rows(
    proxy_vertices: np.ndarray,
    proxy_triangles: np.ndarray,
    proxy_sides: np.ndarray,
    vertices: np.ndarray,
    sides: np.ndarray,
    *,
    proxy_part: np.ndarray | None = None,
    part: np.ndarray | None = None,
) -> sp.csr_matrix:
    """CSR (n, n_p) float64: each of ``vertices`` (n, 3) as the barycentric weights of its nearest point on the
    proxy's faces ``proxy_triangles`` (m, 3) over ``proxy_vertices`` (n_p, 3). A vertex on a lip's side (``sides``
    (n,), :func:`lip_sides`) looks only at proxy faces with a corner on its side and none on the other
    (``proxy_sides`` (n_p,)), so an upper-lip vertex never takes the lower lip's rows, nor a blend of both lips' from
    faces the proxy's cut left unsided (where the two cuts end at different places round a corner); with ``part``
    (n,) and ``proxy_part`` (n_p,), only at faces of its own part. Rows sum to 1."""
    pv = np.asarray(proxy_vertices, dtype=np.float64)
    pt = np.asarray(proxy_triangles, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    face_side = np.asarray(proxy_sides)[pt]
    has_up = (face_side == UPPER).any(axis=1)
    has_low = (face_side == LOWER).any(axis=1)
    face_part = np.zeros(len(pt), dtype=np.int64) if proxy_part is None else np.asarray(proxy_part)[pt[:, 0]]
    v_part = np.zeros(len(v), dtype=np.int64) if part is None or proxy_part is None else np.asarray(part)
    centroids = pv[pt].mean(axis=1)
    rows = np.zeros((len(v), 3), dtype=np.int64)
    weights = np.zeros((len(v), 3))
    for side in (NO_SIDE, UPPER, LOWER):
        for p in np.unique(v_part):
            who = np.flatnonzero((np.asarray(sides) == side) & (v_part == p))
            if not len(who):
                continue
            ok = face_part == p
            if side == UPPER:
                ok &= ~has_low & has_up
            elif side == LOWER:
                ok &= ~has_up & has_low
            faces = np.flatnonzero(ok)
            if not len(faces):
                faces = np.arange(len(pt))  # a part the proxy lost: the nearest face of any part
            k = min(CANDIDATE_FACES, len(faces))
            _, near = cKDTree(centroids[faces]).query(v[who], k=k)
            cand = faces[np.asarray(near).reshape(len(who), k)]  # (w, k)
            # And every allowed face round the nearest corners: on a mesh of mixed sizes a vertex's own faces may
            # have farther centroids than 8 small faces beside it.
            fan = _fans(pt[faces], len(pv))
            corners = np.unique(pt[faces])
            _, nv = cKDTree(pv[corners]).query(v[who], k=min(CORNER_FANS, len(corners)))
            near_fans = fan[corners[np.asarray(nv).reshape(len(who), -1)]].reshape(len(who), -1)
            cand = np.concatenate([cand, faces[np.where(near_fans >= 0, near_fans, near[:, :1])]], axis=1)
            k = cand.shape[1]
            tri = pv[pt[cand.ravel()]]  # (w*k, 3, 3)
            q = np.repeat(v[who], k, axis=0)
            foot = closest_point(tri, q)
            dist = np.linalg.norm(foot - q, axis=1).reshape(len(who), k)
            best = np.argmin(dist, axis=1)
            pick = np.arange(len(who)) * k + best
            with np.errstate(divide="ignore", invalid="ignore"):
                w = np.clip(points_to_barycentric(tri[pick], foot[pick]), 0.0, 1.0)
            bad = ~np.isfinite(w).all(axis=1) | (w.sum(axis=1) <= 0)
            if bad.any():  # a face without area (a decimation's sliver): its nearest corner
                corner = np.argmin(np.linalg.norm(tri[pick][bad] - foot[pick][bad][:, None], axis=2), axis=1)
                w[bad] = np.eye(3)[corner]
            weights[who] = w / w.sum(axis=1, keepdims=True)
            rows[who] = pt[cand[np.arange(len(who)), best]]
    b = sp.csr_matrix((weights.ravel(), (np.repeat(np.arange(len(v)), 3), rows.ravel())), shape=(len(v), len(pv)))
    b.sum_duplicates()
    b.eliminate_zeros()
    return b


def _fans(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(n_vertices, d) int64: each vertex's faces (rows of ``triangles``), padded with -1 to the largest valence."""
    t = np.asarray(triangles, dtype=np.int64)
    corner = t.ravel()
    face = np.repeat(np.arange(len(t)), 3)
    order = np.argsort(corner, kind="stable")
    corner, face = corner[order], face[order]
    count = np.bincount(corner, minlength=n_vertices)
    start = np.r_[0, np.cumsum(count)[:-1]]
    out = np.full((n_vertices, max(int(count.max(initial=0)), 1)), -1, dtype=np.int64)
    out[corner, np.arange(len(corner)) - start[corner]] = face
    return out


CARRIED_META = (
    "fold_repair",
    "open_response",
    "open_rescaled",
    "simple_gain_capped",
    "simple_corners_at_points",
    "upper_lip_eased",
)
"""The proxy rig's meta that describes the carried field (the rest describes the proxy's own mesh)."""


def carried_rig(proxy: Rig, proxy_mesh: HeadMesh, vertices: np.ndarray, triangles: np.ndarray, **kw: object) -> Rig:
    """A rig of ``vertices`` (n, 3) / ``triangles`` (m, 3) whose displacements are ``proxy``'s carried over
    (:func:`carried_rows`; ``kw``: its ``sides``, ``part`` and the proxy's ``proxy_sides``, ``proxy_part``): the
    same simple face, basis and calibration, each vertex's three matrix rows the barycentric sum of the proxy
    vertices' rows (rows, not weights over the simple face, so rigid rows carry too). ``proxy_mesh``: the mesh the
    proxy rig animates (its cavity, appended last, is never a source). Meta "proxy": the proxy's size and checks."""
    cut = int(proxy.meta.get("lip_seam_cut", 0) or 0)
    cavity = int(proxy.meta.get("mouth_cavity", 0) or 0)
    pv = modelled_rest(proxy).astype(np.float64)
    n_src = len(pv) - cavity
    pt = np.asarray(proxy.triangles, dtype=np.int64)
    pt = pt[(pt < n_src).all(axis=1)]
    b = carried_rows(pv[:n_src], pt, vertices=vertices, **kw)  # type: ignore[arg-type]
    own = np.flatnonzero(proxy.moving < n_src)  # the cavity's moving rows (its floor follows the jaw) are no source
    pick = sp.csr_matrix((np.ones(len(own)), (proxy.moving[own], own)), shape=(n_src, len(proxy.moving)))
    b_moving = (b @ pick).tocsr()
    moving = np.flatnonzero(np.diff(b_moving.indptr) > 0)
    rows = sp.kron(b_moving[moving], sp.identity(3, format="csr"), format="csr") @ proxy.matrix.astype(np.float64)
    _, near = cKDTree(np.asarray(vertices, dtype=np.float64)).query(pv[proxy.control])
    meta = {k: copy.deepcopy(proxy.meta[k]) for k in CARRIED_META if k in proxy.meta}
    meta["proxy"] = {
        "vertices": int(len(proxy_mesh.vertices)),
        "triangles": int(len(proxy_mesh.triangles)),
        "lip_seam_cut": cut,
        "checks": proxy.meta.get("checks"),
        "rig_attempts": proxy.meta.get("rig_attempts", []),
    }
    return Rig(
        neutral=np.asarray(vertices, dtype=np.float32),
        triangles=np.asarray(triangles, dtype=np.int32),
        moving=moving.astype(np.int64),
        matrix=rows.tocsr(),
        basis=proxy.basis,
        control=near.astype(np.int64),
        simple=proxy.simple,
        calibration=proxy.calibration,
        meta=meta,
    )
