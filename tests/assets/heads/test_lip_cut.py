"""Cutting closed lips open (:func:`assets.heads.rigging.cut_mouth`) and the harmonic field with the
cut's two sides pinned to their own lips, on synthetic meshes (no head files needed)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from assets.heads.rigging import cut_mouth


def _grid_triangles(rows: int, cols: int) -> np.ndarray:
    """(2 (rows - 1) (cols - 1), 3) int triangles of a row-major ``rows`` x ``cols`` vertex grid."""
    t = []
    for j in range(rows - 1):
        for i in range(cols - 1):
            a = j * cols + i
            t += [[a, a + cols + 1, a + 1], [a, a + cols, a + cols + 1]]
    return np.array(t)


def _creased_lips(depth: float = 0.1, profile: list[tuple[float, float]] | None = None):
    """A closed mouth whose lips meet in a crease, as scanned heads have it: the profile runs down the
    upper lip to the contact line (y = 0, z = 0), back into a crease behind it (slightly above the
    contact line), and out again down the lower lip; 17 columns from x = -1 to 1, corners at y = 0,
    the crease shallower towards them. ``profile``: (y, z) rows from the top instead, the contact
    line the fourth."""
    profile = profile or [
        (0.5, 0.0),
        (0.25, 0.0),
        (0.1, 0.0),
        (0.0, 0.0),
        (0.02, -depth),
        (-0.04, -0.5 * depth),
        (-0.1, 0.0),
        (-0.25, 0.0),
        (-0.5, 0.0),
    ]
    xs = np.linspace(-1.0, 1.0, 17)
    rows = len(profile)
    v = []
    for y, z in profile:
        for x in xs:
            fade = max(0.2, min(1.0, 4.0 * (1.0 - abs(x))))  # the crease grows shallow at the corners
            v.append([x, y * fade if abs(y) < 0.2 else y, z * fade])
    v = np.array(v)
    t = []
    for j in range(rows - 1):
        for i in range(len(xs) - 1):
            a = j * len(xs) + i
            t += [[a, a + len(xs) + 1, a + 1], [a, a + len(xs), a + len(xs) + 1]]
    contact = 3 * len(xs)
    return v, np.array(t), contact, contact + len(xs) - 1, contact + len(xs) // 2


def test_cut_mouth_separates_lips_that_meet_in_a_crease():
    """The crease behind the contact line must not keep the lips joined (it did when only the path's
    vertices were split: the crease wall bridged the two lips, a shard across the opening)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    e = np.concatenate([t2[:, [0, 1]], t2[:, [1, 2]], t2[:, [2, 0]]])
    w = np.linalg.norm(v2[e[:, 0]] - v2[e[:, 1]], axis=1)
    g = sp.csr_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v2), len(v2)))
    top = int(np.argmin(np.linalg.norm(v2 - [0, 0.25, 0], axis=1)))
    bottom = int(np.argmin(np.linalg.norm(v2 - [0, -0.25, 0], axis=1)))
    # Only around a mouth corner (x = +-1) can one lip reach the other.
    assert dijkstra(g, indices=top)[bottom] > 1.5
    np.testing.assert_array_equal(v2[origin], v2)
    # No triangle joins a vertex of the upper lip's outer surface to one of the lower lip's.
    up_side = v2[:, 1] > 0.05
    low_side = v2[:, 1] < -0.05
    assert not (up_side[t2].any(axis=1) & low_side[t2].any(axis=1)).any()


def test_harmonic_field_opens_creased_lips_cleanly():
    """The cut creased lips of :func:`_creased_lips` with the seam's two sides pinned to their own
    lip (upper to a still control, lower to one that drops by 0.15): the field opens the mouth with
    no flipped triangle and no edge stretched past 3x, and the two sides of the cut part by the
    whole drop at the midline."""
    import scipy.sparse as sp

    from realtime_core.face.harmonic import harmonic_weights

    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    n = len(v)
    copies = np.arange(n, len(v2))
    pin = np.concatenate([origin[copies], copies])
    rows = sp.csr_matrix(
        (np.ones(len(pin)), (np.arange(len(pin)), np.r_[np.zeros(len(copies)), np.ones(len(copies))])),
        shape=(len(pin), 2),
    )
    top = int(np.argmin(np.linalg.norm(v2 - [0, 0.25, 0], axis=1)))
    bottom = int(np.argmin(np.linalg.norm(v2 - [0, -0.25, 0], axis=1)))
    # Sec. 5.2's region: everything but the outer rim (the rows at y = +-0.5 and the corner columns).
    still = (np.abs(v2[:, 1]) >= 0.5) | (np.abs(v2[:, 0]) >= 1.0)
    sec5 = sp.csr_matrix(np.c_[(~still).astype(float), np.zeros(len(v2))])
    g = harmonic_weights(v2, t2, np.array([top, bottom]), sec5, pinned=pin, pinned_rows=rows)
    motion = np.array([[0.0, 0.0, 0.0], [0.0, -0.15, 0.0]])
    v1 = v2 + g @ motion
    n0 = np.cross(v2[t2[:, 1]] - v2[t2[:, 0]], v2[t2[:, 2]] - v2[t2[:, 0]])
    n1 = np.cross(v1[t2[:, 1]] - v1[t2[:, 0]], v1[t2[:, 2]] - v1[t2[:, 0]])
    assert (np.einsum("ij,ij->i", n0, n1) > 0).all()
    e = np.concatenate([t2[:, [0, 1]], t2[:, [1, 2]], t2[:, [2, 0]]])
    l0 = np.linalg.norm(v2[e[:, 0]] - v2[e[:, 1]], axis=1)
    ratio = np.linalg.norm(v1[e[:, 0]] - v1[e[:, 1]], axis=1) / l0
    assert ratio.max() < 3.0
    centre = copies[np.argmin(np.abs(v2[copies, 0]) + np.abs(v2[copies, 2]))]
    assert v1[origin[centre], 1] - v1[centre, 1] == pytest.approx(0.15)


def test_front_contact_moves_a_point_inside_the_crease_to_the_lips_front_edge():
    """A landmark found on a render lands inside the crease between closed lips (Lee Perry-Smith's automatic
    inner-lip points sat up the lower lip's crease wall; the cut from there folded the rig, 33 flipped
    triangles). front_contact moves it to the front edge of the lower lip where the crease begins, and
    leaves a point already there (the hand-picked kind) where it is."""
    from assets.heads.rigging import front_contact

    v, t, _, _, mid = _creased_lips()
    cols = 17
    forward = np.array([0.0, 0.0, 1.0])
    wall = mid + 2 * cols  # row 5: the crease's lower wall, facing up and back
    edge = mid + 3 * cols  # row 6: where the lower lip's front meets the crease
    assert v[wall, 2] < -0.01 and abs(v[edge, 2]) < 1e-12
    assert front_contact(v, t, wall, forward, reach=0.5) == edge
    assert front_contact(v, t, edge, forward, reach=0.5) == edge
    # Wound the other way round: the same answer.
    assert front_contact(v, t[:, ::-1], wall, forward, reach=0.5) == edge


