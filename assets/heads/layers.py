"""Layers on the skin (a beard or moustache shell, stubble, eyebrows, a second skin) moved with the skin beneath them.

Real heads often carry such a layer as a separate mesh. Left to the rig, it had no control point of its own: the
field moved it by where it lay, not with the skin under it. Lee Perry-Smith with a beard shell 0.02 IOD over its lower
face (``--head-part beard.obj``) failed its checks: the shell stayed while the lips opened, the skin came 0.23 IOD
through it at /a/, its faces hung across the opening, its rim tore (docs/animation.md, "A layer on the skin").

A separate part is a layer when it is no skin (:func:`assets.heads.parts.skin_parts`: it shares no position with the
face), its name says no eyes, teeth or tongue (:func:`assets.heads.parts.part_kind`; eyelashes are eyes, brows and
lids are not), no rule of :func:`assets.heads.parts.rigid_inner_pieces` took it (teeth, a tongue or an eye found by
shape) and LAYER_SHARE of its vertices lie within LAYER_REACH of the skin's surface. Chosen by that rule, never by
its name. Each of its vertices then moves as its nearest point on the rigged skin (barycentric rows of that face's
corners, :func:`assets.heads.dense.carried_rows`, as a dense scan's vertices take its proxy's), the lip-contact push
included, from its own lip's side of the cut (:func:`layer_sides`: near the mouth line above it the upper lip's,
below the lower's; the cut's copies are the lower side's, :func:`assets.heads.dense.lip_sides`), so a layer over
closed lips parts with them.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from assets.heads.dense import LOWER, NO_SIDE, SIDE_REACH, UPPER, carried_rows, lip_sides
from assets.heads.mesh import HeadMesh
from assets.heads.parts import mouth_local, part_kind, skin_parts
from realtime_core.face import Rig
from realtime_core.face.rig import modelled_rest
from realtime_core.face.welding import weld

LAYER_REACH = 0.05
"""IOD: how near the skin's surface (its nearest point) a layer's vertices lie. A beard or moustache shell, stubble or
brows lie 0.005-0.03 IOD over it; teeth lie 0.1-0.2 behind the lips, eyeballs under their lids reach further than
this, a body or hair far from the face."""
LAYER_SHARE = 0.8
"""Fraction of a separate part's vertices that must lie within LAYER_REACH of the skin for it to be a layer (its rim
may stand off; a body meeting the head at the neck, most of it far away, is none)."""


def layer_vertices(
    vertices: np.ndarray,
    triangles: np.ndarray,
    part: np.ndarray | None,
    part_names: tuple[str, ...],
    face: int,
    iod: float,
    *,
    taken: np.ndarray | None = None,
) -> np.ndarray:
    """(n,) bool: the vertices of the separate parts lying on the skin (see the module docstring). ``vertices``
    (n, 3) and ``triangles`` (m, 3) the head as modelled (the rig's faces), ``part`` (n,) each vertex's part (None: no
    parts, no layer), ``face`` the face's part, ``iod`` head units per IOD; ``taken`` (n,) bool: vertices some other
    rule moves (teeth, tongue, eyes found by shape), whose parts are no layer."""
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    out = np.zeros(n, dtype=bool)
    if part is None:
        return out
    p = np.asarray(part, dtype=np.int64)
    t = np.asarray(triangles, dtype=np.int64)
    skin = np.isin(p, skin_parts(weld(v)[0], p, face, part_names))
    skin_t = t[skin[t].all(axis=1)]
    busy = np.zeros(int(p.max()) + 1, dtype=bool)
    if taken is not None and np.asarray(taken).any():
        busy[np.unique(p[np.asarray(taken, dtype=bool)])] = True
    candidates = [
        i
        for i in np.unique(p[~skin])
        if not busy[i] and (i >= len(part_names) or part_kind(part_names[i]) is None) and np.isin(p[t], i).any()
    ]
    if not candidates or not len(skin_t):
        return out
    sel = np.flatnonzero(np.isin(p, candidates))
    b = carried_rows(v, skin_t, np.zeros(n, dtype=np.int8), v[sel], np.zeros(len(sel), dtype=np.int8))
    near = np.linalg.norm(b @ v - v[sel], axis=1) <= LAYER_REACH * iod
    for i in candidates:
        mine = p[sel] == i
        if near[mine].mean() >= LAYER_SHARE:
            out[sel[mine]] = True
    return out


LINE_BAND = 0.05
"""IOD: a layer vertex this near the mouth line takes the side of the line it lies on (:func:`layer_sides`); farther,
the side of the skin beneath it."""


def layer_sides(
    vertices: np.ndarray,
    layer: np.ndarray,
    foot: np.ndarray,
    originals: np.ndarray,
    landmarks: Mapping[str, int],
    axes: np.ndarray,
    iod: float,
) -> np.ndarray:
    """(k,) int8: UPPER, LOWER or NO_SIDE for each vertex ``layer`` (k,) of ``vertices`` (n, 3), whose nearest skin
    point lies on ``foot`` (k,): the lip side (:func:`assets.heads.dense.lip_sides`) of that point's heaviest corner.
    Within LINE_BAND of the mouth line, a vertex over a lip's side takes the upper lip's side above the line and the
    lower's below: closed lips touch, and a vertex just below the contact may lie nearest the upper lip's overhanging
    underside. Farther, it keeps its foot's side: beside a corner the lower lip's side of the cut reaches above the
    line (the once-subdivided Lee Perry-Smith: 0.07-0.16 IOD above it by the left corner), and sent to the upper lip's
    faces there, the beard's faces flipped. The mouth line: the cut's upper side ``originals`` between the corners
    (their heights along the face's up axis, ``axes`` (3, 3), about the corners' midpoint), level with the corners
    beyond them."""
    local = mouth_local(np.asarray(vertices, dtype=np.float64), landmarks, axes, iod)
    line_x = np.r_[local[np.asarray(originals, dtype=np.int64), 0], local[[landmarks["corner_left"]], 0]]
    line_x = np.r_[line_x, local[[landmarks["corner_right"]], 0]]
    line_y = np.r_[local[np.asarray(originals, dtype=np.int64), 1], 0.0, 0.0]
    order = np.argsort(line_x)
    height = local[layer, 1] - np.interp(local[layer, 0], line_x[order], line_y[order])
    by_line = np.where(height >= 0.0, UPPER, LOWER)
    foot = np.asarray(foot, dtype=np.int8)
    side = np.where((np.abs(height) < LINE_BAND) | (foot == NO_SIDE), by_line, foot)
    return np.where(foot != NO_SIDE, side, NO_SIDE).astype(np.int8)


def with_layers(
    rig: Rig,
    layer: np.ndarray,
    part: np.ndarray,
    part_names: tuple[str, ...],
    landmarks: Mapping[str, int],
    axes: np.ndarray,
    iod: float,
    *,
    seam: np.ndarray | None = None,
) -> Rig:
    """``rig`` whose ``layer`` vertices (k,) move as their nearest points on the skin: each its three matrix rows and
    its share of the lip-contact push the barycentric sum of that skin face's corners'
    (:func:`assets.heads.dense.carried_rows` on the head as modelled), on its own lip's side of a cut lip seam
    (``seam`` (s, 2): upper side, lower copy; :func:`layer_sides`). The skin: the rig's faces whose corners are all of
    skin parts (:func:`assets.heads.parts.skin_parts`; ``part`` (n,) each rig vertex's part, ``part_names`` their
    names, the face's part the nose tip's of ``landmarks``). ``axes`` (3, 3) the face's frame, ``iod`` head units per
    IOD. A rig resting in a pose (``with_rest_pose``) rests its layer at that pose too. Records ``layer_vertices``
    (their indices; the checks count the layer as skin, :func:`realtime_core.face.checks.inside_split`) in the
    meta."""
    layer = np.asarray(layer, dtype=np.int64)
    if not len(layer):
        return rig
    rest = modelled_rest(rig).astype(np.float64)
    n = len(rest)
    p = np.asarray(part, dtype=np.int64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    skin = np.isin(p, skin_parts(weld(rest)[0], p, int(p[landmarks["nose_tip"]]), part_names))
    st = t[skin[t].all(axis=1)]
    sides = np.zeros(n, dtype=np.int8)
    layer_side = np.zeros(len(layer), dtype=np.int8)
    if seam is not None and len(seam):
        s = np.asarray(seam, dtype=np.int64)
        sides = lip_sides(rest, st, s[:, 1], s[:, 0], SIDE_REACH * iod)
        first = carried_rows(rest, st, sides, rest[layer], layer_side)
        heaviest = np.array(
            [first.indices[i + int(np.argmax(first.data[i:j]))] for i, j in itertools.pairwise(first.indptr)]
        )
        layer_side = layer_sides(rest, layer, sides[heaviest], s[:, 0], landmarks, axes, iod)
    # Each side's vertices from the faces touching no vertex of the other side. carried_rows' own rule (a face with a
    # corner on the vertex's side) sent a layer vertex over skin whose faces have no sided corner (beyond SIDE_REACH)
    # to a face 0.19 IOD away: the once-subdivided Lee Perry-Smith's beard, its faces flipped at /a/.
    b = sp.csr_matrix((len(layer), n))
    for side in (NO_SIDE, UPPER, LOWER):
        who = np.flatnonzero(layer_side == side)
        if not len(who):
            continue
        own = np.zeros(n, dtype=np.int8) if side == NO_SIDE else np.where(sides == NO_SIDE, side, sides).astype(np.int8)
        rows = carried_rows(rest, st, own, rest[layer[who]], np.full(len(who), side, dtype=np.int8))
        put = sp.csr_matrix((np.ones(len(who)), (who, np.arange(len(who)))), shape=(len(layer), len(who)))
        b = b + put @ rows  # (k, n)
    b = b.tocsr()
    row = -np.ones(n, dtype=np.int64)
    row[rig.moving] = np.arange(len(rig.moving))
    pick = sp.csr_matrix(
        (np.ones(len(rig.moving)), (rig.moving, np.arange(len(rig.moving)))), shape=(n, len(rig.moving))
    )
    carry = (b @ pick).tocsr()  # (k, n_moving): still corners add nothing
    carry.eliminate_zeros()
    is_layer = np.zeros(n, dtype=bool)
    is_layer[layer] = True
    keep = rig.moving[~is_layer[rig.moving]]
    moves = layer[np.diff(carry.indptr) > 0]
    moving = np.union1d(keep, moves).astype(np.int64)
    at = -np.ones(n, dtype=np.int64)
    at[layer] = np.arange(len(layer))
    own = sp.csr_matrix(
        (np.ones(len(keep)), (np.searchsorted(moving, keep), row[keep])), shape=(len(moving), len(rig.moving))
    )
    coo = carry[at[moves]].tocoo()
    carried = sp.csr_matrix(
        (coo.data, (np.searchsorted(moving, moves)[coo.row], coo.col)), shape=(len(moving), len(rig.moving))
    )
    transfer = (own + carried).tocsr()  # (new moving, old moving)
    matrix = (sp.kron(transfer, sp.identity(3, format="csr"), format="csr") @ rig.matrix.astype(np.float64)).tocsr()
    spread = None if rig.contact_spread is None else (transfer @ rig.contact_spread.astype(np.float64)).tocsr()
    neutral = rig.neutral
    if rig.meta.get("rest_pose") is not None:
        # The skin rests posed (with_rest_pose): its layer rests at its skin's rest displacement.
        offset = np.asarray(rig.neutral, dtype=np.float64)[rig.moving] - rest[rig.moving]
        neutral = np.array(rig.neutral, dtype=np.float32, copy=True)
        neutral[layer] = (rest[layer] + carry @ offset).astype(np.float32)
    meta = {**rig.meta, "layer_vertices": [int(i) for i in layer]}
    return replace(rig, neutral=neutral, moving=moving, matrix=matrix, contact_spread=spread, meta=meta)


def without_layers(mesh: HeadMesh, nose_tip: int, iod: float) -> HeadMesh:
    """``mesh`` without its layers (:func:`layer_vertices`; ``nose_tip``: a vertex of the face's part, ``iod`` head
    units per IOD): the mesh a dense scan's decimated copy is made from (:func:`assets.heads.dense.proxy_mesh`). Each
    proxy vertex takes the part of the nearest dense vertex, and a shell 0.02 IOD over the skin, decimated, had most of
    its vertices nearest the skin's (the once-subdivided Lee Perry-Smith with a beard: 32 of a 79-vertex piece's): the
    copy's rig then put control points on it and failed (3 flips, stretch 5.90). The dense rig moves the layer with its
    own skin (:func:`with_layers`). ``mesh`` itself when it has none."""
    if mesh.part is None:
        return mesh
    p = np.asarray(mesh.part, dtype=np.int64)
    layer = layer_vertices(mesh.vertices, mesh.triangles, p, mesh.part_names, int(p[nose_tip]), iod)
    if not layer.any():
        return mesh
    keep = ~layer
    remap = np.cumsum(keep) - 1
    t = np.asarray(mesh.triangles, dtype=np.int64)
    t = remap[t[keep[t].all(axis=1)]]
    return replace(
        mesh,
        vertices=mesh.vertices[keep],
        triangles=t.astype(np.asarray(mesh.triangles).dtype),
        uvs=None if mesh.uvs is None else mesh.uvs[keep],
        colors=None if mesh.colors is None else mesh.colors[keep],
        targets=None if mesh.targets is None else {k: d[keep] for k, d in mesh.targets.items()},
        part=mesh.part[keep],
    )
