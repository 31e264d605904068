"""What lies behind a head's lips: a lip membrane to open, a mouth that opens onto nothing.

Three questions every head without its own inner mouth raises, answered on the mesh alone:

- :func:`front_depth`: how far forward the head's surface lies at given face-frame (x, y) points (an
  orthographic ray cast along the face's forward axis, the way the automatic landmarks are cast back).
- :func:`lip_membrane`: the triangles that close a mouth between two *distinct* inner-lip contours
  (the MediaPipe canonical face closes its mouth with a strip of triangles from the upper inner lip
  to the lower one, 0.09 IOD tall). Cutting such a mouth along one contour leaves the strip hanging
  from the other lip: a light sliver between the lips that keeps them 0.05 IOD apart when they
  should meet. Removing the strip gives two lips that part and meet like the built-in head's.
- :func:`opens_onto_nothing`: does the mouth open onto empty space (a face mask such as Candide-3 or
  the MediaPipe face, or a hollow scan), rather than onto a mouth bag, teeth or tongue?
  Such heads get a dark mouth cavity (:func:`assets.heads.rigging.add_mouth_cavity`), and
  :func:`with_mouth_cavity` gives one to a head driven by its own targets.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from itertools import pairwise

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from realtime_core.face import FaceFrame
from realtime_core.face.projection import vertex_adjacency
from realtime_core.face.visibility import front_most

HOLLOW_DEPTH = 0.8
"""IOD: a mouth whose nearest surface behind the inner lips lies farther back than this (or nowhere)
opens onto nothing. The built-in head's mouth bag, teeth and tongue lie within 0.5 IOD of its lips;
a hollow scan's back of the head lies 2 IOD or more behind them."""


def front_depth(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, xy: np.ndarray, *, behind: float | None = None
) -> np.ndarray:
    """(k,) face-frame z (head units, along ``frame.axes[2]`` from ``frame.origin``) of the front-most
    surface under each face-frame point ``xy`` (k, 2) (head units), looking along -z; NaN where no
    triangle lies under the point. ``behind``: only surfaces with z below this count (a ray starting
    there, going back)."""
    q = (np.asarray(vertices, dtype=np.float64) - frame.origin) @ frame.axes.T
    t = np.asarray(triangles, dtype=np.int64)
    return front_most(np.asarray(xy, dtype=np.float64).reshape(-1, 2), q[t], below=behind, tolerance=1e-9)