def test_every_interior_vertex_of_the_cut_path_is_split():
    """Where the per-edge height test contradicts itself along the path (on Lee Perry-Smith's crease it
    did for 22-48% of the path's edges), a path vertex must still be split: left whole on one lip it
    tied the lips together there, and the rig folded around it (meshopt's 5 flipped triangles sat at
    its 6 unsplit path vertices). A flat strip whose path is the middle row; over x in [0.2, 0.3] the
    rows beside the path are swapped in height, so the faces above the path there have the lower
    third vertex. The lower lip's seeds reach further (CREASE_TO_LOWER: here 0.15, 3 columns), so
    before they swallowed the upper seeds on both sides of the path from x = 0.1 to 0.35."""
    xs = np.linspace(-1.0, 1.0, 41)
    ys = [0.5, 0.25, 0.05, 0.0, -0.05, -0.25, -0.5]
    v = []
    for y in ys:
        for x in xs:
            swapped = 0.2 <= x <= 0.3 and abs(y) == 0.05
            v.append([x, -1.5 * y if swapped else y, 0.0])
    v = np.array(v)
    cols = len(xs)
    t = _grid_triangles(len(ys), cols)
    left, right = 3 * cols, 4 * cols - 1
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]))
    split = set(origin[len(v) :].tolist())
    interior = range(left + 1, right)
    assert not [int(p) for p in interior if p not in split]
    # Each copy is used only by faces that no longer use its original (the two sides really part).
    for c in range(len(v), len(v2)):
        faces_c = (t2 == c).any(axis=1)
        assert faces_c.any() and not (faces_c & (t2 == origin[c]).any(axis=1)).any()


def test_level_path_bypasses_an_inner_lip_point_below_the_contact_line():
    """A cut pulled through an inner-lip point below its path neighbours makes a V (Lee Perry-Smith's
    front-contact vertex, 0.028 IOD below them): a wedge of the lower lip's front went with the upper lip,
    a notch at /a/ and a dark V at /m/. level_path joins the neighbours by a level detour and names the
    vertex that now stands for the point; a point on the line is left alone."""
    from assets.heads.rigging import cut_path, level_path

    xs = np.linspace(-1.0, 1.0, 21)
    ys = [0.3, 0.1, 0.0, -0.1, -0.3]
    v = np.array([[x, y, 0.0] for y in ys for x in xs])
    cols = len(xs)
    t = _grid_triangles(len(ys), cols)
    left, right = 2 * cols, 3 * cols - 1
    dip = 3 * cols + 10  # x = 0, one row below the contact line (y = -0.1)
    up = np.array([0.0, 1.0, 0.0])
    path = cut_path(v, t, left, right, through=dip)
    assert dip in path
    new, stand = level_path(v, t, path, dip, up, iod=1.0)
    assert dip not in new and new[0] == left and new[-1] == right
    assert np.abs(v[new, 1]).max() < 1e-12  # the detour runs along the contact line
    assert stand == 2 * cols + 10  # the contact vertex above the point
    on_line = 2 * cols + 10
    assert level_path(v, t, cut_path(v, t, left, right, through=on_line), on_line, up, iod=1.0)[1] == on_line


def test_mend_front_keeps_the_upper_lips_skin_whole_near_the_corners():
    """Lower-side faces reaching up into the upper lip's skin beside a mouth corner split vertices there (a
    crack rising from the corner on Lee Perry-Smith's meshopt file at /a/): after the mend no vertex off
    the path, above and in front of it, has faces on both sides, the faces on the path's edges keep their
    sides, and a lump away from the corners is left as it was."""
    from assets.heads.rigging import _mend_front, cut_path

    xs = np.linspace(-1.0, 1.0, 21)
    ys = [0.3, 0.2, 0.1, 0.0, -0.1, -0.3]
    v = np.array([[x, y, 0.5 * max(y, 0.0)] for y in ys for x in xs])  # the upper rows lean forward (+z)
    cols = len(xs)
    t = _grid_triangles(len(ys), cols)
    left, right = 3 * cols, 4 * cols - 1
    path = cut_path(v, t, left, right)
    assert np.abs(v[path, 1]).max() < 1e-12
    c = v[t].mean(axis=1)
    lower = c[:, 1] < 0
    on_path = np.isin(t, path).sum(axis=1) == 2  # the faces on the path's edges (seeds: above is upper)
    corner_lump = (c[:, 0] > 0.75) & (c[:, 1] > 0) & (c[:, 1] < 0.2) & ~on_path
    mid_lump = (np.abs(c[:, 0]) < 0.15) & (c[:, 1] > 0) & (c[:, 1] < 0.2) & ~on_path
    lower |= corner_lump | mid_lump
    up, fwd = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    near = np.ones(len(t), dtype=bool)
    out = _mend_front(v, t, path, lower, near, up, fwd, margin=0.02)
    n_lo = np.bincount(t[out].ravel(), minlength=len(v))
    n_up = np.bincount(t[~out].ravel(), minlength=len(v))
    skin = (v[:, 1] > 0.02) & (np.abs(v[:, 0]) > 0.7)
    assert not (skin & (n_lo > 0) & (n_up > 0)).any()
    assert (out[on_path] == lower[on_path]).all()
    assert (out[mid_lump] == lower[mid_lump]).all() and not out[corner_lump].any()


def test_the_cut_creases_inner_walls_are_removed_and_the_lips_fronts_kept():
    """A cut crease's walls (hidden behind the lips at rest) pulled into the opening showed as pink
    slivers along the lower lip and across the corners of Lee Perry-Smith's /a/: they go, with the
    fins they leave, while every face of the lips' front surfaces stays."""
    from dataclasses import dataclass, field

    from assets.heads.mesh import HeadMesh
    from assets.heads.rigging import inner_lip_vertices, without_inner_lips
    from realtime_core.face.model import FaceFrame

    @dataclass(frozen=True)
    class _Still:
        triangles: np.ndarray
        meta: dict = field(default_factory=dict)

    # A deep crease: three rows curl back and up behind the upper lip's front, two come down to the lower lip.
    deep = [(0.5, 0.0), (0.25, 0.0), (0.1, 0.0), (0.0, 0.0), (0.03, -0.05), (0.05, -0.1), (0.03, -0.15)]
    deep += [(-0.02, -0.12), (-0.05, -0.06), (-0.1, 0.0), (-0.25, 0.0), (-0.5, 0.0)]
    v, t, left, right, mid = _creased_lips(profile=deep)
    v2, t2, _, _ = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    mesh = HeadMesh(vertices=v2, triangles=t2, name="creased lips")
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=2.0)
    lm = {
        "corner_left": left,
        "corner_right": right,
        "upper_lip": int(np.argmin(np.linalg.norm(v2 - [0, 0.25, 0], axis=1))),
        "lower_lip": int(np.argmin(np.linalg.norm(v2 - [0, -0.25, 0], axis=1))),
    }
    inner = inner_lip_vertices(mesh, frame, lm)
    # The crease's rows behind the upper lip's front (y > 0); those below the contact line are the
    # front-most surface at their place (the crease opens to the front there) and stay.
    crease = np.flatnonzero((v2[:, 2] < -1e-9) & (v2[:, 1] > 0) & (np.abs(v2[:, 0]) < 1 - 1e-9))
    assert len(crease) >= 3 * 15
    np.testing.assert_array_equal(np.sort(inner), crease)
    rig, out = without_inner_lips(_Still(triangles=t2), mesh, inner)
    np.testing.assert_array_equal(rig.triangles, out.triangles)
    kept = np.asarray(out.triangles)
    # No face lies wholly in the crease; every face of the front surfaces (z = 0) is kept.
    assert not np.isin(kept, crease).all(axis=1).any()
    front = (np.abs(v2[t2][:, :, 2]) < 1e-9).all(axis=1)
    assert front.sum() == (np.abs(v2[kept][:, :, 2]) < 1e-9).all(axis=1).sum()
    assert rig.meta["inner_lip_removed"] == len(t2) - len(kept) > 0


