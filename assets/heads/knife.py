"""A knife cut along a coarse head's lip contact line: vertices inserted where the line crosses the mesh.

A decimated (low-poly) head's closed lips meet along a few long edges (Lee Perry-Smith at 1,428
triangles: the lower lip's top is one edge from mouth corner to mouth corner, under a thin strip of
slivers that hangs from the upper lip). No edge path between the corners then follows the lips'
contact: the path through the mesh vertex nearest the inner-lip point ran as a V down the lower lip
(that vertex lay 0.1 IOD below the contact), and a path along the corner-to-corner line had too few
vertices to split for the lips to part. Modelling tools' knife does what is needed: it cuts the
triangles a line crosses, inserting a vertex on every edge it passes. Here the line is the lips'
contact curve seen from the front: the parabola through the two mouth corners and the inner-lip point
(in the face frame's side/up plane), swept along the depth axis over the mouth's front. The new
vertices form an edge path from corner to corner on the curve, with a vertex at every edge the curve
crosses, so the cut (:func:`assets.heads.rigging.cut_mouth`) separates the lips wherever they touch
and the inner-lip point lies on the path (a vertex of it is within one crossed edge of the point).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

COARSE_EDGES = 8.0
"""A closed mouth is coarse when its corner-to-corner width spans fewer than this many median edges of
the mesh round the mouth (Lee Perry-Smith: 1,428 triangles 2.6, 3,810 triangles 4.1, the full scan 17.7;
the stylised held-out head 5.0): it is then knife-cut (:func:`knife_contact`). Finer meshes have a
vertex close to any point of the contact and keep the edge path of :func:`assets.heads.rigging.cut_path`."""
MOUTH_REACH = 0.5
"""IOD: the edges within this distance of the mouth centre measure the mesh's resolution there."""
KNIFE_SNAP = 0.02
"""IOD: a crossing this close to an edge's end moves onto that end (the vertex joins the path), so the
cut leaves no sliver shorter than this along an edge."""
KNIFE_DEPTH = 0.1
"""IOD: the knife cuts faces whose vertices all lie no further behind the mouth corners than this (the
lips' front and their contact; a hollow head's inner walls and the back of the head stay whole)."""
KNIFE_SIDE = 0.02
"""IOD: how far beyond a mouth corner, sideways, a cut face's vertices may reach."""
KNIFE_BRIDGE = 10.0
"""Where the knife's pieces do not join the corners, the path bridges the gap along edges of the cut faces off the
curve, taken only towards the right corner, each costing this many times its length against the pieces' own
(:func:`knife_contact`): the path keeps to the pieces where it can and bridges with the fewest, shortest edges."""
KNIFE_BRIDGE_SHARE = 0.34
"""At most this fraction of the knife's cut edges (corner to corner, long edges split) may bridge gaps off the curve
(KNIFE_BRIDGE); a path mostly off the curve is not the lips' contact and the knife gives up (None), as before
bridging. The 3,810-triangle Lee Perry-Smith copy mirrored bridges 3 of its 13 cut edges; the MediaPipe face with lips
that touch but are apart in the mesh (tests/assets/heads/test_parted_lips.py) bridged 10 of 18, a cut that passed the
checks where those lips are to be rigged apart, not cut."""
KNIFE_HEIGHT = 0.35
"""IOD: a cut face reaches within this distance above or below the contact curve (the lips' height; the
nose and chin stay as they are)."""
LIP_BACK_HEIGHT = 0.04
"""IOD: an edge whose ends lie on the knife's path or no higher than this above the contact curve, and which
passes behind path vertices, is the upper lip's back running along the cut (:func:`split_lip_back`)."""
LIP_BACK_DEPTH = 0.35
"""IOD: ...and which passes at most this far behind them (a lip's back lies within the lip's height, KNIFE_HEIGHT, of
its front; Lee Perry-Smith at 1,428 triangles: 0.04-0.06). The 3,810-triangle copy jittered (seeds 3, 4) had an edge
of the mouth cavity's back, 1.5 IOD behind the lips and 0.46 IOD long, split as a lip's back: moved with the cut's
upper edge, its faces flipped (docs/animation.md, "The knife's gap")."""
LIP_BACK_SPAN = 0.5
"""Such an edge is split when it is at least this fraction of the mouth's corner-to-corner width long: an upper lip
of a handful of faces (Lee Perry-Smith at 1,428 triangles: 0.72 and 0.74), which the rig also pins to the simple
face's upper lip and smooths on its own (:func:`assets.heads.rigging.rig_head`). Its 3,810 copy's longest is 0.45,
the stylised held-out head's 0.32: split (with that rig), their lip backs seen rose, 1.64 -> 1.73 and 4.55 -> 27.97
(1e-3 IOD^2; docs/animation.md, "The 1,428 copy's flap")."""
CORNER_SPAN = 0.35
"""A knife path whose first (or last) edge, from a mouth corner to the next path vertex, is longer than this fraction
of the mouth's half-width (the lip line leaving the corner through one large face: the stylised held-out head's
0.48; the other ends of the test sets' knife paths 0.08-0.24) gets the corner's edge to the lower lip split
(:func:`split_lower_corner`)..."""
CORNER_SPAN_MAX = 0.75
"""...unless it is longer than this fraction: that side's lip is then one face from the corner to near the middle (Lee
Perry-Smith at 1,428 triangles: 0.86), whose rig handles it as a whole (:data:`LIP_BACK_SPAN`); split there, its lip
backs seen rose 4.99 -> 18.08 (1e-3 IOD^2) and the opening's corner stood as one straight triangle (docs/animation.md,
"The stylised head's lower-lip corner")."""

