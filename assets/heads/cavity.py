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

And one question every head without a texture raises: how dark is the inside of its mouth? Neither renderer
casts shadows, so a mouth's inside is lit like the face unless its colours say otherwise:
:func:`inside_light` (the light kept at a depth behind the lips' contact) darkens the built-in head's
inside (:func:`assets.heads.builtin.vertex_colors`) and every file head's (:func:`with_dark_mouth_inside`:
its mouth bag, teeth, tongue and gums).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from itertools import pairwise

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from assets.errors import LandmarkError
from assets.heads.mesh import SKIN_COLOR, HeadMesh
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


INNER_MOUTH_WORDS = ("teeth", "tooth", "gum", "tongue", "mouth")
"""A part whose name holds one of these lies inside the mouth (teeth, tongue, gums, a mouth bag)."""
CAVITY_COLOR = (0.09, 0.035, 0.035)  # dark red-brown: the shadowed back of a mouth

MOUTH_SHADE_START = 0.08
"""IOD behind the lip contact line where the inside of the mouth starts to darken: the incisors' front
(upper ~0.0, lower ~0.1 IOD behind it) stays lit."""
MOUTH_SHADE_LENGTH = 0.1
"""IOD: each this much deeper into the mouth keeps 1/e of the light (the lower teeth behind the mouth
corners, ~0.35 IOD: ~10%; the molars and the tongue's back, >= 0.6 IOD: the floor)."""
MOUTH_SHADE_FLOOR = 0.04
"""The darkest an inner-mouth surface gets (fraction of its colour)."""

INSIDE_RAMP = 0.1
"""IOD: the inside of an unpainted mouth bag goes from the skin's colour at the lips' crease to CAVITY_COLOR this
far from it: behind the lips' contact, or away from the crease (straight-line) (:func:`with_dark_mouth_inside`)."""
INSIDE_BOX = (0.1, 0.35, 0.5)
"""IOD: the inside of a mouth without inner-mouth parts lies at most this far past the corners (sideways), above and
below the mouth line (a mouth bag's walls, the lips' inner walls) for :func:`with_dark_mouth_inside`; any depth behind
the lips' contact (the stylised held-out head's bag floor, 0.7-0.8 IOD back, showed skin-coloured at /a/ past a 0.6
IOD limit)."""
INSIDE_SEED = 0.05
"""IOD: hidden vertices between the corners and this close to the mouth line (the lips' crease) start the inside."""
INSIDE_OPENING = 1.2
"""How much larger than the widest opening's ellipse (corners, inner-lip points) the inside that can show is (a mouth
without inner-mouth parts; a three-quarter view shows more of a modelled bag: its cheeks' lining past the corners)."""
PAINTED = 0.02
"""Colour units: vertex colours of the mouth bag that differ by more than this were painted by the file's author
(its hue is kept); within it, one colour (none, or a material's) gets CAVITY_COLOR."""
INSIDE_COVER = 0.01
"""IOD: a vertex with the head's surface more than this in front of it (along the face's forward axis, at rest)
is hidden from the front."""
SHADED_DEPTH = 0.3
"""IOD: the inside this far or more behind the lips' contact is what :data:`SHADED` looks at."""
SHADED = 0.3
"""An inside whose vertices SHADED_DEPTH IOD or more behind the contact are on average darker than this fraction
of the head's median vertex colour (brightest channel) is already shaded (the built-in head's colours, written
into a glb or rigged again): shading it again would darken it twice."""


def inside_light(depth: np.ndarray) -> np.ndarray:
    """(k,) fraction of its colour an inner-mouth surface keeps at ``depth`` (k,) IOD behind the lips' contact:
    all of it to MOUTH_SHADE_START, then exp(-(depth - start) / MOUTH_SHADE_LENGTH), never below
    MOUTH_SHADE_FLOOR. Both renderers light the inside of the mouth like the face (no shadows); the depth
    behind the lips stands in for the occlusion a real mouth's inside gets."""
    shade = np.exp(-np.maximum(np.asarray(depth) - MOUTH_SHADE_START, 0.0) / MOUTH_SHADE_LENGTH)
    return MOUTH_SHADE_FLOOR + (1 - MOUTH_SHADE_FLOOR) * shade