def test_control_points_near_the_cuts_ends_are_left_to_the_seam_rows():
    """Within SEAM_TAPER of a cut's end (a mouth corner) the tapered seam rows stand for the control points,
    as within SEAM_CLEAR of the seam: a control point beside the corner pinned the skin there to its lip's
    full motion while the corner's row moves between both lips' (Lee Perry-Smith through meshopt: a flip and
    stretch 4.14 at the widest opening). Control points further off stay."""
    from realtime_core.face.model import FaceFrame, FaceModel
    from realtime_core.face.rig import SEAM_CLEAR, SEAM_TAPER, _seam_rows

    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    copies = np.arange(len(v), len(v2))
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=3.0)
    # (1, 0.25): 0.25 from the corner (1, 0), under SEAM_TAPER (0.3 here) but more than SEAM_CLEAR (0.15)
    # from the seam along the mesh; (0, 0.25) and (0, -0.25): the lips' middles, 0.25 off the seam.
    spots = ([1.0, 0.25, 0.0], [0.0, 0.25, 0.0], [0.0, -0.25, 0.0])
    control = np.array([int(np.argmin(np.linalg.norm(v2 - p, axis=1))) for p in spots])
    assert np.linalg.norm(v2[control[0]] - v2[right]) < SEAM_TAPER * frame.iod
    simple = FaceModel(vertices=v2[control], triangles=np.array([[0, 1, 2]]), name="three points")
    seam = np.column_stack([origin[copies], copies])
    lower = np.array([False, False, True])
    _pin, _rows, near = _seam_rows(v2, t2, simple, frame, seam, lower, ~lower, control)
    assert near.tolist() == [True, False, False]
    assert SEAM_CLEAR < SEAM_TAPER


