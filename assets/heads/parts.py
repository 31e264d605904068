"""Separate head parts (eyes, teeth, tongue) as rigid components of a retargeted head.

Heads often come with the eyes, teeth and tongue as separate meshes: objects of an OBJ, meshes of a
glTF scene, or files of their own (``--head head.obj --head-part eyes.obj --head-part teeth.obj``,
:func:`assets.heads.mesh.load_mesh`). Such a part has no control point of the simple face model, so
the rig would move it with whatever lies near its centroid (upper teeth pulled down by the lower
lip, eyeballs dragged by the cheeks). Here each part is classified by its name, and for teeth by
where it sits, and given a rigid motion:

- ``skull``: eyes (eyeball, iris, cornea, pupil, sclera, eyelashes...) and upper teeth/gums: still;
- ``jaw``: lower teeth/gums and the tongue: one displacement for every vertex, the chin landmark's (the jaw's
  motion; the lower outer-lip midpoint when the rig does not move the chin) sideways and forwards (square to the
  face's up axis), and TEETH_FOLLOW of the lower inner lip's drop along that axis (the lower teeth's edge shows
  above the lip as the built-in head's does, not their whole front).

The part holding the face (the nose-tip landmark) is never reclassified, whatever its name. A teeth
part whose name says neither upper nor lower is split by connected pieces: above the mouth line
(the corners' midpoint, along the face's up direction) upper, below lower. A head exported as one mesh with its teeth
inside names no part: its teeth rows and tongue are found by shape (low, wide shells of their own behind the lips,
:func:`rigid_inner_pieces`) and moved by the same rules.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from assets.heads.mesh import HeadMesh
from realtime_core.face import MouthLandmarks, face_frame

EYE_WORDS = ("eye", "iris", "cornea", "pupil", "sclera", "lash")
TEETH_WORDS = ("teeth", "tooth", "gum", "dent")
TONGUE_WORDS = ("tongue",)
UPPER_WORDS = ("upper", "top", "up", "maxill")
LOWER_WORDS = ("lower", "bottom", "low", "mandib", "jaw")


def _words(name: str) -> list[str]:
    # "Eye_L", "teethUpper", "eyes:default" -> lower-case words
    return [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+", name)]


def _has(words: list[str], keys: tuple[str, ...]) -> bool:
    return any(w.startswith(k) for w in words for k in keys)


def part_kind(name: str) -> str | None:
    """ "eyes", "teeth", "upper teeth", "lower teeth", "tongue" or None (skin, unknown) for a part name."""
    w = _words(name)
    if _has(w, TONGUE_WORDS):
        return "tongue"
    if _has(w, TEETH_WORDS):
        if _has(w, LOWER_WORDS):
            return "lower teeth"
        if _has(w, UPPER_WORDS):
            return "upper teeth"
        return "teeth"
    if _has(w, EYE_WORDS) and not any("brow" in x or "lid" in x for x in w):  # brows and lids: skin
        return "eyes"
    return None


def rigid_labels(mesh: HeadMesh, landmarks: Mapping[str, int]) -> np.ndarray:
    """(n,) per-vertex label: "skull", "jaw" or "" (left to the rig) from the mesh's part names.
    landmarks: name -> vertex index (nose_tip, corner_left/right, eye corners)."""
    n = len(mesh.vertices)
    out = np.full(n, "", dtype=object)
    if mesh.part is None or not mesh.part_names:
        return out
    v = np.asarray(mesh.vertices, dtype=np.float64)
    face = int(mesh.part[landmarks["nose_tip"]])
    mouth = 0.5 * (v[landmarks["corner_left"]] + v[landmarks["corner_right"]])
    eyes = 0.25 * sum(
        v[landmarks[k]] for k in ("eye_outer_left", "eye_inner_left", "eye_outer_right", "eye_inner_right")
    )
    up = (eyes - mouth) / max(float(np.linalg.norm(eyes - mouth)), 1e-300)
    for i, name in enumerate(mesh.part_names):
        kind = part_kind(name)
        sel = np.flatnonzero(mesh.part == i)
        if kind is None or i == face or not len(sel):
            continue
        if kind == "teeth":  # both rows in one part: each connected piece by its side of the mouth line
            out[sel] = _split_rows(v, mesh.triangles, sel, mouth, up, landmarks)
        else:
            out[sel] = "skull" if kind in ("eyes", "upper teeth") else "jaw"
    return out


def _split_rows(
    v: np.ndarray,
    triangles: np.ndarray,
    sel: np.ndarray,
    mouth: np.ndarray,
    up: np.ndarray,
    landmarks: Mapping[str, int],
) -> np.ndarray:
    """(len(sel),) "skull" / "jaw": each connected piece of the teeth part ``sel`` (vertex indices of ``v`` (n, 3)) by
    its mean height above ``mouth`` along ``up``; a piece holding both rows (joined by gums or a palate:
    :func:`_rows_apart`) by its rows."""
    from scipy.sparse.csgraph import connected_components

    local = -np.ones(len(v), dtype=np.int64)
    local[sel] = np.arange(len(sel))
    t = np.asarray(triangles, dtype=np.int64)
    t = local[t[(local[t] >= 0).all(axis=1)]]
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    adj = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(sel), len(sel)))
    _, comp = connected_components(adj, directed=False)
    height = (v[sel] - mouth) @ up
    mean = np.bincount(comp, weights=height) / np.bincount(comp)
    out = np.where(mean[comp] >= 0, "skull", "jaw").astype(object)
    frame = face_frame(v, MouthLandmarks.among(landmarks))
    where = mouth_local(v[sel], landmarks, frame.axes, frame.iod, mouth=mouth)
    for c in np.unique(comp):
        at = np.flatnonzero(comp == c)
        keep = -np.ones(len(sel), dtype=np.int64)
        keep[at] = np.arange(len(at))
        upper = _rows_apart(where[at], keep[t[(comp[t] == c).all(axis=1)]])
        if upper is not None:
            out[at] = np.where(upper, "skull", "jaw")
    return out


ROWS_CORE = 0.1
"""Share of a shell's vertices, its highest and its lowest, that :func:`_rows_apart` holds to be in the upper and the
lower row whatever the cut between them (the top of the upper gum, the bottom of the lower)."""
ROWS_CUT = 1.0
"""How long the cut between a shell's two rows may be (:func:`_rows_apart`: the summed length of the edges it
severs), as a fraction of the narrower row's sideways extent: joined rows part where they are joined, a bridge (the
built-in head's rows joined by two triangles each side: 0.70 of a row's width, 6 edges); a single row or a tongue cut
between its top and bottom is cut right through, along its whole length (the built-in head's upper and lower rows: 1.97
and 1.80 of the narrower side's width, its tongue 6.7). A length, not a count of edges: a cut's edges grow in
number with the mesh's resolution, their summed length does not."""
ROWS_OVERLAP = 0.5
"""Fraction of the narrower row's extent (sideways, and front to back) that the two rows of a shell holding both teeth
rows share (:func:`_rows_apart`): they lie one above the other, so their footprints coincide (the built-in head's rows:
1.0 sideways, 0.91 front to back)."""


def _rows_apart(local: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """(k,) bool, True on the upper row, for a shell holding both teeth rows (joined by gums, a palate or a few faces);
    None for any other shell (one row, a tongue, a lining). ``local`` (k, 3): the shell's vertices about the mouth line
    (sideways, up, out; :func:`mouth_local`), ``triangles`` (m, 3) its faces in those indices, one connected piece.

    The shell is cut where its top (ROWS_CORE of its vertices, the highest) and its bottom (the lowest) are joined by
    the least: a minimum cut between them (maximum flow, each edge's capacity its length). The two sides are the rows
    when that cut is no longer than ROWS_CUT of the narrower side's width (a bridge, not the body of a row), their
    sideways and front-to-back extents share ROWS_OVERLAP or more (one above the other), and the upper side's mean
    height lies above the mouth line, the lower's below. Not by the mouth line itself: the built-in head's rows reach
    past it (its upper row down to -0.11 IOD, the lower's molars up to +0.21); nor by the Laplacian's Fiedler vector:
    rows joined both sides make a ring, which it cut across the rows' middles (32 and 36 of the rows' 68 vertices)."""
    from scipy.sparse.csgraph import breadth_first_order, maximum_flow

    k = len(local)
    if k < 8 or not len(triangles):
        return None
    t = np.asarray(triangles, dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    e = e[e[:, 0] != e[:, 1]]
    h = local[:, 1]
    lo, hi = np.quantile(h, [ROWS_CORE, 1.0 - ROWS_CORE])
    top, bottom = np.flatnonzero(h >= hi), np.flatnonzero(h <= lo)
    if np.intersect1d(top, bottom).size:
        return None
    length = np.linalg.norm(local[e[:, 0]] - local[e[:, 1]], axis=1)
    unit = max(float(np.median(length)), 1e-300) / 100.0  # integer capacities: lengths in 1/100 of the median edge
    edge_cap = np.maximum(1, np.round(length / unit)).astype(np.int64)
    src, sink = k, k + 1
    rows = np.r_[e[:, 0], e[:, 1], np.full(len(top), src), bottom]
    cols = np.r_[e[:, 1], e[:, 0], top, np.full(len(bottom), sink)]
    cap = np.r_[edge_cap, edge_cap, np.full(len(top) + len(bottom), 2 * int(edge_cap.sum()) + 1)].astype(np.int32)
    graph = sp.csr_matrix((cap, (rows, cols)), shape=(k + 2, k + 2))
    res = maximum_flow(graph, src, sink)
    residual = (graph - res.flow).tocsr()
    residual.data = np.where(residual.data > 0, 1, 0).astype(np.int32)
    residual.eliminate_zeros()
    reached = breadth_first_order(residual, src, directed=True, return_predecessors=False)
    upper = np.zeros(k, dtype=bool)
    upper[reached[reached < k]] = True
    if upper.all() or not upper.any():
        return None
    a, b = local[upper], local[~upper]
    if res.flow_value * unit > ROWS_CUT * min(np.ptp(a[:, 0]), np.ptp(b[:, 0])):
        return None
    for axis in (0, 2):
        shared = min(a[:, axis].max(), b[:, axis].max()) - max(a[:, axis].min(), b[:, axis].min())
        if shared < ROWS_OVERLAP * min(np.ptp(a[:, axis]), np.ptp(b[:, axis])):
            return None
    if not (a[:, 1].mean() > 0 > b[:, 1].mean()):
        return None
    return upper


TEETH_FOLLOW = 0.71
"""Fraction of the lower inner lip's drop (at its middle, along the face's up axis) the lower teeth and tongue take
(:func:`with_rigid_parts`). The built-in head driven by its own targets at /a/ (mouth open 0.35): its lower incisors'
edge drops 0.234 IOD, its lower inner lip 0.329 (0.71; 0.73 since the streamed ARKit map nets its antagonists, not
re-tuned: cached rigs' keys do not hold this constant); the edge shows above the lip, not the teeth's front. Moved
with the chin instead, a retarget's lower teeth dropped 0.54 of the lip (the full-body avatar without targets: chin
0.177 IOD, lip 0.329) and a tall band of lower-teeth fronts filled the opening's lower half."""


def with_rigid_parts(rig, mesh: HeadMesh, landmarks: Mapping[str, int], *, pieces: np.ndarray | None = None):
    """The :class:`realtime_core.face.Rig` with the rows of its separate parts replaced by their rigid
    motion (see the module docstring); the rig unchanged when the mesh has no such parts. ``pieces``: (k,) labels
    ("skull", "jaw", "eye", "") of the first k vertices, moved so where the part names say nothing: the unnamed teeth
    and tongue of a one-mesh head or of unnamed separate parts (:func:`rigid_inner_pieces`), recorded as
    ``inner_rigid_pieces`` (their vertex indices) in the meta; "eye": an unnamed separate part in an eye socket, with
    the skull (meta ``eye_rigid_pieces``: how many vertices). Records ``rigid_parts`` (label -> vertex count) in the
    rig's meta."""
    labels = rigid_labels(mesh, landmarks)
    found = np.zeros(0, dtype=np.int64)
    eyes = np.zeros(0, dtype=np.int64)
    if pieces is not None:
        extra = np.full(len(labels), "", dtype=object)
        extra[: len(pieces)] = pieces
        eyes = np.flatnonzero((labels == "") & (extra == "eye"))
        found = np.flatnonzero((labels == "") & (extra != "") & (extra != "eye"))
        labels[found] = extra[found]
        labels[eyes] = "skull"
    if not (labels != "").any():
        return rig
    n = len(rig.neutral)
    row = -np.ones(n, dtype=np.int64)  # each vertex's row among the moving ones
    row[rig.moving] = np.arange(len(rig.moving))
    anchor = landmarks["chin"] if row[landmarks["chin"]] >= 0 else landmarks["lower_lip"]
    lip = landmarks["lower_inner"]
    matrix = rig.matrix
    jaw_row = row[anchor]
    if (labels == "jaw").any() and row[lip] >= 0:
        # The jaw's parts drop TEETH_FOLLOW of the lower inner lip's drop (along the face's up axis) and keep the
        # anchor's motion square to that axis: see TEETH_FOLLOW. One appended vertex row carries that motion.
        up = _face_up(np.asarray(rig.neutral, dtype=np.float64), landmarks)
        vertical = np.outer(up, up)
        chin = matrix[3 * row[anchor] + np.arange(3)]
        lower = matrix[3 * row[lip] + np.arange(3)]
        jaw_rows = sp.csr_matrix(np.eye(3) - vertical) @ chin + sp.csr_matrix(TEETH_FOLLOW * vertical) @ lower
        matrix = sp.vstack([matrix, jaw_rows.astype(matrix.dtype)]).tocsr()
        jaw_row = len(rig.moving)
    src_row = np.where(labels == "skull", -1, np.where(labels == "jaw", jaw_row, row))
    moving = np.flatnonzero(src_row >= 0)
    rows = (3 * src_row[moving][:, None] + np.arange(3)).reshape(-1)
    counts = {k: int((labels == k).sum()) for k in ("skull", "jaw") if (labels == k).any()}
    meta = {**rig.meta, "rigid_parts": counts, "jaw_anchor": int(anchor)}
    if len(found):
        meta["inner_rigid_pieces"] = found.tolist()
    if len(eyes):
        meta["eye_rigid_pieces"] = len(eyes)
    spread = rig.contact_spread
    if spread is not None:
        # The lip-contact push is a correction of the lips' own surface: a part that follows the
        # jaw rigidly takes none of it (it would bend the teeth with the lips).
        own = (labels[moving] == "").astype(np.float32)
        spread = sp.diags(own) @ spread[np.where(labels[moving] == "", src_row[moving], 0)]
    return replace(rig, moving=moving.astype(np.int64), matrix=matrix[rows], meta=meta, contact_spread=spread)


def _face_up(vertices: np.ndarray, landmarks: Mapping[str, int]) -> np.ndarray:
    """(3,) unit: the face frame's up axis (mouth -> eyes) of ``vertices`` (n, 3) at the named landmark vertices."""
    return face_frame(vertices, MouthLandmarks.among(landmarks)).axes[1]


JAW_FULL = 0.5
"""Fraction of the way from the mouth line down to the chin at which an inner-mouth piece follows the jaw
fully (:func:`inner_mouth_weights`); above the mouth line it keeps the field's motion."""
INNER_REACH = (1.0, 1.5)
"""IOD: how far from the mouth's centre an inner-mouth piece may reach sideways and back (the inside of
a mouth; ears, hair and the back of a bust lie further)."""
SEAM_RAMP = 0.2
"""IOD: where a texture seam joins an inner-mouth piece to the face's surface, how far along each side the jaw weight
blends between them (:func:`inner_mouth_weights`: half the height's weight at the seam, all of it this far into the
piece, none this far into the surface; the scan's pieces' edges are about 0.13 IOD long)."""


def inner_mouth_weights(
    vertices: np.ndarray,
    triangles: np.ndarray,
    part: np.ndarray | None,
    landmarks: Mapping[str, int],
    axes: np.ndarray,
    iod: float,
    *,
    still: np.ndarray | None = None,
    part_names: tuple[str, ...] = (),
) -> np.ndarray:
    """(n,) float64 in [0, 1]: how much each vertex of an *inner-mouth piece* (and of the surface within SEAM_RAMP of
    a texture seam joining one to it) follows the jaw, 0 elsewhere and at every position of ``still``.

    An inner-mouth piece is a connected piece of the face's own part (the nose tip's; the whole mesh
    without parts) apart from the face's surface, lying wholly behind the mouth corners (their midpoint,
    along the face's z = axes[2]), above the chin and within INNER_REACH of the mouth: the inside of a
    scanned mouth (gums, the cheeks' insides; Lee Perry-Smith has one each side, 225 vertices). The field
    moves such a piece by the frontal position of its vertices, not with the skin in front of it: at a
    wide /a/ the chin skin went back 0.25-0.3 IOD and the piece behind it 0.05-0.07, through the chin
    (a dark fleck below the lower lip). Each vertex's weight rises with its height below the mouth line
    (along axes[1]), from 0 at the line to 1 at JAW_FULL of the way to the chin: a lower gum follows the
    jaw (the chin's displacement whole; a separate lower-teeth part takes the lower lip's share along the face's up
    axis, :func:`with_rigid_parts`), the piece stays whole.

    Pieces are found on the mesh as it came, where texture seams part coincident copies of a vertex: a scan's
    inside of the mouth is such a piece only across seams (Lee Perry-Smith: it continues the lips' inner walls at 48
    welded positions). Welded, it is no piece at all, and the dark fleck through the chin comes back; weighted on its
    side of the seam alone, its copies took up to 0.58 while the wall's kept 0 and the seam tore open at /a/ (0.12-0.23
    IOD; docs/animation.md, "The seam tear at the right depth"). So the weight is blended on the welded mesh
    (:func:`_seam_blend`): every position has one weight, half the height's at a seam, rising to all of it SEAM_RAMP
    IOD into the piece and falling to none SEAM_RAMP IOD into the surface.
    ``still``: vertex indices that follow no jaw whatever their height, with every copy of their positions: the upper
    lip's contact row, the mouth line itself. A knife-cut mouth's row sags up to 0.005 IOD below the corners' line and
    the surface's blend beside a seam gave it a trace of the jaw, which undid its upper lip's pinned rows: Lee
    Perry-Smith at ~1,500 triangles, 0.0017 of the jaw on the contact vertex by the right corner turned the corner's
    wall by 91 degrees at a wide /a/ (a flipped triangle; 89.1 without it).
    The face's part is its skin as :func:`skin_parts` finds it (``part_names`` name the eyes, teeth and tongue, which
    are never skin): a head exported as a "Head" and a "Jaw" mesh meeting along the lower face is one surface, and
    weighted on the face's part alone, the Head's copies of the seam took up to 0.84 of the jaw while the Jaw's kept 0:
    the seam opened 4.9 mm at mouth_open 0.3 (issue 12, Lee Perry-Smith with its jaw as a separate mesh).
    ``vertices`` (n, 3) and ``triangles`` (m, 3) as the mesh came (before any cut); ``landmarks``: name ->
    vertex index (corner_left, corner_right, chin, nose_tip)."""
    from realtime_core.face.welding import mesh_pieces

    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    out = np.zeros(n)
    canon, welded, t = _skin_faces(v, triangles, part, landmarks, part_names)
    comp = mesh_pieces(n, t)
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    local = mouth_local(v, landmarks, axes, iod)
    chin = float(local[landmarks["chin"], 1])
    if not chin < 0:
        return out
    face = comp[landmarks["nose_tip"]]
    inside = (
        used
        & (comp != face)
        & (local[:, 2] < 0)
        & (local[:, 2] > -INNER_REACH[1])
        & (np.abs(local[:, 0]) < INNER_REACH[0])
        & (local[:, 1] > chin)
    )
    # A piece counts only if every one of its vertices lies there.
    outside = np.bincount(comp[used & ~inside], minlength=comp.max() + 1) > 0
    piece = inside & ~outside[comp]
    height = np.clip(local[:, 1] / (JAW_FULL * chin), 0.0, 1.0)
    if still is not None:
        height[np.isin(canon, canon[np.asarray(still, dtype=np.int64)])] = 0.0
    return np.where(used, height * _seam_blend(canon, welded, t, piece, used, iod), 0.0)


RIGID_PIECE_HEIGHT = 1.0
"""Fraction of the mouth's width (corner to corner) a separate inner-mouth shell may be tall and still move rigidly as a
teeth row or a tongue (:func:`rigid_inner_pieces`; it must also be no taller than it is wide). A teeth row is a low arch
and a tongue a flat lump: the one-mesh anny heads' rows are 0.40-0.74 of their mouths' widths tall and 1.6-2.5 times as
wide as tall, their tongues 0.42-0.77 tall, 1.1-1.9 as wide; a lining of the mouth's inside reaches from one gum to the
other, taller than it is wide (the synthetic scan's inside of test_inner_mouth: 1.1 of the mouth's width, 1.8 times as
tall as wide)."""


def rigid_inner_pieces(
    vertices: np.ndarray,
    triangles: np.ndarray,
    part: np.ndarray | None,
    landmarks: Mapping[str, int],
    axes: np.ndarray,
    iod: float,
    *,
    part_names: tuple[str, ...] = (),
) -> np.ndarray:
    """(n,) per-vertex label: "skull" (an upper teeth row), "jaw" (a lower row, a tongue), "eye" (an unnamed separate
    part in an eye socket) or "" for the unnamed teeth, tongue and eyes of a head: separate shells of the face's skin
    (:func:`skin_parts`; a head exported as one mesh) even where texture seams are welded, or of its unnamed parts
    that are no skin (teeth exported as a separate "Object001", "mesh_3", "Cube.002": :func:`part_kind` names nothing,
    and they touch the face nowhere), lying wholly behind the front-most outer lip midpoint (along the face's z =
    axes[2]), below half the eyes' height, above the chin and within INNER_REACH of the mouth, and no taller (along
    axes[1]) than RIGID_PIECE_HEIGHT of the mouth's width nor than it is wide. Such a shell is a solid thing in the
    mouth, not the skin's inside: moved by the height weights of :func:`inner_mouth_weights` as a scan's lining is,
    anny's upper row dropped 0.11 IOD at /a/ (it should stay) and its lower row 0.12 while the lower lip dropped 0.54,
    and each row bent; a separate part left to the rig moved as one lump with its centroid's row (the built-in head's
    teeth as "Object003"/"Object004": the upper row dropped 0.085 IOD, the lower 0.179 against the named rows' 0.228).
    A lining is a piece only across seams (Lee Perry-Smith's gums and cheek insides continue the lips' inner walls) or
    taller than that: it keeps those weights. A shell holding both rows (joined by gums, a palate: :func:`_rows_apart`)
    is its two rows, upper with the skull and lower with the jaw, when it is low and wide as a whole or each row is and
    the whole is no taller than wide (a lining is taller). A shell deeper (front to back) than it is wide is a tongue:
    with the jaw. Else a row: its mean height above the mouth line (the corners' midpoint) is an upper row, with the
    skull; below, a lower row, with the jaw. An unnamed separate part wholly within an eye's width (corner to corner)
    of its corners' midpoint is an eye, with the skull (the built-in head's eyeballs reach 0.25 IOD from it, 0.49 of
    that width); a one-mesh head's eyeballs are left to the field as before. The built-in head (its mesh named
    "builtin") is left to its field by the rig (:func:`assets.heads.rigging.rig_head`).
    ``vertices`` (n, 3), ``triangles`` (m, 3) as the mesh came; ``landmarks``: name -> vertex index (corners, chin,
    nose_tip, upper_lip, lower_lip, eye corners)."""
    from realtime_core.face.welding import welded_pieces

    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    out = np.full(n, "", dtype=object)
    canon0, _, t = _skin_faces(v, triangles, part, landmarks, part_names)
    if not len(t):
        return out
    loose = np.zeros(n, dtype=bool)  # the vertices of unnamed parts that are no skin
    if part is not None:
        p = np.asarray(part, dtype=np.int64)
        skin = skin_parts(canon0, p, int(p[landmarks["nose_tip"]]), part_names)
        named = [i for i, name in enumerate(part_names) if part_kind(name) is not None]
        tri = np.asarray(triangles, dtype=np.int64)
        tri = tri[~np.isin(p[tri], np.r_[skin, named]).any(axis=1)]
        loose[tri.ravel()] = True
        t = np.vstack([t, tri])
    canon, _, pieces = welded_pieces(v, t)
    comp = pieces[canon]
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    local = mouth_local(v, landmarks, axes, iod)
    chin = float(local[landmarks["chin"], 1])
    width = abs(float(local[landmarks["corner_left"], 0] - local[landmarks["corner_right"], 0]))
    front = max(float(local[landmarks["upper_lip"], 2]), float(local[landmarks["lower_lip"], 2]))
    eyes = float(
        np.mean(
            [local[landmarks[k], 1] for k in ("eye_outer_left", "eye_inner_left", "eye_outer_right", "eye_inner_right")]
        )
    )
    if not chin < 0 or not width > 0:
        return out
    inside = (
        used
        & (comp != comp[landmarks["nose_tip"]])
        & (local[:, 2] < front)
        & (local[:, 2] > -INNER_REACH[1])
        & (np.abs(local[:, 0]) < INNER_REACH[0])
        & (local[:, 1] > chin)
        & (local[:, 1] < 0.5 * eyes)  # an upper gum reaches above the nose tip's height; the eyeballs lie higher
    )

    def low_wide(sel: np.ndarray) -> bool:  # (n,) bool: a teeth row's or a tongue's shape
        lo, hi = local[sel].min(axis=0), local[sel].max(axis=0)
        return bool(hi[1] - lo[1] <= min(RIGID_PIECE_HEIGHT * width, hi[0] - lo[0]))

    for c in np.unique(comp[inside]):
        sel = used & (comp == c)
        if not inside[sel].all():
            continue
        upper = _shell_rows(local, canon, t, sel)
        if upper is not None:
            extent = np.ptp(local[sel], axis=0)
            if low_wide(sel) or (low_wide(upper) and low_wide(sel & ~upper) and extent[1] <= extent[0]):
                out[upper], out[sel & ~upper] = "skull", "jaw"
                continue
        if not low_wide(sel):
            continue
        lo, hi = local[sel].min(axis=0), local[sel].max(axis=0)
        tongue = hi[2] - lo[2] > hi[0] - lo[0]
        out[sel] = "jaw" if tongue or float(local[sel, 1].mean()) < 0 else "skull"
    for side in ("left", "right") if loose.any() else ():
        a, b = v[landmarks[f"eye_outer_{side}"]], v[landmarks[f"eye_inner_{side}"]]
        near = np.linalg.norm(v - 0.5 * (a + b), axis=1) <= np.linalg.norm(a - b)
        for c in np.unique(comp[loose & near]):
            sel = used & (comp == c)
            if (loose[sel] & near[sel]).all():
                out[sel] = "eye"
    return out


def unnamed_inner_parts(mesh: HeadMesh, landmarks: Mapping[str, int], pieces: np.ndarray) -> np.ndarray:
    """(n,) bool: the vertices of the unnamed parts that are no skin (:func:`skin_parts`) and hold a teeth row or a
    tongue found by shape (``pieces`` (n,): :func:`rigid_inner_pieces`' labels, "skull" or "jaw"): parts inside the
    mouth as named teeth are (:func:`assets.heads.cavity.has_inner_mouth`), so a head whose teeth are "Object003" gets
    the rules of one with teeth: its inside shaded as a modelled mouth's (teeth and tongue keep their hue; unnamed, the
    built-in head's teeth as a separate "Object003" part came out a lighter, unshaded inside at /a/ and /u/), no mouth
    cavity, no lip walls dropped. All False without parts, so a one-mesh head's rules stay as they were."""
    n = len(mesh.vertices)
    if mesh.part is None:
        return np.zeros(n, dtype=bool)
    from realtime_core.face.welding import weld

    p = np.asarray(mesh.part, dtype=np.int64)
    skin = skin_parts(
        weld(np.asarray(mesh.vertices, dtype=np.float64))[0], p, int(p[landmarks["nose_tip"]]), mesh.part_names
    )
    labels = np.asarray(pieces, dtype=object)[:n]
    found = np.unique(p[: len(labels)][(labels == "skull") | (labels == "jaw")])
    return np.isin(p, np.setdiff1d(found, skin))


def _shell_rows(local: np.ndarray, canon: np.ndarray, triangles: np.ndarray, sel: np.ndarray) -> np.ndarray | None:
    """(n,) bool, True on the upper row of the shell ``sel`` (n,) bool when it holds both teeth rows
    (:func:`_rows_apart` on its welded vertices: ``canon`` (n,) each vertex's welded index, ``triangles`` (m, 3) the
    faces it is a piece of, ``local`` (n, 3) the vertices about the mouth line); None when it does not."""
    at = np.unique(canon[sel])
    keep = -np.ones(int(canon.max()) + 1, dtype=np.int64)
    keep[at] = np.arange(len(at))
    first = np.zeros(len(at), dtype=np.int64)  # a vertex at each welded position
    first[keep[canon[sel]]] = np.flatnonzero(sel)
    wt = keep[canon[np.asarray(triangles, dtype=np.int64)]]
    upper = _rows_apart(local[first], wt[(wt >= 0).all(axis=1)])
    return None if upper is None else sel & upper[keep[canon]]


def _skin_faces(
    v: np.ndarray,
    triangles: np.ndarray,
    part: np.ndarray | None,
    landmarks: Mapping[str, int],
    part_names: tuple[str, ...],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(each vertex's welded index (n,), the welded positions, the triangles of the face's skin (:func:`skin_parts`;
    every triangle when the mesh has no parts)) of ``v`` (n, 3) as the mesh came."""
    from realtime_core.face.welding import weld

    t = np.asarray(triangles, dtype=np.int64)
    canon, welded = weld(v)
    if part is not None:
        skin = skin_parts(canon, np.asarray(part), int(part[landmarks["nose_tip"]]), part_names)
        t = t[np.isin(np.asarray(part)[t], skin).all(axis=1)]
    return canon, welded, t


def mouth_local(
    v: np.ndarray, landmarks: Mapping[str, int], axes: np.ndarray, iod: float, *, mouth: np.ndarray | None = None
) -> np.ndarray:
    """(n, 3) IOD: ``v`` about the mouth corners' midpoint (``mouth`` (3,), else taken from ``v`` at the corner
    landmarks) along the face's axes (sideways, up, out)."""
    if mouth is None:
        mouth = 0.5 * (v[landmarks["corner_left"]] + v[landmarks["corner_right"]])
    return (v - mouth) @ np.asarray(axes, dtype=np.float64).T / iod


def skin_parts(canon: np.ndarray, part: np.ndarray, face: int, part_names: tuple[str, ...] = ()) -> np.ndarray:
    """Sorted part indices that are one surface with the face's part ``face``: it and every part that shares a
    position with a skin part (``canon`` (n,): each vertex's welded position, :func:`realtime_core.face.welding.weld`;
    ``part`` (n,) each vertex's part), unless ``part_names`` says eyes, teeth or tongue (:func:`part_kind`: they move by
    their own rules). Meshes that meet at a seam (a separate jaw or chin, a head split by material) are skin; a part
    that touches the face nowhere is not, so a head without such seams keeps the face's part alone."""
    p = np.asarray(part, dtype=np.int64)
    c = np.asarray(canon, dtype=np.int64)
    n_parts = int(p.max()) + 1
    own_rules = np.array([i < len(part_names) and part_kind(part_names[i]) is not None for i in range(n_parts)])
    at = sp.csr_matrix((np.ones(len(p)), (c, p)), shape=(int(c.max()) + 1, n_parts))
    meet = (at.T @ at).toarray() > 0  # (parts, parts): they share a position
    skin = np.zeros(n_parts, dtype=bool)
    skin[face] = True
    while True:
        more = meet[skin].any(axis=0) & ~own_rules & ~skin
        if not more.any():
            return np.flatnonzero(skin)
        skin |= more


def part_seam_pairs(
    vertices: np.ndarray,
    part: np.ndarray,
    face: int,
    part_names: tuple[str, ...] = (),
    *,
    skip: np.ndarray | None = None,
) -> np.ndarray:
    """(k, 2) vertex indices: copies of one position (``vertices`` (n, 3), welded as the rig welds) in two different
    skin parts (:func:`skin_parts` of the face's part ``face``; ``part`` (n,)), each paired with the position's first
    skin copy: the seams between a head's meshes, which must not open (the rig checks' seam gap). Positions holding
    any of ``skip`` (a cut lip seam's copies, whose sides part on purpose; a mouth cavity) are left out."""
    from realtime_core.face.welding import weld

    canon, welded = weld(np.asarray(vertices, dtype=np.float64))
    p = np.asarray(part, dtype=np.int64)
    skin = np.isin(p, skin_parts(canon, p, face, part_names))
    if skip is not None and len(skip):
        away = np.zeros(len(welded), dtype=bool)
        away[canon[np.asarray(skip, dtype=np.int64)]] = True
        skin &= ~away[canon]
    idx = np.flatnonzero(skin)
    first = np.full(len(welded), -1, dtype=np.int64)
    first[canon[idx[::-1]]] = idx[::-1]
    other = idx[p[idx] != p[first[canon[idx]]]]
    return np.column_stack([first[canon[other]], other])


def _seam_blend(
    canon: np.ndarray, welded: np.ndarray, t: np.ndarray, piece: np.ndarray, used: np.ndarray, iod: float
) -> np.ndarray:
    """(n,) in [0, 1], one value per welded position (``canon`` (n,): each vertex's row of ``welded`` (p, 3)): 1 on the
    inner-mouth pieces (``piece`` (n,) bool), 0 on the rest of the mesh (``used`` (n,) bool: the vertices of ``t``),
    blended across the seams where they share a position: 0.5 there, rising to 1 at SEAM_RAMP IOD along the pieces
    and falling to 0 at SEAM_RAMP IOD along the rest (edge-path distances on the welded mesh; a seam between two
    pieces is no seam)."""
    from scipy.sparse.csgraph import dijkstra

    from realtime_core.face.projection import edge_length_graph

    surface = np.zeros(len(welded), dtype=bool)
    surface[canon[used & ~piece]] = True
    inner = np.zeros(len(welded), dtype=bool)
    inner[canon[piece]] = True
    seams = np.flatnonzero(inner & surface)
    if not len(seams):
        return piece.astype(np.float64)
    reach = SEAM_RAMP * iod
    in_piece = piece[t].all(axis=1)
    into_piece = dijkstra(edge_length_graph(welded, canon[t[in_piece]]), indices=seams, min_only=True, limit=reach)
    into_surface = dijkstra(edge_length_graph(welded, canon[t[~in_piece]]), indices=seams, min_only=True, limit=reach)
    blend = np.where(
        inner & ~surface,
        0.5 + 0.5 * np.clip(into_piece / reach, 0.0, 1.0),
        0.5 - 0.5 * np.clip(into_surface / reach, 0.0, 1.0),
    )
    return blend[canon]


def with_jaw_weights(rig, weights: np.ndarray, anchor: int):
    """The :class:`realtime_core.face.Rig` whose vertex i moves by (1 - w_i) of its own displacement plus
    w_i of vertex ``anchor``'s (the chin's, the anchor of :func:`with_rigid_parts`); ``weights`` (n,) in
    [0, 1]. A still vertex with a weight joins the moving set. Each vertex keeps its whole lip-contact push: the
    push closes the crossing measured on the final rows, so a lip vertex weighted w (the lips' inner walls by the seams
    of :func:`inner_mouth_weights`) that kept only (1 - w) of it left its lips crossed (Lee Perry-Smith, hand
    landmarks: by 2.6e-5 IOD pressed beyond speech); the inner-mouth pieces lie beyond the push's reach. Records
    ``inner_mouth_pieces`` (vertices weighted) in the meta."""
    n = len(rig.neutral)
    w = np.asarray(weights, dtype=np.float64)
    row = -np.ones(n, dtype=np.int64)
    row[rig.moving] = np.arange(len(rig.moving))
    if row[anchor] < 0 or not (w > 0).any():
        return rig
    moving = np.union1d(rig.moving, np.flatnonzero(w > 0)).astype(np.int64)
    k = len(moving)
    own = row[moving]  # -1 for a vertex that did not move
    wm = w[moving]
    # New rows: (1 - w) x own rows + w x the anchor's rows, per coordinate.
    r = (3 * np.arange(k)[:, None] + np.arange(3)).ravel()
    has = np.repeat(own >= 0, 3)
    pick_own = sp.csr_matrix(
        (np.repeat(1.0 - wm, 3)[has], (r[has], (3 * own[:, None] + np.arange(3)).ravel()[has])),
        shape=(3 * k, rig.matrix.shape[0]),
    )
    pick_anchor = sp.csr_matrix(
        (np.repeat(wm, 3), (r, np.tile(3 * row[anchor] + np.arange(3), k))), shape=(3 * k, rig.matrix.shape[0])
    )
    matrix = ((pick_own + pick_anchor) @ rig.matrix).tocsr()
    matrix.eliminate_zeros()
    spread = rig.contact_spread
    if spread is not None:
        keep = sp.csr_matrix(
            (np.ones(int((own >= 0).sum())), (np.flatnonzero(own >= 0), own[own >= 0])), shape=(k, spread.shape[0])
        )
        spread = (keep @ spread).tocsr()
    meta = {**rig.meta, "inner_mouth_pieces": int((w > 0).sum())}
    return replace(rig, moving=moving, matrix=matrix, meta=meta, contact_spread=spread)