def mouth_line_path(
    vertices: np.ndarray, triangles: np.ndarray, left: int, right: int, through: int, *, penalty: float = 20.0
) -> list[int]:
    """The edge path from mouth corner ``left`` to ``right`` through vertex ``through`` that stays
    closest to the straight corner-to-corner line (edge length plus ``penalty`` times both ends'
    distance from the line, as :func:`assets.heads.rigging.cut_mouth` chooses its seam). Empty when
    the corners are not connected to ``through``."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    a, b = v[left], v[right]
    ab = b - a
    length = float(np.linalg.norm(ab))

    def off_line(p: np.ndarray) -> np.ndarray:
        s = np.clip((p - a) @ ab / length**2, 0, 1)
        return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)

    adj = vertex_adjacency(len(v), t).tocoo()
    cost = np.linalg.norm(v[adj.row] - v[adj.col], axis=1) + penalty * (off_line(v[adj.row]) + off_line(v[adj.col]))
    g = sp.csr_matrix((cost + 1e-12, (adj.row, adj.col)), shape=(len(v), len(v)))

    def leg(a_: int, b_: int) -> list[int]:
        dist, pred = dijkstra(g, indices=a_, return_predecessors=True)
        if not np.isfinite(dist[b_]):
            return []
        p_ = [b_]
        while p_[-1] != a_:
            p_.append(int(pred[p_[-1]]))
        return p_[::-1]

    first, second = leg(left, through), leg(through, right)
    if not first or not second:
        return []
    return first + second[1:]


def lip_membrane(
    vertices: np.ndarray,
    triangles: np.ndarray,
    left: int,
    right: int,
    upper_inner: int,
    lower_inner: int,
) -> np.ndarray:
    """(m,) bool: the triangles that close the mouth between distinct inner-lip vertices ``upper_inner``
    and ``lower_inner`` (vertex indices; corners ``left``/``right``): the triangles enclosed by the
    corner-to-corner path through the upper inner lip and the one through the lower inner lip
    (:func:`mouth_line_path`), found by a flood fill over shared edges from the triangles at the
    inner-lip midpoints that crosses neither path. All False when the inner lips are one vertex
    (a closed seam, cut instead), when the two paths share more than half their vertices (the same
    seam), when a path is missing, or when the fill would leak past the paths (they do not enclose a
    region)."""
    t = np.asarray(triangles, dtype=np.int64)
    none = np.zeros(len(t), dtype=bool)
    if upper_inner == lower_inner:
        return none
    up = mouth_line_path(vertices, t, left, right, upper_inner)
    lo = mouth_line_path(vertices, t, left, right, lower_inner)
    if not up or not lo:
        return none
    if len(set(up) & set(lo)) > 0.5 * min(len(up), len(lo)):
        # Mostly one path: a closed seam whose inner-lip points snapped to neighbouring vertices
        # (automatic landmarks on Lee Perry-Smith: 21 of 26 shared), cut instead, not a membrane.
        return none
    fence = {tuple(sorted(e)) for p in (up, lo) for e in pairwise(p)}
    # Triangles sharing an edge that is not on a path are neighbours.
    edges: dict[tuple[int, int], list[int]] = {}
    for i, f in enumerate(t.tolist()):
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            edges.setdefault((min(a, b), max(a, b)), []).append(i)
    seed = [i for i, f in enumerate(t.tolist()) if upper_inner in f and lower_inner in f]
    if not seed:  # no triangle joins the two midpoints: not a membrane this reads
        return none
    region = np.zeros(len(t), dtype=bool)
    stack = list(seed)
    region[seed] = True
    limit = max(8, 4 * (len(up) + len(lo)))  # a strip between two paths holds about len(up) + len(lo) triangles
    while stack:
        i = stack.pop()
        f = t[i].tolist()
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            e = (min(a, b), max(a, b))
            if e in fence:
                continue
            for j in edges[e]:
                if not region[j]:
                    region[j] = True
                    stack.append(j)
        if region.sum() > limit:
            return none
    return region


def opens_onto_nothing(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, landmarks: Mapping[str, int]
) -> bool:
    """True when nothing of the head lies within :data:`HOLLOW_DEPTH` IOD behind the inner lips, over
    the middle of the mouth (five rays along -forward, from just behind the inner lips, between
    0.6 of the way to each corner): a mask or a hollow scan, not a head with a mouth bag, teeth or a
    tongue. ``landmarks``: vertex indices of the corners and the inner-lip midpoints."""
    q = (np.asarray(vertices, dtype=np.float64) - frame.origin) @ frame.axes.T
    iod = frame.iod
    ql, qr = q[landmarks["corner_left"]], q[landmarks["corner_right"]]
    qu, qd = q[landmarks["upper_inner"]], q[landmarks["lower_inner"]]
    y = 0.5 * (qu[1] + qd[1])
    xs = np.linspace(0.6 * qr[0] + 0.4 * qu[0], 0.6 * ql[0] + 0.4 * qu[0], 5)
    xy = np.column_stack([xs, np.full(5, y)])
    # Each ray starts just behind the lips at its place (the front-most surface there, else the inner lips).
    lips = front_depth(vertices, triangles, frame, xy)
    lips = np.where(np.isfinite(lips), lips, min(qu[2], qd[2])) - 0.02 * iod
    z = np.array([front_depth(vertices, triangles, frame, xy[i : i + 1], behind=lips[i])[0] for i in range(5)])
    near = np.isfinite(z) & (lips - z < HOLLOW_DEPTH * iod)
    return int(near.sum()) < 3


def with_mouth_cavity(head, landmark_points: Mapping[str, object] | None = None):
    """A head driven by its own targets (:class:`assets.heads.head.Head` with a MorphRig) whose mouth
    opens onto nothing gets the still, dark mouth cavity retargeted heads get; others come back as
    they are. Landmarks: ``landmark_points`` (name -> (3,) point) or the rig's meta; without them the
    head is returned unchanged (its mouth cannot be found)."""
    from assets.heads.head import Head
    from assets.heads.rigging import INNER_MOUTH_WORDS, MASK_CAVITY, add_mouth_cavity, mouth_landmarks
    from realtime_core.face import face_frame

    rig, mesh = head.rig, head.mesh
    pts = landmark_points or rig.meta.get("landmarks")
    if not pts or any(any(w in n.lower() for w in INNER_MOUTH_WORDS) for n in mesh.part_names):
        return head
    v = np.asarray(mesh.vertices, dtype=np.float64)
    idx = {k: int(np.argmin(np.linalg.norm(v - np.asarray(p, dtype=np.float64), axis=1))) for k, p in pts.items()}
    lm = mouth_landmarks(idx)
    frame = face_frame(v, lm)
    if not opens_onto_nothing(v, mesh.triangles, frame, idx):
        return head
    new_rig, new_mesh = add_mouth_cavity(rig, mesh, frame, idx["corner_left"], idx["corner_right"], shape=MASK_CAVITY)
    n_c = len(new_mesh.vertices) - len(v)
    targets = None
    if mesh.targets:
        targets = {
            k: np.vstack([np.asarray(d), np.zeros((n_c, 3), dtype=np.asarray(d).dtype)])
            for k, d in mesh.targets.items()
        }
    return Head(new_rig, replace(new_mesh, targets=targets))
