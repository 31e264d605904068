"""Cutting closed lips open (:func:`assets.heads.rigging.cut_mouth`) and the harmonic field with the
cut's two sides pinned to their own lips, on synthetic meshes (no head files needed)."""

from __future__ import annotations

import numpy as np
import pytest

from assets.heads.rigging import cut_mouth


def _creased_lips(depth: float = 0.1):
    """A closed mouth whose lips meet in a crease, as scanned heads have it: the profile runs down the
    upper lip to the contact line (y = 0, z = 0), back into a crease behind it (slightly above the
    contact line), and out again down the lower lip; 17 columns from x = -1 to 1, corners at y = 0,
    the crease shallower towards them."""
    profile = [
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
    t = []
    for j in range(len(ys) - 1):
        for i in range(cols - 1):
            a = j * cols + i
            t += [[a, a + cols + 1, a + 1], [a, a + cols, a + cols + 1]]
    t = np.array(t)
    left, right = 3 * cols, 4 * cols - 1
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]))
    split = set(origin[len(v) :].tolist())
    interior = range(left + 1, right)
    assert not [int(p) for p in interior if p not in split]
    # Each copy is used only by faces that no longer use its original (the two sides really part).
    for c in range(len(v), len(v2)):
        faces_c = (t2 == c).any(axis=1)
        assert faces_c.any() and not (faces_c & (t2 == origin[c]).any(axis=1)).any()