def shade_inside(colors: np.ndarray, depth: np.ndarray, *, lining: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(k, 3) float32: inner-mouth ``colors`` (k, 3) taken ``weight`` (k,) in [0, 1] of the way to the ``lining``
    colour (3,) (a mouth bag the file does not paint; 0 for teeth, tongue, a painted bag: their hue is kept),
    then darkened by :func:`inside_light` at ``depth`` (k,) IOD behind the lips' contact."""
    w = np.asarray(weight)[:, None]
    base = (1 - w) * colors + w * np.asarray(lining, dtype=np.float32)
    return (base * inside_light(depth)[:, None]).astype(np.float32)


def _inner_parts(mesh: HeadMesh) -> list[int]:
    """Indices into ``mesh.part_names`` of the parts inside its mouth (:data:`INNER_MOUTH_WORDS`)."""
    return [i for i, n in enumerate(mesh.part_names) if any(w in n.lower() for w in INNER_MOUTH_WORDS)]


def has_inner_mouth(mesh: HeadMesh) -> bool:
    """Whether a part of ``mesh`` lies inside its mouth (:data:`INNER_MOUTH_WORDS`)."""
    return bool(_inner_parts(mesh))


def inner_mouth_vertices(mesh: HeadMesh) -> np.ndarray:
    """(n,) bool: the vertices of ``mesh``'s inner-mouth parts (teeth, tongue, gums: :data:`INNER_MOUTH_WORDS`)."""
    out = np.zeros(len(mesh.vertices), dtype=bool)
    ids = _inner_parts(mesh)
    if mesh.part is None or not ids:
        return out
    part = np.asarray(mesh.part)[: len(out)]
    out[: len(part)] = np.isin(part, ids)
    return out


def with_dark_mouth_inside(
    mesh: HeadMesh,
    rest: np.ndarray,
    frame: FaceFrame,
    snap: Mapping[str, int],
    *,
    skip: int = 0,
    wide: np.ndarray | None = None,
    inside: np.ndarray | None = None,
) -> HeadMesh:
    """``mesh`` (untextured) with the inside of its mouth darkened by its depth behind the lips' contact
    (:func:`inside_light`): its inner-mouth parts (teeth, tongue, gums; :func:`inner_mouth_vertices`) and its mouth
    bag; the last ``skip`` vertices, a mouth cavity, keep theirs. ``rest`` (n, 3): the rig's neutral, lips touching;
    ``snap``: landmark vertex indices; ``wide`` (n, 3): the rig at its widest opening (None: no opening limit on a
    head without inner-mouth parts, and the contact's depth from the inner-lip points); ``inside`` (n,) bool: more
    vertices of inner-mouth parts, unnamed ones found by shape (:func:`assets.heads.parts.unnamed_inner_parts`).

    The bag: every skin vertex that the closed lips hide from the front at ``rest`` (the surface within
    INSIDE_COVER IOD in front of it does not count) and that lies behind the lips' contact (the inner-lip landmarks'
    front-most depth in the middle, the corners' at the corners, in between linearly across the mouth), at any
    depth, if the hidden vertices join it to the lips' crease (INSIDE_SEED: a crease elsewhere, the chin's fold under
    the lower lip, hidden at rest and shown when the jaw drops, is skin). On a head without inner-mouth parts (no
    modelled mouth bag: a hollow scan, a stylised head) also only in INSIDE_BOX around the mouth and, given ``wide``,
    where the opening can show it (INSIDE_OPENING); a head with them has the built-in head's bag (its cheeks' lining
    behind the corners, seen in three-quarter view). A bag the file does not paint (no vertex
    colours, or one colour within PAINTED: a material's) first takes CAVITY_COLOR in proportion to how far inside it
    is (its depth behind the contact or its distance from the lips' crease, whichever is larger), all of it from
    INSIDE_RAMP IOD on: without it the inner lip walls are skin-coloured, and a wall that crosses the opening at /a/
    shows as a light flap (the stylised held-out head). A painted bag, teeth and tongue keep their hue.

    The depth that darkens is measured from the lips' contact line (the skin vertices the widest opening parts,
    :func:`realtime_core.face.simple.lip_contact_vertices`, their median depth, as the built-in head's colours
    measure it; else the inner-lip points'): the front of the incisors stays lit, the molars and the tongue's back
    go dark, the lips' own faces, their front and the crease where they touch keep their colour. An inside already
    dark deep in (:data:`SHADED`) is left as it is."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from realtime_core.face.simple import lip_contact_vertices

    v = np.asarray(rest, dtype=np.float64)
    n0 = len(mesh.vertices)
    q = (v[:n0] - frame.origin) @ frame.axes.T
    iod = frame.iod
    cl, cr = q[snap["corner_left"]], q[snap["corner_right"]]
    mid = 0.5 * (cl + cr)
    half = 0.5 * abs(float(cl[0] - cr[0]))
    inner = inner_mouth_vertices(mesh)
    if inside is not None:
        inner[: len(inside)] |= np.asarray(inside, dtype=bool)[: len(inner)]
    inner[n0 - skip :] = False
    # The lips' contact runs from the inner-lip points back to the corners (tucked in on some heads): its depth at
    # each vertex's place across the mouth, so the corners themselves keep their colour.
    middle = max(float(q[snap["upper_inner"], 2]), float(q[snap["lower_inner"], 2]))
    ends = 0.5 * float(cl[2] + cr[2])
    contact = middle + (min(ends, middle) - middle) * np.clip(np.abs(q[:, 0] - mid[0]) / max(half, 1e-300), 0.0, 1.0)
    side, up, down = INSIDE_BOX
    dy = q[:, 1] - mid[1]
    # A head with its own teeth, tongue or gums has a mouth bag around them: all of its hidden skin behind the
    # contact joined to the crease is inside, as the built-in head's (assets.heads.builtin.mouth_bag). Not one rule:
    # the built-in's, seeded by its contact line, also takes the lips' hidden walls in front of the contact (141
    # vertices its crease shade skips: under this rule they darken by up to 0.69). Bounded by the box and the opening
    # (below), its cheeks' inner walls behind the corners (up to 0.19 IOD past them) stayed skin-coloured and showed
    # as a light wall at the near corner in three-quarter view at /a/ (the multi-material OBJ, the --head-part row).
    # A head without one reaches further that way (a hollow scan's inside, the chin's fold): the box bounds it.
    modelled = bool(inner.any())
    box = (q[:, 2] < contact) & ~inner
    if not modelled:
        box &= (np.abs(q[:, 0] - mid[0]) <= half + side * iod) & (dy <= up * iod) & (dy >= -down * iod)
    box[n0 - skip :] = False
    bag = np.flatnonzero(box)
    crease = np.zeros((0, 3))
    if len(bag):
        front = front_depth(v, mesh.triangles, frame, q[bag, :2])
        bag = bag[np.isfinite(front) & (front > q[bag, 2] + INSIDE_COVER * iod)]
        # Only what is reached from the lips' contact through hidden vertices.
        _, label = connected_components(vertex_adjacency(n0, mesh.triangles)[bag][:, bag], directed=False)
        seed = (np.abs(q[bag, 0] - mid[0]) <= half) & (np.abs(dy[bag]) <= INSIDE_SEED * iod)
        crease = q[bag[seed]]
        if modelled:
            # Unbounded, hidden skin at the mouth line's height HOLLOW_DEPTH or more behind the lips is the back of
            # the head, not the crease: through it the back of the head and neck, hidden from the front but seen from
            # the side, joined the inside (the full-body avatars: 558 vertices 2.5-2.8 IOD back, the neck darkened).
            seed &= contact[bag] - q[bag, 2] < HOLLOW_DEPTH * iod
        bag = bag[np.isin(label, label[seed])]
    if wide is not None and len(bag) and not modelled:
        # And only what the widest opening can show: seen from the front there, inside the ellipse through its
        # corners and inner-lip points (INSIDE_OPENING times as large).
        w = (np.asarray(wide, dtype=np.float64)[:n0] - frame.origin) @ frame.axes.T
        wl, wr = w[snap["corner_left"]], w[snap["corner_right"]]
        wu, wd = w[snap["upper_inner"]], w[snap["lower_inner"]]
        cx, cy = 0.5 * (wl[0] + wr[0]), 0.5 * (wu[1] + wd[1])
        ax, ay = 0.5 * abs(float(wl[0] - wr[0])), max(0.5 * abs(float(wu[1] - wd[1])), 1e-9 * iod)
        r = ((w[bag, 0] - cx) / ax) ** 2 + ((w[bag, 1] - cy) / ay) ** 2
        bag = bag[r <= INSIDE_OPENING**2]
    textured = mesh.texture is not None
    if textured:
        # A texture paints the skin, the bag included, as its author meant (a scan's inner lip walls): only the teeth,
        # tongue and gums are darkened, by vertex colours the texture is multiplied by (glTF's COLOR_0 rule; the
        # renderer, the browser and exports apply it). Lit like the face they glowed white at the corners.
        bag = bag[:0]
    inside = np.r_[bag, np.flatnonzero(inner)]
    if not len(inside):
        return mesh
    line = np.zeros(0, dtype=np.int64)
    if wide is not None:
        skin = ~inner
        skin[n0 - skip :] = False
        centre = 0.5 * (v[snap["corner_left"]] + v[snap["corner_right"]])
        opening = np.asarray(wide, dtype=np.float64)[:n0] - v[:n0]
        line = lip_contact_vertices(v[:n0], opening, frame, mouth_centre=centre, candidates=skin, spacing=0.01)
    lips = float(np.median(q[line, 2])) if len(line) else middle
    depth = (lips - q[inside, 2]) / iod
    blank = np.ones(3, dtype=np.float32) if textured else np.asarray(SKIN_COLOR, dtype=np.float32)
    colors = np.array(mesh.colors, dtype=np.float32) if mesh.colors is not None else np.tile(blank, (n0, 1))
    bright = colors.max(axis=1)
    deep = depth >= SHADED_DEPTH
    if deep.any() and float(bright[inside[deep]].mean()) < SHADED * float(np.median(bright)):
        return mesh  # already dark inside: its author (or the built-in head's colours) shaded it
    weight = np.zeros(len(inside))
    if len(bag) and float(np.ptp(colors[bag], axis=0).max()) <= PAINTED:
        # How far inside: behind the contact, or away from the crease (a wall just behind the contact
        # but 0.2-0.3 IOD above the mouth line, the stylised head's, crosses the opening at /a/: it is no lip).
        far = np.maximum(contact[bag] - q[bag, 2], cKDTree(crease).query(q[bag])[0])  # crease: the bag is seeded
        weight[: len(bag)] = np.clip(far / (INSIDE_RAMP * iod), 0.0, 1.0)
    colors[inside] = shade_inside(colors[inside], depth, lining=np.asarray(CAVITY_COLOR), weight=weight)
    return replace(mesh, colors=colors)


def with_mouth_cavity(
    head,
    landmark_points: Mapping[str, object] | None = None,
    *,
    landmark_finder: Callable[[HeadMesh], Mapping[str, object]] | None = None,
):
    """A head driven by its own targets (:class:`assets.heads.head.Head` with a MorphRig): one whose mouth opens onto
    nothing gets the dark mouth cavity retargeted heads get (its floor following the jaw); without a texture, the
    inside of its mouth is darkened as a retargeted head's is (:func:`with_dark_mouth_inside`). Landmarks:
    ``landmark_points`` (name -> (3,) point) or the rig's meta; for an untextured head with inner-mouth parts and
    neither, ``landmark_finder(mesh)`` (the automatic landmarks; a full-body avatar's glb carries none). Without
    landmarks (or when the finder finds none) the head is returned unchanged (its mouth cannot be found)."""
    from assets.heads.head import Head
    from assets.heads.rigging import MASK_CAVITY, WIDE_OPEN, add_mouth_cavity, mouth_landmarks
    from realtime_core.face import face_frame

    rig, mesh = head.rig, head.mesh
    inner = has_inner_mouth(mesh)
    pts = landmark_points or rig.meta.get("landmarks")
    if not pts and inner and landmark_finder is not None:
        try:
            pts = dict(landmark_finder(mesh))
        except LandmarkError:
            pts = None  # no face found: the head as it came
        if pts:
            # Kept with the rig, as a retargeted head's are: found again on the shaded mesh (the finder reads a
            # render), they moved (the avatar's inner-lip points: its checks' lip interpenetration 0.0004 -> 0.0058).
            rig = replace(rig, meta={**rig.meta, "landmarks": {k: np.asarray(p).tolist() for k, p in pts.items()}})
            head = Head(rig, mesh)
    if not pts:
        return head
    v = np.asarray(mesh.vertices, dtype=np.float64)
    idx = {k: int(np.argmin(np.linalg.norm(v - np.asarray(p, dtype=np.float64), axis=1))) for k, p in pts.items()}
    frame = face_frame(v, mouth_landmarks(idx))
    if not inner and opens_onto_nothing(v, mesh.triangles, frame, idx):
        new_rig, new_mesh = add_mouth_cavity(
            rig, mesh, frame, idx["corner_left"], idx["corner_right"], shape=MASK_CAVITY
        )
        targets = None
        if mesh.targets:
            # The mesh's targets as the rig's: the cavity's floor follows the jaw (add_mouth_cavity).
            targets = {k: target_with_cavity(np.asarray(d), new_rig, k, len(v)) for k, d in mesh.targets.items()}
        head = Head(new_rig, replace(new_mesh, targets=targets))
    rest = np.asarray(head.rig.neutral, dtype=np.float64)
    wide = head.rig.deformed(np.array([0.0, 0.0, WIDE_OPEN, 0.0]))
    cavity = int(head.rig.meta.get("mouth_cavity", 0) or 0)
    shaded = with_dark_mouth_inside(head.mesh, rest, frame, idx, skip=cavity, wide=wide)
    return head if shaded is head.mesh else Head(head.rig, shaded)


def target_with_cavity(d: np.ndarray, rig, name: str, n0: int) -> np.ndarray:
    """A mesh target ``d`` (n0, 3) of the head's own vertices grown by the rows of the mouth cavity appended after
    them (rig's vertices n0..): the rig's target ``name`` there (its floor following the jaw), zero where the rig
    does not move the cavity or drives no such target (a Rig, which has no named targets)."""
    out = np.zeros((len(rig.neutral), 3), dtype=d.dtype)
    out[:n0] = d
    rows = np.flatnonzero(np.asarray(rig.moving) >= n0)
    names = tuple(getattr(rig, "names", ()))
    if name in names and len(rows):
        out[np.asarray(rig.moving)[rows]] = rig.targets[names.index(name)][rows]
    return out