MEETING_STEP = 0.002
"""IOD: the rays that find where closed lips meet (:func:`lips_meeting`) lie this far apart, upwards."""
MEETING_REACH = 0.02
"""IOD: how far above the inner-lip point the lips' meeting is looked for (the 3,810-triangle Lee Perry-Smith copy:
0.014, mirrored 0.010); found no lower than this, the point stays where it is. The 1,428-triangle copy's point lies
on its lower lip's front, 0.024 IOD under the upper lip's underside: raised there, every try from three landmark sets
failed (the lips parting 0.23-0.40 of the opening asked) and the fourth's rig tore across the chin at /a/."""
TOP_FACING = 60.0
"""Degrees: a face whose normal lies within this angle of straight up is a lip's top (:func:`lips_meeting`; the
3,810-triangle Lee Perry-Smith copy's lower lip below its found inner-lip point: 46 degrees, then 31)."""


@dataclass(frozen=True, kw_only=True)
class KnifeCut:
    """A mesh with vertices inserted on edges. ``vertices`` (n + k, 3): the original n first;
    ``triangles`` (m', 3); ``edge`` (k, 2) the two vertices each new vertex lies between (earlier
    vertices: an original one or a new one before it) and ``at`` (k,) where (0 = edge[:, 0],
    1 = edge[:, 1]); ``path`` the corner-to-corner vertex path along the contact (indices into
    ``vertices``)."""

    vertices: np.ndarray
    triangles: np.ndarray
    edge: np.ndarray
    at: np.ndarray
    path: list[int]
    behind: dict[int, int] = field(default_factory=dict)
    """New vertices on the upper lip's back (:func:`split_lip_back`) -> the path vertex in front of each."""
    corners_split: int = 0
    """How many mouth corners' edges to the lower lip were split (:func:`split_lower_corner`)."""
    bridged: int = 0
    """How many of the path's edges leave the curve, bridging a gap between the cut's pieces (KNIFE_BRIDGE)."""
    inner: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """(3,) the inner-lip point the curve passes through: the given one, raised to the lips' meeting
    (:func:`lips_meeting`) when it lay on the lower lip's top."""
    raised: float = 0.0
    """IOD: how far :func:`lips_meeting` raised the inner-lip point."""

    def along_path(self) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """The new vertices on an edge the path runs along (:func:`split_long_edges`'s: both ends on the path),
        each -> (the edge's two ends (2,), their weights (2,) at the vertex's place)."""
        n = len(self.vertices) - len(self.edge)
        on = set(self.path)
        return {
            n + k: (np.asarray((i, j), dtype=np.int64), np.array([1.0 - w, w]))
            for k, ((i, j), w) in enumerate(zip(self.edge.tolist(), self.at.tolist(), strict=True))
            if i in on and j in on and n + k in on
        }

    def carry(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex ``values`` (n, ...) extended to the new vertices by linear interpolation along
        their edges (UVs, colours)."""
        a = np.asarray(values)
        out = np.concatenate([a, np.zeros((len(self.edge), *a.shape[1:]), dtype=a.dtype)])
        n = len(a)
        for k, ((i, j), w) in enumerate(zip(self.edge.tolist(), self.at.tolist(), strict=True)):
            out[n + k] = (1.0 - w) * out[i] + w * out[j]
        return out

    def carry_nearest(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex labels (n,) extended to the new vertices from their edge's nearer end (part ids)."""
        a = np.asarray(values)
        out = np.concatenate([a, np.zeros(len(self.edge), dtype=a.dtype)])
        n = len(a)
        for k, ((i, j), w) in enumerate(zip(self.edge.tolist(), self.at.tolist(), strict=True)):
            out[n + k] = out[i] if w < 0.5 else out[j]
        return out


def mouth_resolution(vertices: np.ndarray, triangles: np.ndarray, left: int, right: int, *, iod: float) -> float:
    """How many median edges (of those within MOUTH_REACH IOD of the corners' midpoint) the
    corner-to-corner distance spans: the mesh's resolution across the mouth."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    mid = 0.5 * (v[left] + v[right])
    near = np.linalg.norm(0.5 * (v[e[:, 0]] + v[e[:, 1]]) - mid, axis=1) <= MOUTH_REACH * iod
    if not near.any():
        return 0.0
    el = float(np.median(np.linalg.norm(v[e[near, 0]] - v[e[near, 1]], axis=1)))
    return float(np.linalg.norm(v[left] - v[right])) / max(el, 1e-12 * iod)


def contact_offset(q: np.ndarray, left: np.ndarray, right: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """(n,) how far above the contact curve each point of ``q`` (n, 3) lies, in the face frame's
    (side, up, forward) coordinates: the up coordinate minus the parabola's (through the corners
    ``left``, ``right`` and the inner-lip point ``inner``, each (3,) in the same coordinates) at the
    point's side coordinate."""
    xs = np.array([left[0], inner[0], right[0]])
    ys = np.array([left[1], inner[1], right[1]])
    coef = np.polyfit(xs, ys, 2)
    return q[:, 1] - np.polyval(coef, q[:, 0])