def _face_components(t: np.ndarray, faces: np.ndarray) -> tuple[int, np.ndarray]:
    """(number, (len(faces),) labels) of the components of ``t[faces]`` joined through shared edges,
    counted from the triangles alone (scipy)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    sub = t[faces]
    edge_face: dict[tuple[int, int], list[int]] = {}
    for f, tri in enumerate(sub):
        for a, b in ((0, 1), (1, 2), (2, 0)):
            edge_face.setdefault((min(tri[a], tri[b]), max(tri[a], tri[b])), []).append(f)
    pairs = [(fs[0], fs[1]) for fs in edge_face.values() if len(fs) == 2]
    rows = [p[0] for p in pairs] + [p[1] for p in pairs]
    cols = [p[1] for p in pairs] + [p[0] for p in pairs]
    g = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(sub),) * 2)
    return connected_components(g, directed=False)


def _lips_with_an_island(hidden_cells: list[tuple[int, int]]):
    """A flat 9 x 7 vertex grid (x -1..1, y 0.75..-0.75), cut along its middle row (y = 0, a path from
    border to border), with a side assignment as the lower side's reach leaves it on a crease: the two
    upper faces of cells (band 2, columns 3 and 4) on the path (the path edges' upper seeds) and the
    rest of the upper side, but the cells round them (band 2 columns 2 and 5, band 1 columns 2 to 5)
    taken by the lower side. ``hidden_cells``: (band, column) cells whose faces the cut mesh loses
    afterwards (the crease's hidden walls). Returns v, t, path, lower, near, gone, the island's faces."""
    cols, rows = 9, 7
    xs = np.linspace(-1.0, 1.0, cols)
    ys = np.linspace(0.75, -0.75, rows)
    v = np.array([[x, y, 0.0] for y in ys for x in xs])
    t = _grid_triangles(rows, cols)

    def cell(j: int, i: int) -> list[int]:
        return [2 * (j * (cols - 1) + i), 2 * (j * (cols - 1) + i) + 1]

    lower = v[t].mean(axis=1)[:, 1] < 0
    for j, i in [(2, 2), (2, 5), (1, 2), (1, 3), (1, 4), (1, 5)]:
        lower[cell(j, i)] = True
    gone = np.zeros(len(t), dtype=bool)
    for j, i in hidden_cells:
        gone[cell(j, i)] = True
    path = list(range(3 * cols, 4 * cols))
    island = np.array(cell(2, 3) + cell(2, 4))
    return v, t, path, lower, np.ones(len(t), dtype=bool), gone, island


def _cut(v, t, path, lower, near):
    from assets.heads.rigging import _split_faces

    split, take = _split_faces(
        v, t, path, lower, near, np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), (path[0], path[-1])
    )
    new_index = np.arange(len(v))
    new_index[split] = len(v) + np.arange(len(split))
    return np.where(take[:, None], new_index[t], t), take


UP, SIDE = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])


def test_an_island_off_the_path_joins_the_lip_around_it():
    """Upper-side faces (band 2, columns 3 and 4) enclosed by lower-side ones (a pocket of the lower side
    above the path, bands 1 to 3) are a piece of the cut mesh apart from both lips; every face beside them is the lower
    lip's, so they join it: the cut mesh is then two pieces (counted by scipy from the triangles alone), the
    lips share no vertex but the corners, and the path vertices split before stay split."""
    from assets.heads.rigging import _without_islands

    cols, rows = 9, 9  # the path along vertex row 4 (y = 0)
    xs, ys = np.linspace(-1.0, 1.0, cols), np.linspace(1.0, -1.0, rows)
    v = np.array([[x, y, 0.0] for y in ys for x in xs])
    t = _grid_triangles(rows, cols)
    path = list(range(4 * cols, 5 * cols))
    near, gone = np.ones(len(t), dtype=bool), np.zeros(len(t), dtype=bool)
    lower = v[t].mean(axis=1)[:, 1] < 0

    def cell(j: int, i: int) -> list[int]:
        return [2 * (j * (cols - 1) + i), 2 * (j * (cols - 1) + i) + 1]

    for j, i in [(3, 2), (3, 3), (3, 4), (3, 5), (2, 2), (2, 5), (1, 2), (1, 3), (1, 4), (1, 5)]:
        lower[cell(j, i)] = True
    island = np.array(cell(2, 3) + cell(2, 4))
    before, _ = _cut(v, t, path, lower, near)
    assert _face_components(before, np.arange(len(t)))[0] == 3  # the upper lip, the lower lip, the island
    fixed = _without_islands(v, t, path, lower, near, UP, SIDE, (path[0], path[-1]), gone)
    after, take = _cut(v, t, path, fixed, near)
    assert _face_components(after, np.arange(len(t)))[0] == 2
    assert take[island].all() and (fixed != lower).sum() == len(island)  # the island alone changes side
    upper_vertices = set(after[~take].ravel().tolist())
    lower_vertices = set(after[take].ravel().tolist())
    assert upper_vertices & lower_vertices <= {path[0], path[-1]}  # the corners only

    def split(cut, side):  # path vertices the upper side keeps while the lower side has their copy
        return {p for p in path[1:-1] if (cut[~side] == p).any() and not (cut[side] == p).any()}

    assert split(after, take) == split(before, _cut(v, t, path, lower, near)[1])


def test_an_island_on_the_path_keeps_its_side_so_every_path_vertex_stays_split():
    """Upper-side faces on the path (its upper seeds) cut off from the upper lip by faces the lower side took:
    joining them to the lower lip would leave their path vertices unsplit, the lips tied there (on Lee
    Perry-Smith the inner-lip landmark's vertex: the lips' gap then did not answer mouth_open and the
    closure check measured a vertex against itself). The rule leaves them: every interior path vertex still
    has a copy in the cut mesh."""
    from assets.heads.rigging import _without_islands

    for hidden in ([], [(1, i) for i in range(1, 7)] + [(2, 1), (2, 6)]):
        v, t, path, lower, near, gone, island = _lips_with_an_island(hidden)
        fixed = _without_islands(v, t, path, lower, near, UP, SIDE, (path[0], path[-1]), gone)
        np.testing.assert_array_equal(fixed, lower)
        after, take = _cut(v, t, path, fixed, near)
        assert not take[island].any()
        for p in path[1:-1]:  # used by both sides: the upper side keeps p, the lower side its copy
            assert (after[~take] == p).any() and not (after[take] == p).any()


def test_an_island_with_only_the_cut_and_walls_beside_it_is_left_and_then_dropped():
    """An island whose only edges to the rest are path edges and hidden walls has no lip beside it: the side
    rule leaves it, and :func:`lip_islands` finds exactly its faces (no more: every face of the lips stays),
    as scipy's components of the faces that stay count it."""
    from assets.heads.rigging import LIP_ISLAND_FACES, _without_islands, lip_islands

    # The island is one cell's two upper faces on the path (band 2, column 4); the walls are the cells
    # round it on the upper side.
    cols = 9
    hidden = [(2, 3), (2, 5), (1, 3), (1, 4), (1, 5)]
    v, t, path, lower, near, gone, _ = _lips_with_an_island(hidden)
    lower = v[t].mean(axis=1)[:, 1] < 0  # a plain cut: upper faces above the path, lower below
    island = np.array([2 * (2 * (cols - 1) + 4), 2 * (2 * (cols - 1) + 4) + 1])
    fixed = _without_islands(v, t, path, lower, near, UP, SIDE, (path[0], path[-1]), gone)
    np.testing.assert_array_equal(fixed, lower)
    after, _ = _cut(v, t, path, fixed, near)
    stays = np.flatnonzero(~gone)
    n, labels = _face_components(after, stays)
    sizes = np.bincount(labels)
    assert n == 3 and sorted(sizes.tolist())[0] == len(island) <= LIP_ISLAND_FACES
    copies = np.unique(after[after >= len(v)])
    drop = lip_islands(after[stays], len(v) + len(copies), np.r_[path, copies])  # the cut's vertices
    np.testing.assert_array_equal(stays[drop], island)


def test_no_lower_face_stays_tied_to_the_upper_lips_skin_at_the_edge_of_the_cut_region():
    """Lower-side faces that reach from the path up to the edge of the region the cut may take (band 1 columns
    3 to 5, above band 2 column 4; the region is bands 1 to 4) share vertices with the upper lip's skin
    beyond it (band 0) and with no upper face in the region, and those are not split:
    a slit into the upper lip that opens from the cut to its tip (Lee Perry-Smith's meshopt file, vertex
    5020). :func:`_without_rim_ties` gives those faces back to the upper side: no vertex of the cut mesh
    but the corners is then shared by a face of each side."""
    from assets.heads.rigging import _without_rim_ties

    cols = 9
    v, t, path, _, _, gone, _ = _lips_with_an_island([])
    c = v[t].mean(axis=1)
    near = np.abs(c[:, 1]) < 0.5  # bands 1 to 4 (band height 0.25)
    lower = c[:, 1] < 0
    top = [2 * (1 * (cols - 1) + i) + k for i in (3, 4, 5) for k in (0, 1)]
    lower[top] = True
    lower[[2 * (2 * (cols - 1) + 4), 2 * (2 * (cols - 1) + 4) + 1]] = True

    def ties(low):
        after, take = _cut(v, t, path, low, near)
        both = set(after[take].ravel().tolist()) & set(after[~take].ravel().tolist())
        return both - {path[0], path[-1]}

    assert ties(lower)  # the slit: band 0's skin and the lower faces share a vertex
    fixed = _without_rim_ties(v, t, path, lower, near, UP, SIDE, gone)
    assert not ties(fixed)
    assert fixed[top].sum() < len(top) / 2  # most given back to the upper lip
    np.testing.assert_array_equal(fixed[c[:, 1] < 0], lower[c[:, 1] < 0])  # the lower lip unchanged


def test_a_head_wound_the_other_way_round_is_recognised():
    """A mirrored export winds every triangle clockwise: the face's triangles then face into the head, and
    rigging reads the winding (the cut's sides, the crease's walls). wound_inwards tells the two apart from
    the face region's summed normal; a head wound either way gives opposite answers."""
    from assets.heads.rigging import wound_inwards

    xs = np.linspace(-1.0, 1.0, 11)
    v = np.array([[x, y, 1.0 - 0.3 * (x * x + y * y)] for y in xs for x in xs])  # a face bulging towards +z
    t = _grid_triangles(len(xs), len(xs))
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    forward = np.array([0.0, 0.0, 1.0])
    if (n @ forward).sum() < 0:
        t = t[:, ::-1]  # the grid's own winding: make it face forward
    nose = v[len(v) // 2]
    assert not wound_inwards(v, t, nose, forward, iod=0.5)
    assert wound_inwards(v, t[:, ::-1], nose, forward, iod=0.5)


def _cut_with_seam(v, t, path, lower, near):
    """The cut mesh's triangles and its (original, copy) vertex pairs."""
    from assets.heads.rigging import _split_faces

    split, take = _split_faces(v, t, path, lower, near, UP, SIDE, (path[0], path[-1]))
    new_index = np.arange(len(v))
    new_index[split] = len(v) + np.arange(len(split))
    after = np.where(take[:, None], new_index[t], t)
    return after, np.column_stack([split, new_index[split]]), take


def test_an_island_on_the_cut_joins_the_other_lip_through_the_copies_and_moves_with_it():
    """The island on the path that :func:`_without_islands` must leave on its side (joining it at the cut ties
    the lips): once the walls round it are gone (here the upper faces round it; the upper lip reaches the path
    further out) it is a piece of its own, its path vertices the upper side's and its other vertices its own.
    :func:`join_path_islands` moves it onto the lower lip through the path vertices' copies: the faces that stay
    are then two pieces (scipy, from the triangles alone), every pair of the cut keeps both its vertices (no face
    of either side uses the other's twin: nothing is tied), and each of the island's own vertices is given rows
    that mix the copies it now shares, nearer ones more."""
    from assets.heads.rigging import join_path_islands

    cols = 9
    hidden = [(1, i) for i in range(2, 6)] + [(2, 2), (2, 5)]  # the walls round the island
    v, t, path, _, near, gone, island = _lips_with_an_island(hidden)
    lower = v[t].mean(axis=1)[:, 1] < 0  # a plain cut: the island's own vertices (row 2) are not split
    after, seam, take = _cut_with_seam(v, t, path, lower, near)
    stays = np.flatnonzero(~gone)
    n_before, labels = _face_components(after, stays)
    island_piece = labels[np.searchsorted(stays, island)]
    assert n_before == 3 and len(np.unique(island_piece)) == 1  # the upper lip, the lower lip, the island
    v2 = np.vstack([v, v[seam[:, 0]]])
    joined, mix = join_path_islands(after[stays], v2, seam)
    assert _face_components(joined, np.arange(len(joined)))[0] == 2
    moved = np.flatnonzero((joined != after[stays]).any(axis=1))
    np.testing.assert_array_equal(stays[moved], island)  # the island's faces alone change
    at = np.searchsorted(stays, island)
    assert not np.isin(joined[at], seam[:, 0]).any()  # it uses the copies only
    upper_faces = np.setdiff1d(np.arange(len(joined)), np.r_[at, np.flatnonzero(take[stays])])
    assert not np.isin(joined[upper_faces], seam[:, 1]).any()  # the upper lip never the copies
    own = np.setdiff1d(joined[at].ravel(), seam[:, 1])
    assert sorted(mix) == own.tolist() == [2 * cols + 3, 2 * cols + 4, 2 * cols + 5]
    for a in own:
        anchors, w = mix[int(a)]
        assert np.isin(anchors, seam[:, 1]).all() and abs(w.sum() - 1.0) < 1e-12
        d = np.linalg.norm(v2[anchors] - v2[a], axis=1)
        np.testing.assert_allclose(w, (1 / d**2) / (1 / d**2).sum())


def test_a_piece_sharing_its_own_vertex_with_a_lip_is_not_joined():
    """Only islands move: the island of the test above with the walls round it gone but cell (1, 2) of the upper
    lip kept, which touches it at one vertex (row 2, column 3; not split, a plain cut): moving the island would
    drag that face of the upper lip along, so nothing changes and no rows are mixed."""
    from assets.heads.rigging import join_path_islands

    v, t, path, _, near, gone, island = _lips_with_an_island([(1, 3), (1, 4), (1, 5), (2, 2), (2, 5)])
    lower = v[t].mean(axis=1)[:, 1] < 0
    after, seam, _ = _cut_with_seam(v, t, path, lower, near)
    stays = np.flatnonzero(~gone)
    v2 = np.vstack([v, v[seam[:, 0]]])
    n, labels = _face_components(after, stays)
    assert n == 3 and len(np.unique(labels[np.searchsorted(stays, island)])) == 1  # the island is a piece
    assert 2 * 9 + 3 not in seam[:, 0]
    joined, mix = join_path_islands(after[stays], v2, seam)
    np.testing.assert_array_equal(joined, after[stays])
    assert mix == {}


@pytest.mark.system
def test_rows_mixed_move_a_vertex_by_its_anchors_displacements(builtin_rig):
    """On the built-in rig: a moving vertex given two anchors moves by their weighted displacements, a still one
    given a moving anchor joins the moving set and moves by that anchor's, every other vertex as before (the
    displacements taken from the old and new rigs' own ``deformed``)."""
    from assets.heads.rigging import with_rows_mixed

    rig, _ = builtin_rig
    p = np.array([0.01, 0.02, 0.35, -0.03])
    old = rig.deformed(p).astype(np.float64) - rig.neutral
    moved = np.flatnonzero(np.linalg.norm(old, axis=1) > 1e-3 * rig.meta["iod"])
    a, b, c = (int(x) for x in moved[[0, len(moved) // 2, -1]])
    still = int(np.setdiff1d(np.arange(len(rig.neutral)), rig.moving)[0])
    new = with_rows_mixed(rig, {a: (np.array([b, c]), np.array([0.25, 0.75])), still: (np.array([c]), np.ones(1))})
    got = new.deformed(p).astype(np.float64) - new.neutral
    np.testing.assert_allclose(got[a], 0.25 * old[b] + 0.75 * old[c], atol=1e-6)
    np.testing.assert_allclose(got[still], old[c], atol=1e-6)
    assert np.linalg.norm(old[b] - old[c]) > 1e-3 * rig.meta["iod"]  # the mix means something
    rest = np.setdiff1d(np.arange(len(rig.neutral)), [a, still])
    np.testing.assert_allclose(got[rest], old[rest], atol=1e-6)
    assert still in new.moving


def test_the_walls_removal_leaves_no_small_hole_in_a_surface_that_stays():
    """:func:`inner_lip_faces` removes the faces whose three vertices are hidden walls, but a piece of at most
    WALL_HOLE_FACES such faces with a face that stays across each of its edges is a hole it would punch in a
    surface that stays (Lee Perry-Smith's upper lip on the lip line): it stays. A larger piece, or one at the
    mesh's free edge, goes. Holes counted from the boundary edges (edges of one face) of what stays."""
    from assets.heads.rigging import WALL_HOLE_FACES, inner_lip_faces

    cols = rows = 9
    t = _grid_triangles(rows, cols)

    def cell_vertices(j: int, i: int) -> list[int]:
        return [j * cols + i, j * cols + i + 1, (j + 1) * cols + i, (j + 1) * cols + i + 1]

    def boundary_edges(tri: np.ndarray) -> int:
        e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        return int((np.unique(e, axis=0, return_counts=True)[1] == 1).sum())

    hole = cell_vertices(2, 2)  # one cell, two faces, inside the grid
    big = sorted({x for j in (4, 5, 6) for i in (4, 5, 6) for x in cell_vertices(j, i)})  # nine cells
    edge = cell_vertices(0, 7)  # a cell on the grid's border
    assert 2 <= WALL_HOLE_FACES < 18
    hole_faces = np.flatnonzero(np.isin(t, hole).all(axis=1))
    big_faces = np.flatnonzero(np.isin(t, big).all(axis=1))
    edge_faces = np.flatnonzero(np.isin(t, edge).all(axis=1))
    assert len(hole_faces) == 2 and len(big_faces) == 18 and len(edge_faces) == 2
    gone = inner_lip_faces(t, rows * cols, np.array(hole + big + edge))
    assert not gone[hole_faces].any() and gone[big_faces].all() and gone[edge_faces].all()
    # The hole's vertices change nothing: no boundary appears round it.
    without_hole = inner_lip_faces(t, rows * cols, np.array(big + edge))
    np.testing.assert_array_equal(gone, without_hole)
    assert boundary_edges(t[~gone]) > boundary_edges(t)  # (the big piece's rim and the border notch)
    assert not inner_lip_faces(t, rows * cols, np.array(hole)).any()
    # A coarse (knife-cut) mouth keeps no hole: every face of the inner vertices goes.
    coarse = inner_lip_faces(t, rows * cols, np.array(hole + big + edge), keep_holes=False)
    assert coarse[hole_faces].all() and coarse[big_faces].all() and coarse[edge_faces].all()


def test_a_thin_wedge_upper_lips_flat_underside_stays_with_the_upper_lip():
    """A decimated stylised mouth (the held-out stylised head): its lips are thin wedges that meet in a crease of flat
    faces, the upper lip's underside running straight back from the contact line (facing down) over the lower lip's
    top. The geodesic split seeds the lower side with every face below a path edge, so the underside went with the
    lower lip, which carried it down at /a/ facing away from the viewer (dark shards by the corner, lip backs seen
    4.55e-3 IOD^2). With ``underside`` (a knife-cut mouth) the faces facing down stay with the upper lip: none of
    them takes a copy, and the lower lip's top and the fronts keep their sides."""
    profile = [
        (0.5, 0.0),
        (0.25, 0.0),
        (0.1, 0.0),
        (0.0, 0.0),  # the contact line
        (0.0, -0.1),  # the upper lip's underside, flat: its faces face straight down
        (-0.05, -0.15),  # the crease's back
        (-0.02, -0.05),  # the lower lip's top, coming forward under the underside
        (-0.1, 0.0),
        (-0.25, 0.0),
        (-0.5, 0.0),
    ]
    v, t, left, right, _ = _creased_lips(profile=profile)
    cols = 17
    up = np.array([0, 1.0, 0])
    normal = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    row = t.min(axis=1) // cols  # the profile row each face starts at
    underside = row == 3
    inner = np.abs(v[t].mean(axis=1)[:, 0]) < 0.75  # away from the corners, where the crease fades
    assert (normal[underside & inner] @ up < -0.99).all()  # the mechanism's premise: they face straight down
    path = list(range(left, right + 1))

    def took_copies(**kw) -> np.ndarray:
        _, t2, _, _ = cut_mouth(v, t, left, right, up, path=path, **kw)
        return (t2 >= len(v)).any(axis=1)

    before = took_copies()
    assert before[underside & inner].all()  # the geodesic split alone: the underside goes with the lower lip
    after = took_copies(underside=True)
    assert not after[underside & inner].any()
    # The lips now part behind the underside: the crease's back takes the copies; the upper lip's front never does.
    assert after[(row == 4) & inner].all()
    assert not after[row < 3].any()


@pytest.mark.parametrize("height", [0.01, -0.01])
def test_a_vertex_touching_both_sides_inside_the_cut_joins_the_side_it_lies_on(height):
    """A vertex that touches both sides of the cut between its ends (on the stylised held-out head the upper lip's
    lining behind the cut, joined to both lips' crease faces) was taken for an end of the cut and pinned to the
    corner row, both lips' simple vertices: it went down with the jaw and the lining hung into the opening at /a/
    (dark shards). It joins the side it lies on: above the cut's line the upper lip's simple vertices only, below it
    the lower lip's (``hinges``, on knife-cut mouths). Here one path vertex of the cut creased lips is left whole (its
    copy merged back) and moved ``height`` off the cut's line; the mouth's corners stay ends."""
    from realtime_core.face.model import FaceFrame, FaceModel
    from realtime_core.face.rig import _seam_rows

    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    copies = np.arange(len(v), len(v2))
    seam = np.column_stack([origin[copies], copies])
    whole = int(np.argmin(np.abs(v2[seam[:, 0], 0])))  # the pair at the midline
    hinge, copy = seam[whole]
    t2 = np.where(t2 == copy, hinge, t2)
    seam = np.delete(seam, whole, axis=0)
    v2 = v2.copy()
    v2[hinge, 1] += height
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=3.0)
    spots = ([0.5, 0.25, 0.0], [0.0, 0.25, 0.0], [0.0, -0.25, 0.0])  # upper lip, upper lip, lower lip
    control = np.array([int(np.argmin(np.linalg.norm(v2 - p, axis=1))) for p in spots])
    simple = FaceModel(vertices=v2[control], triangles=np.array([[0, 1, 2]]), name="three points")
    lower = np.array([False, False, True])
    pin0, rows0, _ = _seam_rows(v2, t2, simple, frame, seam, lower, ~lower, control)
    assert rows0.toarray()[int(np.flatnonzero(pin0 == hinge)[0])][2] > 0.0  # without: an end, both lips' row
    pin, rows, _ = _seam_rows(v2, t2, simple, frame, seam, lower, ~lower, control, hinges=True)
    assert (pin == hinge).sum() == 1
    row = rows.toarray()[int(np.flatnonzero(pin == hinge)[0])]
    assert row.sum() == pytest.approx(1.0)
    if height > 0:
        assert row[2] == 0.0 and row[:2].sum() == pytest.approx(1.0)
    else:
        assert row[2] == pytest.approx(1.0)
    # The corners still follow both lips.
    for corner in (left, right):
        if (pin == corner).any():
            assert rows.toarray()[int(np.flatnonzero(pin == corner)[0])][2] > 0.0


def test_a_crease_end_short_of_the_corner_tapers_the_lower_side_only():
    """The stylised held-out head's cut stops 0.19 IOD short of its left corner, and a crease vertex behind the lips
    there (1289), joined to both sides mid-cut, is an end of the cut beyond the upper side's last vertex. The taper
    blended the upper side's last vertex (1294, 0.037 IOD from it) 63% into the corner row, both lips' simple
    vertices: it went down 0.14 IOD at /a/, a step in the upper lip's edge. With ``hinges`` (knife-cut mouths) the
    upper side tapers only into the corners, the ends touching its outermost pair; the lower side and the crease
    end keep their rows. Here the cut creased lips' outermost right pair is merged back (the cut stops a column short
    of the corner) and a crease vertex is joined to a mid-cut pair, 0.03 IOD beside the upper side's last vertex."""
    from realtime_core.face.model import FaceFrame, FaceModel
    from realtime_core.face.rig import SEAM_TAPER, _seam_rows

    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    copies = np.arange(len(v), len(v2))
    seam = np.column_stack([origin[copies], copies])
    seam = seam[np.argsort(v2[seam[:, 0], 0])]  # left to right
    corner_end = seam[-1, 0]  # the pair by the right corner: merged back, it is the cut's corner end now
    t2 = np.where(t2 == seam[-1, 1], corner_end, t2)
    seam = seam[:-1]
    x = v2[seam[:, 0], 0]
    last = len(seam) - 1  # the upper side's last pair
    at = int(np.argmin(np.abs(x - 0.25)))  # a pair mid-cut
    crease = len(v2)
    v2 = np.vstack([v2, [x[last] + 0.03, 0.01, -0.1]])
    t2 = np.vstack([t2, [[crease, seam[at, 0], seam[at - 1, 0]], [crease, seam[at - 1, 1], seam[at, 1]]]])
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=1.0)
    corner_gap = float(np.linalg.norm(v2[seam[last, 0], :2] - v2[corner_end, :2]))
    assert corner_gap > SEAM_TAPER  # the premise: the upper side's last vertex is out of the corner's taper
    spots = ([0.5, 0.25, 0.0], [0.0, 0.25, 0.0], [0.0, -0.25, 0.0])  # upper lip, upper lip, lower lip
    control = np.array([int(np.argmin(np.linalg.norm(v2 - p, axis=1))) for p in spots])
    simple = FaceModel(vertices=v2[control], triangles=np.array([[0, 1, 2]]), name="three points")
    lower = np.array([False, False, True])

    def row_of(pin: np.ndarray, rows, vertex: int) -> np.ndarray:
        assert (pin == vertex).sum() == 1
        return rows.toarray()[int(np.flatnonzero(pin == vertex)[0])]

    pin, rows, _ = _seam_rows(v2, t2, simple, frame, seam, lower, ~lower, control, hinges=True)
    up, lo = row_of(pin, rows, seam[last, 0]), row_of(pin, rows, seam[last, 1])
    assert up.sum() == pytest.approx(1.0) and lo.sum() == pytest.approx(1.0)
    assert up[2] == 0.0  # the upper side's last vertex follows the upper lip alone (the taper mixed the lower lip in)
    # The lower side's last vertex: blended into the corner row (inverse-square weights of all three simple vertices,
    # frontal plane) by its distance to the crease end, the rest the lower lip's.
    p = v2[seam[last, 1], :2]
    blend = 1.0 - np.linalg.norm(p - v2[crease, :2]) / SEAM_TAPER
    w = 1.0 / np.linalg.norm(v2[control, :2] - p, axis=1) ** 2
    np.testing.assert_allclose(lo, blend * w / w.sum() + (1.0 - blend) * np.array([0.0, 0.0, 1.0]), atol=1e-9)
    assert 0.6 < blend < 0.7
    end = row_of(pin, rows, crease)
    assert end[:2].sum() > 0.0 and end[2] > 0.0  # the crease vertex is still an end, both lips' row
    # Without ``hinges`` (the full scans) both sides taper into every end, as before.
    pin0, rows0, _ = _seam_rows(v2, t2, simple, frame, seam, lower, ~lower, control)
    assert row_of(pin0, rows0, seam[last, 0])[2] > 0.0


def _lower_edge_on_the_lip():
    """A knife-cut mouth whose cut's lower side is another layer lying on the lower lip (the stylised held-out head:
    the knife's path runs through the upper lip's overhang). Columns x = -1..1 (9); the upper lip rows y = 0, 0.1, 0.2
    (z = 0), its bottom row the cut's upper side; the cut's lower side (copies of that row's 7 inner vertices) and a
    row 0.03 behind and 0.005 below it, the overhang's underside; the lower lip's own surface rows y = -0.02, -0.08,
    -0.14 at z = -0.01, joined to the rest only at the corners (the upper row's end vertices). Returns vertices,
    triangles and the seam's (upper, lower) pairs."""
    xs = np.linspace(-1.0, 1.0, 9)
    v = [[x, y, 0.0] for y in (0.0, 0.1, 0.2) for x in xs]  # upper lip: row r, column i at 9 r + i

    def add(points):
        v.extend(points)
        return list(range(len(v) - len(points), len(v)))

    lower = add([[x, 0.0, 0.0] for x in xs[1:-1]])
    under = add([[x, -0.005, -0.03] for x in xs[1:-1]])
    lip = [add([[x, y, -0.01] for x in xs[1:-1]]) for y in (-0.02, -0.08, -0.14)]
    t = [[9 * r + i, 9 * (r + 1) + i + 1, 9 * r + i + 1] for r in range(2) for i in range(8)]
    t += [[9 * r + i, 9 * (r + 1) + i, 9 * (r + 1) + i + 1] for r in range(2) for i in range(8)]
    edge = [0, *lower, 8]  # the lower side between the corners
    back = [0, *under, 8]
    t += [[edge[i], edge[i + 1], back[i + 1]] for i in range(8)] + [[edge[i], back[i + 1], back[i]] for i in range(8)]
    for a, b in itertools.pairwise(lip):
        t += [[a[i], a[i + 1], b[i + 1]] for i in range(6)] + [[a[i], b[i + 1], b[i]] for i in range(6)]
    t += [[0, lip[0][0], back[1]], [8, back[7], lip[0][6]]]  # the lip joins the rest round the corners only
    return np.array(v, dtype=np.float64), np.array(t), np.column_stack([np.arange(1, 8), lower])


def test_a_knife_cut_lower_edge_lying_on_the_lower_lip_moves_with_it():
    """The stylised held-out head's cut lower side is a strip of the upper lip's overhang lying 0.02-0.06 IOD on the
    lower lip, joined to it only round the corners. Pinned to the simple face's lower lip it dropped up to 0.08 IOD more
    than that lip at /a/ and its down-facing faces turned to the viewer: a light strip with a dark line under it
    across the lip, a flap at a corner. Each vertex of such a side moves, through the fold repair, as the point of the
    lower lip's surface nearest it (:func:`assets.heads.rigging.lip_edge_glue`, the repair's face ties); a cut whose
    lower side is the lip's own surface (the creased lips, the decimated scans) is left as it was."""
    import scipy.sparse as sp

    from assets.heads.rigging import LIP_GLUE, lip_edge_glue
    from realtime_core.face.model import FaceFrame
    from realtime_core.face.repair import repair_folds

    v, t, seam = _lower_edge_on_the_lip()
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=1.0)
    glue = lip_edge_glue(v, t, seam, frame)
    assert sorted(glue) == sorted(seam[:, 1].tolist())
    for i, (anchors, w) in glue.items():
        assert min(w) >= 0.0 and sum(w) == pytest.approx(1.0)
        point = np.asarray(w) @ v[list(anchors)]
        # The lip sheet lies in z = -0.01 between y = -0.14 and -0.02: its point nearest (x, 0, 0) is its top edge's.
        np.testing.assert_allclose(point, [v[i, 0], -0.02, -0.01], atol=1e-9)
        assert np.linalg.norm(point - v[i]) <= LIP_GLUE
    # The repair with those ties: the lower side (pinned 1.3 of the lower lip's drop, as the simple face's lower lip
    # dropped more than the surface under it) moves as its glue point; without them it keeps its own drop.
    n = len(v)
    lip_rows = v[:, 1] < -0.01
    g = np.zeros((n, 2))
    g[v[:, 1] >= 0.0, 0] = 1.0
    g[lip_rows, 1] = 1.0
    g[seam[:, 1]] = g[np.isclose(v[:, 1], -0.005)] = [0.0, 1.3]
    motions = np.array([[[0.0, 0.0, 0.0], [0.0, -0.1, 0.0]]])
    moved = repair_folds(v, t, sp.csr_matrix(g), motions).weights @ motions[0]
    assert (moved[seam[:, 1], 1] < -0.11).all()
    moved = repair_folds(v, t, sp.csr_matrix(g), motions, ties=glue).weights @ motions[0]
    np.testing.assert_allclose(moved[seam[:, 1], 1], -0.1, atol=1e-9)
    # Creased lips cut open: the lower side is the lower lip's own surface, no other layer under it.
    v, t, left, right, mid = _creased_lips()
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    copies = np.arange(len(v), len(v2))
    assert lip_edge_glue(v2, t2, np.column_stack([origin[copies], copies]), frame) == {}
    # A cut that split no vertex (the 1,428-triangle copy with its mouth jittered by 0.002 IOD): no side to glue
    # (np.interp raised "array of sample points is empty" out of `facecast rig`).
    assert lip_edge_glue(v2, t2, np.zeros((0, 2), dtype=np.int64), frame) == {}


def test_a_fin_seen_from_the_front_stays_and_faces_seen_are_told_by_depth():
    """The fin rule of :func:`inner_lip_faces` (a face with two hidden vertices joined to what stays by one edge) keeps
    the faces ``seen`` from the front at rest: on the 3,810-triangle Lee Perry-Smith copy cut at the lips' meeting,
    the lower lip's top by the corner joined its side by one edge with two vertices under the upper lip's overhang,
    and removed it left a dark gap along the lips at rest. :func:`faces_seen`: of two planes one behind the other, the
    back one's faces under the front one are hidden, those beside it seen."""
    from assets.heads.rigging import faces_seen, inner_lip_faces
    from realtime_core.face.model import FaceFrame

    cols = rows = 9
    t = _grid_triangles(rows, cols)
    # Rows 0 and 1, columns 2..6 hidden: the cells between them go; the cells beside them on the grid's border
    # keep two hidden vertices and are joined to the rest by one edge: fins.
    inner = np.array([j * cols + i for j in (0, 1) for i in range(2, 7)])
    n_in = np.isin(t, inner).sum(axis=1)
    gone = inner_lip_faces(t, rows * cols, inner, keep_holes=False)
    fins = gone & (n_in < 3)
    assert fins.any() and gone[n_in == 3].all()
    kept = inner_lip_faces(t, rows * cols, inner, keep_holes=False, seen=fins)
    assert not kept[fins].any() and kept[n_in == 3].all()
    np.testing.assert_array_equal(kept, gone & ~fins)

    back = np.array([[x, y, 0.0] for y in (0.0, 1.0) for x in (0.0, 1.0, 2.0)])
    front = np.array([[-0.1, -0.1, 0.1], [1.05, -0.1, 0.1], [1.05, 1.1, 0.1], [-0.1, 1.1, 0.1]])  # the left half
    v = np.vstack([back, front])
    tri = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [6, 7, 8], [6, 8, 9]])
    frame = FaceFrame(origin=np.zeros(3), axes=np.eye(3), iod=1.0)
    seen = faces_seen(v, tri, frame, np.ones(len(tri), dtype=bool))
    np.testing.assert_array_equal(seen, [False, False, True, True, True, True])
    assert not faces_seen(v, tri, frame, np.array([True, True, False, False, False, False])).any()


def _two_charts(v: np.ndarray, t: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mesh as a scanner writes it in two texture charts (menpo3d's james.obj): the faces ``right`` (m,) bool take
    copies of all their vertices (appended), each copy its chart's texture coordinate (u in [0.5, 1) against the
    first copies' [0, 0.5)), so the vertices both halves use are texture-seam copies. Returns vertices (2n, 3),
    triangles, uvs (2n, 2)."""
    n = len(v)
    uv = np.c_[0.25 + 0.2 * v[:, 0], 0.5 + 0.4 * v[:, 1]]
    return np.vstack([v, v]), np.where(right[:, None], t + n, t), np.vstack([uv, uv + np.array([0.5, 0.0])])


def test_a_texture_seam_through_the_lips_is_seen_through_for_the_cut():
    """Closed lips split down the middle into two texture charts: the corners lie on two pieces that only the seam's
        coincident copies join, so the cut found no path (the james.obj scan: "mouth corners are not connected").
        :func:`seam_welded` gives each vertex its first copy: the welded triangles are the unsplit mesh's, and the cut's
        path over them runs from corner to corner; so where the halves join round the seam's end and the path went round
    it. A mesh whose path crosses no seam is left alone."""
    from assets.errors import MeshError
    from assets.heads.rigging import cut_path, seam_welded

    v, t, left, right, mid = _creased_lips()
    assert seam_welded(v, t, left, right) is None
    v2, t2, _ = _two_charts(v, t, v[t].mean(axis=1)[:, 0] > 0.0)
    right2 = right + len(v)  # the right corner's copy, the one the right half's faces use
    with pytest.raises(MeshError, match="not connected"):
        cut_path(v2, t2, left, right2, through=mid)
    first = seam_welded(v2, t2, left, right2)
    assert first is not None
    np.testing.assert_array_equal(v2[first], v2)
    np.testing.assert_array_equal(first[t2], t)
    assert first[right2] == right
    assert cut_path(v2, first[t2], left, right, through=mid) == cut_path(v, t, left, right, through=mid)
    # Two pieces apart in space too (no coincident copy joins them): still no path, as before.
    apart = v2.copy()
    apart[len(v) :, 2] += 1.0
    assert seam_welded(apart, t2, left, right2) is None
    # The halves joined round the seam's end (the top row of faces left whole): the path as loaded goes up round it,
    # off the lip line; across the seam it is the unsplit mesh's.
    top = v[t].mean(axis=1)[:, 1] > 0.3
    v3, t3, _ = _two_charts(v, t, v[t].mean(axis=1)[:, 0] > 0.0)
    t3[top] = np.where(v[t[top], 0] == 0.0, t[top], t3[top])  # the midline's vertices there one copy
    right3 = right + len(v)
    assert np.abs(v3[cut_path(v3, t3, left, right3), 1]).max() >= 0.25  # up to the joined row
    first = seam_welded(v3, t3, left, right3)
    assert first is not None
    assert cut_path(v3, first[t3], left, right, through=mid) == cut_path(v, t, left, right, through=mid)