def lips_meeting(
    vertices: np.ndarray, triangles: np.ndarray, inner: np.ndarray, axes: np.ndarray, *, iod: float
) -> float:
    """IOD: how far above the inner-lip point ``inner`` (3,) the closed lips meet, seen from the front (``axes`` (3, 3)
    the face frame's side, up and forward axes, rows): rays along -forward at the point's side coordinate, every
    MEETING_STEP IOD upwards from the point; while the front-most face a ray meets is a lip's top (normal within
    TOP_FACING degrees of up, turned to face the viewer), the meeting lies higher. 0 when the point's own ray meets no
    lip top, or no ray within MEETING_REACH leaves the lip's top (or a ray meets nothing).

    An automatic inner-lip point can land on the lower lip's top, below the slit where the upper lip's overhang meets
    it: on the 3,810-triangle Lee Perry-Smith copy 0.014 IOD below (docs/animation.md, "The low-poly pale strip"). The
    knife's curve through it cut a strip of the lower lip's top off with the upper lip, a pale line between the lips
    at /m/ and a pale band at /u/; through the meeting it runs along the slit."""
    ax = np.asarray(axes, dtype=np.float64)
    q = np.asarray(vertices, dtype=np.float64) @ ax.T
    qt = q[np.asarray(triangles, dtype=np.int64)]  # (m, 3, 3) side, up, forward
    x, y0 = (np.asarray(inner, dtype=np.float64) @ ax.T)[:2]
    top = y0 + MEETING_REACH * iod
    # The faces a ray can meet: spanning the point's side coordinate, within the heights the rays cover.
    near = (qt[:, :, 0].min(axis=1) <= x) & (qt[:, :, 0].max(axis=1) >= x)
    near &= (qt[:, :, 1].max(axis=1) >= y0) & (qt[:, :, 1].min(axis=1) <= top)
    qt = qt[near]
    if not len(qt):
        return 0.0
    n = np.cross(qt[:, 1] - qt[:, 0], qt[:, 2] - qt[:, 0])
    n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None] / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    lip_top = n[:, 1] >= np.cos(np.radians(TOP_FACING))
    a, b, c = qt[:, 0, :2], qt[:, 1, :2], qt[:, 2, :2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(det) > 1e-18 * iod * iod  # faces seen edge-on hide nothing
    for k in range(int(round(MEETING_REACH / MEETING_STEP)) + 1):
        py = y0 + k * MEETING_STEP * iod
        d = np.where(ok, det, 1.0)
        wb = ((x - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (py - a[:, 1])) / d
        wc = ((b[:, 0] - a[:, 0]) * (py - a[:, 1]) - (x - a[:, 0]) * (b[:, 1] - a[:, 1])) / d
        hit = ok & (wb >= 0) & (wc >= 0) & (wb + wc <= 1)
        if not hit.any():
            return 0.0
        z = qt[:, 0, 2] + wb * (qt[:, 1, 2] - qt[:, 0, 2]) + wc * (qt[:, 2, 2] - qt[:, 0, 2])
        front = int(np.argmax(np.where(hit, z, -np.inf)))
        if not lip_top[front]:
            return k * MEETING_STEP
    return 0.0


def knife_contact(
    vertices: np.ndarray,
    triangles: np.ndarray,
    left: int,
    right: int,
    inner: np.ndarray,
    axes: np.ndarray,
    *,
    iod: float,
    meeting: bool = True,
) -> KnifeCut | None:
    """Cut ``triangles`` along the lip contact curve (:func:`contact_offset`: through the corner vertices ``left``,
    ``right`` and the inner-lip point ``inner`` (3,), raised to where the lips meet when it lies on the lower lip's
    top: :func:`lips_meeting`), ``axes`` (3, 3) the face frame's side, up and forward axes (rows). Every face within
    the mouth's width and front (KNIFE_SIDE, KNIFE_DEPTH, KNIFE_HEIGHT) that the curve crosses gets a vertex on each
    crossed edge (a crossing within KNIFE_SNAP IOD of an end takes that end); faces sharing a split edge are split
    too, so the mesh stays conforming, and every new vertex lies on an old edge (the surface, its UVs and colours
    are unchanged). Where the curve runs along an edge of the mesh (lips touching along one long edge), the edge is
    split into pieces no longer than the mouth's width / COARSE_EDGES (:func:`split_long_edges`). Where the cut
    pieces leave a gap between the corners (a face the curve crosses lies outside those bounds), the path bridges it
    along the cut faces' edges (KNIFE_BRIDGE); returns None when even that does not join them. ``meeting``: False, the
    curve passes through ``inner`` as given (not raised)."""
    ax = np.asarray(axes, dtype=np.float64)
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    width = float(np.linalg.norm(v[left] - v[right]))
    raised = lips_meeting(v, t, inner, ax, iod=iod) if meeting else 0.0
    inner = np.asarray(inner, dtype=np.float64) + raised * iod * ax[1]
    qi = inner @ ax.T
    q = v @ ax.T
    s = contact_offset(q, q[left], q[right], qi)
    s[np.abs(s) <= 1e-9 * iod] = 0.0  # on the curve to rounding (a contact edge the curve runs along)
    s[[left, right]] = 0.0
    region = _knife_region(q, t, left, right, iod, s)
    e_all = np.concatenate([t[region][:, [0, 1]], t[region][:, [1, 2]], t[region][:, [2, 0]]])
    e_all = np.unique(np.sort(e_all, axis=1), axis=0)
    # Crossings near an edge's end move onto it (that vertex is then on the curve): no slivers.
    for _ in range(10):
        a, b = e_all[:, 0], e_all[:, 1]
        cross = s[a] * s[b] < 0
        w = np.where(cross, s[a] / np.where(cross, s[a] - s[b], 1.0), 0.0)
        length = np.linalg.norm(v[a] - v[b], axis=1)
        snap_a = cross & (w * length < KNIFE_SNAP * iod) & (w <= 0.5)
        snap_b = cross & ((1 - w) * length < KNIFE_SNAP * iod) & (w > 0.5)
        if not (snap_a.any() or snap_b.any()):
            break
        s[e_all[snap_a, 0]] = 0.0
        s[e_all[snap_b, 1]] = 0.0
    cross = s[e_all[:, 0]] * s[e_all[:, 1]] < 0
    edge = e_all[cross]
    at = s[edge[:, 0]] / (s[edge[:, 0]] - s[edge[:, 1]])
    n = len(v)
    on = np.r_[s == 0, np.ones(len(edge), dtype=bool)]  # the vertices on the curve, the new ones too
    v2, t2 = _split_edges(v, t, edge, at)
    region2 = _knife_region(np.r_[q, v2[n:] @ ax.T], t2, left, right, iod, np.r_[s, np.zeros(len(edge))])
    # The curve's pieces: edges of the cut faces whose two ends are on the curve.
    e_cut = np.concatenate([t2[region2][:, [0, 1]], t2[region2][:, [1, 2]], t2[region2][:, [2, 0]]])
    e_cut = np.unique(np.sort(e_cut, axis=1), axis=0)
    piece = on[e_cut[:, 0]] & on[e_cut[:, 1]]
    if not piece.any():
        return None
    e2 = e_cut[piece]
    lw = np.linalg.norm(v2[e2[:, 0]] - v2[e2[:, 1]], axis=1) + 1e-12 * iod
    g = sp.csr_matrix((np.r_[lw, lw], (np.r_[e2[:, 0], e2[:, 1]], np.r_[e2[:, 1], e2[:, 0]])), shape=(len(v2),) * 2)
    dist, pred = dijkstra(g, indices=left, return_predecessors=True)
    if not np.isfinite(dist[right]):
        # The pieces leave a gap: the curve crossed a face outside the region (a vertex past KNIFE_DEPTH or
        # KNIFE_SIDE), whose crossed edges stayed whole. Followed on past the bounds the curve may wander into
        # the lips' slit (the 3,810-triangle Lee Perry-Smith copy mirrored: from the loose end 0.09 IOD from the
        # left corner it dips past 0.2 IOD behind the corners, and the pieces on either side turn back on
        # themselves), so the gap is bridged along the cut faces' own edges instead: the path is the shortest from
        # corner to corner over the pieces and those edges, each costing KNIFE_BRIDGE times its length and taken only
        # towards the right corner (docs/animation.md, "The knife's gap"). Bridged in both directions the path
        # turned back past a corner's neighbour (0 / 2.78 but the lips parting 0.40); bridged only between loose
        # ends, it ran a hairpin out and back along the pieces (0 / 2.95, parting 0.35).
        off = e_cut[~piece]
        # Each off-curve edge only in the direction from the left corner's side to the right's: no bridge back.
        ahead = (v2[off[:, 1]] - v2[off[:, 0]]) @ (v[right] - v[left]) >= 0
        off = np.where(ahead[:, None], off, off[:, ::-1])
        ow = KNIFE_BRIDGE * (np.linalg.norm(v2[off[:, 0]] - v2[off[:, 1]], axis=1) + 1e-12 * iod)
        g = sp.csr_matrix(
            (np.r_[lw, lw, ow], (np.r_[e2[:, 0], e2[:, 1], off[:, 0]], np.r_[e2[:, 1], e2[:, 0], off[:, 1]])),
            shape=(len(v2),) * 2,
        )
        dist, pred = dijkstra(g, indices=left, return_predecessors=True)
        if not np.isfinite(dist[right]):
            return None
    path = [right]
    while path[-1] != left:
        path.append(int(pred[path[-1]]))
    bridged = sum(1 for a, b in itertools.pairwise(path) if not (on[a] and on[b]))
    v3, t3, edge3, at3, path3 = split_long_edges(v2, t2, path[::-1], width / COARSE_EDGES, among=n)
    if bridged > KNIFE_BRIDGE_SHARE * (len(path3) - 1):
        return None
    s3 = np.r_[s, np.zeros(len(v3) - n)]  # the knife's vertices lie on the curve
    v4, t4, edge4, at4, behind = split_lip_back(v3, t3, path3, s3, ax, iod=iod, longest=LIP_BACK_SPAN * width)
    s4 = np.r_[s3, np.zeros(len(v4) - len(s3))]
    v5, t5, edge5, at5 = split_lower_corner(
        v4, t4, path3, s4, longest=CORNER_SPAN * 0.5 * width, at_most=CORNER_SPAN_MAX * 0.5 * width
    )
    return KnifeCut(
        vertices=v5,
        triangles=t5,
        edge=np.concatenate([edge.astype(np.int64), edge3, edge4, edge5]),
        at=np.concatenate([at, at3, at4, at5]),
        path=path3,
        behind=behind,
        corners_split=len(edge5),
        bridged=bridged,
        inner=inner,
        raised=raised,
    )


def split_lip_back(
    vertices: np.ndarray,
    triangles: np.ndarray,
    path: list[int],
    s: np.ndarray,
    axes: np.ndarray,
    *,
    iod: float,
    longest: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[int, int]]:
    """Split the upper lip's back where it runs behind the knife's ``path`` (corner to corner): every edge at
    least ``longest`` long (head units), not on the path, whose two ends are path vertices or lie no higher
    than LIP_BACK_HEIGHT IOD above the contact curve (``s`` (n,), :func:`contact_offset`, head units), gets a
    vertex where it passes more than KNIFE_SNAP IOD (and at most LIP_BACK_DEPTH) behind an interior path vertex
    and not below it (the face
    frame's side coordinate; ``axes`` (3, 3) its rows), each split a fan as in :func:`split_long_edges`. On a
    decimated mouth such an edge can span most of the mouth (Lee Perry-Smith at 1,428 triangles: 292-410, 0.51
    IOD from beside the right corner, 0.04-0.06 IOD behind three path vertices): straight, it cannot follow the
    cut's upper edge, which bends down towards the corners as the jaw opens, and the face above it hung below
    the cut into the opening, a pink flap (docs/animation.md, "The 1,428 copy's flap"). Returns vertices
    (n + k, 3), triangles, the (k, 2) edge each new vertex lies on, (k,) where on it (see :class:`KnifeCut`)
    and new vertex -> the path vertex in front of it (the rig moves it as that vertex's upper side)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    q = v @ np.asarray(axes, dtype=np.float64).T
    on = np.zeros(len(v), dtype=bool)
    on[path] = True
    low = on | ((s > 0) & (s <= LIP_BACK_HEIGHT * iod))
    interior = np.asarray(path[1:-1], dtype=np.int64)
    path_edges = {(min(a, b), max(a, b)) for a, b in itertools.pairwise(path)}
    e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    e = e[low[e[:, 0]] & low[e[:, 1]] & ~(on[e[:, 0]] & on[e[:, 1]])]
    e = e[np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) >= longest]
    edges: list[tuple[int, int]] = []
    ats: list[float] = []
    behind: dict[int, int] = {}
    for a, b in e.tolist():
        if (a, b) in path_edges:
            continue
        dx = q[b, 0] - q[a, 0]
        if abs(dx) <= KNIFE_SNAP * iod:
            continue
        f = (q[interior, 0] - q[a, 0]) / dx
        length = float(np.linalg.norm(v[b] - v[a]))
        inside = (f * length > KNIFE_SNAP * iod) & ((1 - f) * length > KNIFE_SNAP * iod)
        point = q[a] + f[:, None] * (q[b] - q[a])
        # Behind the path vertex and not below it: the lip's back, which the cut's upper edge hides at rest; no
        # further behind than LIP_BACK_DEPTH (an edge of the mouth cavity's back is not the lip's).
        depth = q[interior, 2] - point[:, 2]
        hidden = inside & (depth > KNIFE_SNAP * iod) & (depth <= LIP_BACK_DEPTH * iod) & (point[:, 1] >= q[interior, 1])
        for fr, p in sorted(zip(f[hidden].tolist(), interior[hidden].tolist(), strict=True)):
            edges.append((a, b))
            ats.append(fr)
            behind[len(v) + len(edges) - 1] = p
    if not edges:
        return v, t, np.zeros((0, 2), dtype=np.int64), np.zeros(0), {}
    # One split at a time, each on what is left of its edge (the pieces as :func:`_split_edges` makes them).
    out_edge: list[tuple[int, int]] = []
    out_at: list[float] = []
    v2, t2 = v, t
    last: dict[tuple[int, int], tuple[int, float]] = {}  # edge -> (the vertex its remaining piece starts at, fraction)
    for (a, b), fr in zip(edges, ats, strict=True):
        start, f0 = last.get((a, b), (a, 0.0))
        w = (fr - f0) / (1.0 - f0)
        lo, hi, at = (start, b, w) if start < b else (b, start, 1.0 - w)
        v2, t2 = _split_edges(v2, t2, np.array([[lo, hi]]), np.array([at]))
        out_edge.append((lo, hi))
        out_at.append(at)
        last[(a, b)] = (len(v2) - 1, fr)
    return v2, t2, np.asarray(out_edge, dtype=np.int64), np.asarray(out_at), behind


def split_lower_corner(
    vertices: np.ndarray, triangles: np.ndarray, path: list[int], s: np.ndarray, *, longest: float, at_most: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where the knife's ``path`` leaves a mouth corner through one edge longer than ``longest`` and no longer than
    ``at_most`` (head units), the edge from the corner to the lower lip's vertex of the face below that edge (the
    face's third vertex, below the contact curve: ``s`` (n,) < 0, :func:`contact_offset`) gets a vertex at its
    middle. The lower lip's corner face otherwise spans from the corner, which the rig holds nearly still, to a vertex
    that drops with the lower lip: on the stylised held-out head (the path's end edge 0.22 IOD, 0.48 of the
    half-width) face [762, 969, 903] at /a/ stood as a lit wedge from the opening's bottom to the corner over a dark
    crease past it (docs/animation.md, "The stylised head's lower-lip corner"). Split, the field bends the lower
    lip's edge into the corner. Returns vertices (n + k, 3), triangles, the (k, 2) edges split and (k,) where
    (0.5)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    pairs: list[tuple[int, int]] = []
    for corner, nxt in ((path[0], path[1]), (path[-1], path[-2])):
        if len(path) < 3 or not longest < float(np.linalg.norm(v[corner] - v[nxt])) <= at_most:
            continue
        faces = t[(t == corner).any(axis=1) & (t == nxt).any(axis=1)]
        third = [int(x) for f in faces.tolist() for x in f if x not in (corner, nxt) and s[x] < 0]
        if third:
            low = min(third, key=lambda x: float(s[x]))
            pairs.append((min(corner, low), max(corner, low)))
    if not pairs:
        return v, t, np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    edge = np.asarray(sorted(set(pairs)), dtype=np.int64)
    at = np.full(len(edge), 0.5)
    v2, t2 = _split_edges(v, t, edge, at)
    return v2, t2, edge, at


def split_long_edges(
    vertices: np.ndarray, triangles: np.ndarray, path: list[int], longest: float, *, among: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Split every edge of ``path`` longer than ``longest`` (head units) into equal pieces: a contact that
    is one long edge (a decimated head's lips) gets vertices on it, so the cut has vertices to split and
    the lips can part along it. Each face on a split edge becomes a fan from its third vertex. ``among``:
    split only edges between two of the first ``among`` vertices (the mesh's own edges that the contact
    curve runs along; the knife's pieces across a face are left whole: on Lee Perry-Smith at 1,428
    triangles their fans were slivers tied to the mouth corners, and the rig opened 0.19 instead of 0.69,
    see docs/animation.md). Returns vertices (n + k, 3), triangles, the (k, 2) edge each new vertex lies
    on and (k,) where on it (see :class:`KnifeCut`), and the path with the new vertices."""
    v0 = np.asarray(vertices, dtype=np.float64)
    n = len(v0)
    added: list[np.ndarray] = []
    tris = [tuple(f) for f in np.asarray(triangles, dtype=np.int64).tolist()]
    edges: list[tuple[int, int]] = []
    ats: list[float] = []
    out_path = [path[0]]
    for a, b in itertools.pairwise(path):
        pieces = int(np.ceil(float(np.linalg.norm(v0[a] - v0[b])) / longest - 1e-9)) if longest > 0 else 1
        if pieces >= 2 and (among is None or max(a, b) < among):
            fracs = np.arange(1, pieces) / pieces
            ids = list(range(n + len(edges), n + len(edges) + pieces - 1))
            edges += [(a, b)] * (pieces - 1)
            ats += fracs.tolist()
            added.append((1 - fracs)[:, None] * v0[a] + fracs[:, None] * v0[b])
            chain = [a, *ids, b]
            fans: list[tuple[int, ...]] = []
            for f in tris:
                for r in range(3):
                    p, q, o = f[r], f[(r + 1) % 3], f[(r + 2) % 3]
                    if (p, q) in ((a, b), (b, a)):
                        seq = chain if p == a else chain[::-1]
                        fans += [(seq[i], seq[i + 1], o) for i in range(len(seq) - 1)]
                        break
                else:
                    fans.append(f)
            tris = fans
            out_path += ids
        out_path.append(b)
    return (
        np.concatenate([v0, *added]) if added else v0,
        np.asarray(tris, dtype=np.int64).reshape(-1, 3),
        np.asarray(edges, dtype=np.int64).reshape(-1, 2),
        np.asarray(ats, dtype=np.float64),
        out_path,
    )


def _knife_region(q: np.ndarray, t: np.ndarray, left: int, right: int, iod: float, s: np.ndarray) -> np.ndarray:
    """(m,) bool the faces the knife may cut: every vertex within the mouth's width (KNIFE_SIDE beyond
    the corners) and no further than KNIFE_DEPTH behind the corners, and the face reaching within
    KNIFE_HEIGHT of the contact curve (``s`` (n,), :func:`contact_offset`); ``q`` (n, 3) the vertices in
    the face frame."""
    x_lo, x_hi = sorted((q[left, 0], q[right, 0]))
    back = min(q[left, 2], q[right, 2]) - KNIFE_DEPTH * iod
    qt = q[t]
    return (
        (qt[:, :, 0] >= x_lo - KNIFE_SIDE * iod).all(axis=1)
        & (qt[:, :, 0] <= x_hi + KNIFE_SIDE * iod).all(axis=1)
        & (qt[:, :, 2] >= back).all(axis=1)
        & (s[t].min(axis=1) <= KNIFE_HEIGHT * iod)
        & (s[t].max(axis=1) >= -KNIFE_HEIGHT * iod)
    )


def _split_edges(v: np.ndarray, t: np.ndarray, edge: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert a vertex on each edge (k, 2) (sorted pairs) at ``at`` (k,) along it and split every face
    with split edges: one split edge into two faces (a fan from the opposite vertex), two into three
    (the lone vertex's corner and the quad left, along its shorter diagonal), three into four (the
    midpoint subdivision). Windings are kept. Returns vertices (n + k, 3) and triangles."""
    n = len(v)
    new_id = {(int(i), int(j)): n + k for k, (i, j) in enumerate(np.asarray(edge).tolist())}
    v2 = np.concatenate([v, (1 - at)[:, None] * v[edge[:, 0]] + at[:, None] * v[edge[:, 1]]]) if len(edge) else v

    def mid(i: int, j: int) -> int | None:
        return new_id.get((i, j) if i < j else (j, i))

    out: list[tuple[int, int, int]] = []
    for i, j, k in t.tolist():
        ms = [mid(i, j), mid(j, k), mid(k, i)]
        cut = [m is not None for m in ms]
        if not any(cut):
            out.append((i, j, k))
            continue
        if all(cut):
            a, b, c = ms
            assert a is not None and b is not None and c is not None
            out += [(i, a, c), (a, j, b), (c, b, k), (a, b, c)]
            continue
        # Rotate so that the first edge (c0 -> c1) is split.
        r = cut.index(True)
        c0, c1, c2 = [(i, j, k)[(r + o) % 3] for o in range(3)]
        m01, m12, m20 = mid(c0, c1), mid(c1, c2), mid(c2, c0)
        assert m01 is not None
        if m12 is None and m20 is None:
            out += [(c0, m01, c2), (m01, c1, c2)]
        elif m12 is not None:  # c1 alone on one side
            out += [(m01, c1, m12), *_quad(v2, c0, m01, m12, c2)]
        else:  # c0 alone on one side
            assert m20 is not None
            out += [(c0, m01, m20), *_quad(v2, m01, c1, c2, m20)]
    return v2, np.asarray(out, dtype=np.int64).reshape(-1, 3)


def _quad(v: np.ndarray, a: int, b: int, c: int, d: int) -> list[tuple[int, int, int]]:
    """The quad a-b-c-d (in winding order) as two triangles split along its shorter diagonal."""
    if np.linalg.norm(v[a] - v[c]) <= np.linalg.norm(v[b] - v[d]):
        return [(a, b, c), (a, c, d)]
    return [(a, b, d), (b, c, d)]
