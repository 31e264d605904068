"""Automatic landmarks: MediaPipe on an offscreen render, cast back onto the mesh."""

from __future__ import annotations

import contextlib
import io
import json
import shutil

import numpy as np
import pytest

from assets.heads.landmarks import shipped_landmarks
from assets.heads.mesh import load_mesh
from clients.render.landmarks import find_landmarks
from facecast.cli import main

# Offscreen OpenGL renders and MediaPipe on real heads.
pytestmark = [pytest.mark.system, pytest.mark.slow]


@pytest.mark.parametrize("colour_map", [True, False], ids=["textured", "untextured"])
def test_automatic_landmarks_agree_with_the_hand_picked_ones(shared_data, tmp_path, colour_map):
    """On Lee Perry-Smith as shipped (its colour map beside it) and on a copy of the .glb alone (rendered
    in its material's flat colour): a user's scan may well come without a texture."""
    lps = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    if colour_map:
        mesh = load_mesh(lps)
        assert mesh.texture is not None
    else:
        shutil.copy(lps, tmp_path / "someone.glb")
        mesh = load_mesh(tmp_path / "someone.glb")
        assert mesh.texture is None
    auto = find_landmarks(mesh)
    ref = json.loads(shipped_landmarks(lps).read_text())["landmarks"]
    v = mesh.vertices
    iod = np.linalg.norm(
        0.5 * (v[ref["eye_outer_left"]] + v[ref["eye_inner_left"]])
        - 0.5 * (v[ref["eye_outer_right"]] + v[ref["eye_inner_right"]])
    )
    err = {k: float(np.linalg.norm(np.asarray(p) - v[ref[k]]) / iod) for k, p in auto.items()}
    assert max(err.values()) < 0.2, err  # hand picks and MediaPipe differ by a few vertices
    assert np.mean(list(err.values())) < 0.1, err


@pytest.fixture(scope="module")
def automatic_rig(shared_data, tmp_path_factory):
    """Lee Perry-Smith's .glb alone (without its colour map: the harder case, its render's inner-lip points
    land on the two walls of the crease between the closed lips) under a name nobody shipped landmarks
    for, rigged by ``facecast rig`` as a user would (automatic landmarks; :func:`assets.heads.head.rig_checked`,
    its first rig failing, rigs it twice): ``(stderr, the Head read back from the rig file)``. Built once
    for the module: rigging it takes minutes, and CI time is budgeted (the textured copy's landmarks are
    checked above; its rig is in the head test set, docs/animation.md)."""
    from assets.heads.head import Head
    from assets.heads.rigfile import load_rig

    tmp = tmp_path_factory.mktemp("automatic_rig")
    head = tmp / "someone.glb"
    lps = shared_data / "heads" / "lee-perry-smith"
    shutil.copy(lps / "LeePerrySmith.glb", head)  # no Map-COL.jpg beside it: rendered untextured
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["rig", str(head), "-o", str(tmp / "r.npz"), "--keep-failing"])
    assert rc == 0 and (tmp / "r.npz").is_file(), err.getvalue()
    rig, mesh = load_rig(tmp / "r.npz")
    return err.getvalue(), Head(rig, mesh)


def test_a_human_like_head_rigs_with_no_manual_landmark(automatic_rig):
    assert "automatic landmarks" not in automatic_rig[0]
    assert automatic_rig[1].mesh.texture is None


def test_untextured_closed_lips_are_seen_closed_and_cut(automatic_rig, shared_data):
    """Without the colour map the render's inner-lip points straddle the crease (upper lip's underside,
    lower lip's top: 24 edges apart); the lips still read as closed, so the seam is cut from the front of
    their contact: the hand-picked inner-lip vertex."""
    meta = automatic_rig[1].rig.meta
    ref = json.loads(shipped_landmarks(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb").read_text())
    assert meta.get("lip_seam_cut", 0) > 5, meta.get("lip_seam_cut")
    assert meta.get("inner_lip_contact") == ref["landmarks"]["lower_inner"], meta.get("inner_lip_contact")


def test_automatic_landmarks_do_not_over_open_the_jaw(automatic_rig):
    """Automatic inner-lip points sit a few hundredths of an IOD off the hand ones and read a small
    lip response; dividing the mouth-open column by it opened the jaw 2.65x (152 flipped triangles,
    a long face at /a/). The rescale must stay bounded and the rig must not fold like that at any
    open pose the shipped models produce."""
    from assets.heads.head import head_checks
    from assets.heads.rigging import OPEN_RESPONSE_RANGE
    from realtime_core.face.checks import EXTREME_POSES

    head = automatic_rig[1]
    rig = head.rig
    assert rig.meta.get("open_rescaled", 1.0) <= 1.0 / OPEN_RESPONSE_RANGE[0] + 1e-3, rig.meta
    open_poses = tuple(p for p in EXTREME_POSES if p[2] >= 0.05)
    assert len(open_poses) >= 40  # most of the checked poses open the mouth
    rep = head_checks(head, poses=open_poses)
    # 152 flips and stretch 30.7 with the unbounded rescale; 33 and 8.1 with the cut started inside the
    # crease between the lips (the automatic inner-lip points, before front_contact moved them to its front).
    # Bounded here well below both failures above, so a jaw that over-opens again still fails (the full
    # checks, stretch <= 4, are the next test's).
    assert rep.flipped_triangles == 0 and rep.max_edge_stretch < 6.0, rep
    assert rep.lip_interpenetration_iod <= 0.005 and rep.closure_gap_iod <= 0.01, rep


def test_the_automatic_landmark_rig_passes_every_check(automatic_rig, tmp_path):
    """Every check at every measured pose, on the rig ``facecast rig`` wrote, as read back from its file
    and after another save and load. RIG_ALGORITHM 21: 1 flipped triangle at closed lips with the corners
    up (the lip-contact push was spread over the crease walls removed afterwards; a rig file dropped the
    spread altogether) and one edge by the right corner stretched 5.26x at the widest opening; 22: 0 flips,
    4.63; 23: the fold repair on the final mesh, chosen as the first rig fails, 0 flips, 3.41 (all three
    with its colour map; docs/animation.md, test set). Without it: RIG_ALGORITHM 24, the lips cut from the
    same front contact, 0 flips, 2.77 (before, its lips were never cut: 13 flips at mouth_open 0.465,
    stretch 13.8); 25: clean lips tried first (docs/animation.md, "Clean lips")."""
    from assets.heads.head import Head, head_checks
    from assets.heads.rigfile import load_rig, save_rig

    head = automatic_rig[1]
    assert head.rig.contact_spread is not None
    assert head.rig.meta.get("clean_lips"), head.rig.meta.get("rig_attempts")
    rep = head_checks(head)
    assert rep.passed, rep
    rig, mesh = load_rig(save_rig(head.rig, head.mesh, tmp_path / "r.npz"))
    rep = head_checks(Head(rig, mesh))
    assert rep.passed, rep


def test_automatic_inner_lip_points_move_to_the_front_of_the_lips_contact(shared_data):
    """On Lee Perry-Smith's closed lips the automatic inner-lip points land inside the crease (0.03 IOD up
    its lower wall); rigging moves both to the one vertex at the crease's front, the hand-picked one."""
    from assets.heads.rigging import CONTACT_REACH, front_contact, mouth_landmarks, resolve_landmarks
    from realtime_core.face import face_frame

    lps = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    mesh = load_mesh(lps)
    v = mesh.vertices
    ref = json.loads(shipped_landmarks(lps).read_text())["landmarks"]
    auto = resolve_landmarks(find_landmarks(mesh), v, "automatic")
    snap = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in auto.items()}
    frame = face_frame(v, mouth_landmarks(snap))
    assert snap["lower_inner"] != ref["lower_inner"]  # the render's point: inside the crease
    got = front_contact(v, mesh.triangles, snap["lower_inner"], frame.axes[2], reach=CONTACT_REACH * frame.iod)
    assert got == ref["lower_inner"]


def test_a_head_wound_the_other_way_round_gets_the_same_landmarks(shared_data):
    """Lee Perry-Smith with every triangle reversed (a mirrored export's winding) renders with its back faces
    towards the camera, which the renderer draws dark: MediaPipe's points on that render landed elsewhere (a
    nose tip 0.12 IOD off, the lips 0.02-0.03 IOD) and the rig failed. The render is wound to face the camera
    first (:func:`facing_viewer`), so the points found equal those of the head as shipped, to the bit."""
    from dataclasses import replace

    from clients.render.landmarks import ORIENTATIONS, _axes, facing_viewer

    mesh = load_mesh(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    reversed_ = replace(mesh, triangles=np.ascontiguousarray(mesh.triangles[:, ::-1]))
    up, fwd = ORIENTATIONS[0]
    axes = _axes(np.array(up, float), np.array(fwd, float))
    assert facing_viewer(mesh, axes) is mesh
    np.testing.assert_array_equal(facing_viewer(reversed_, axes).triangles, mesh.triangles)
    assert find_landmarks(reversed_) == find_landmarks(mesh)


def test_a_head_whose_colours_hide_its_face_is_found_by_its_shape(shared_data):
    """Lee Perry-Smith painted green all over (an orc's skin; menpo3d's template.ply, a face painted by position in
    rainbow hues, alike): MediaPipe finds no face on any render of it as painted, so the search looks again at its
    shape drawn as plain skin and finds the points of the head without its colours, to the bit."""
    from dataclasses import replace

    from clients.render.landmarks import _face_pieces, _searched

    mesh = load_mesh(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    plain = replace(mesh, texture=None, uvs=None)
    green = replace(plain, colors=np.tile(np.float32([0.1, 0.9, 0.1]), (len(mesh.vertices), 1)))
    assert _searched(green, _face_pieces(green)) is None
    assert find_landmarks(green) == find_landmarks(plain)


def test_a_head_and_its_mirror_image_get_mirrored_landmarks(shared_data, tmp_path):
    """The untextured Lee Perry-Smith (the .glb alone) mirrored left to right: MediaPipe's points on one render of it
    and on one of the head lay up to 0.046 IOD apart once mirrored back (the inner lips; the corners 0.03-0.04), and
    its rig failed (44 flips) where the head's passed. The first alternative set's render is lit mirror-symmetrically
    and its points are the median of MediaPipe's on several views of it and their mirror images: within 0.015 IOD
    (measured 0.008). The found set is the one studio-lit render's, as before; each alternative differs from it."""
    import shutil
    from dataclasses import replace

    shutil.copy(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb", tmp_path / "someone.glb")
    mesh = load_mesh(tmp_path / "someone.glb")
    assert mesh.texture is None
    found = find_landmarks(mesh)
    p = {k: np.asarray(x) for k, x in found.alternatives[0].items()}
    centre = 0.5 * (p["corner_left"] + p["corner_right"])
    v = np.array(mesh.vertices, dtype=np.float64)
    v[:, 0] = 2.0 * centre[0] - v[:, 0]
    mirrored = replace(mesh, vertices=v, triangles=np.ascontiguousarray(mesh.triangles[:, ::-1]))
    swap = {"left": "right", "right": "left"}

    def mirrored_back(points):
        # The mirrored head's points mirrored back, left and right swapped: the head's own points if the finder is
        # indifferent to the mirror.
        back = {}
        for k, x in points.items():
            side = k.rsplit("_", 1)[-1]
            q = np.asarray(x, dtype=np.float64)
            name = k.rsplit("_", 1)[0] + "_" + swap[side] if side in swap else k
            back[name] = np.array([2 * centre[0] - q[0], *q[1:]])
        return back

    found_mirrored = find_landmarks(mirrored)
    eyes = [0.5 * (p[f"eye_outer_{s}"] + p[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    back = mirrored_back(found_mirrored.alternatives[0])
    off = {k: float(np.linalg.norm(back[k] - p[k])) / iod for k in p}
    assert max(off.values()) < 0.015, off
    # The steady set is steadier than the one studio-lit render's (the found set), which the mirror moves by more.
    plain = {k: np.asarray(x, dtype=np.float64) for k, x in found.items()}
    plain_back = mirrored_back(found_mirrored)
    plain_off = {k: float(np.linalg.norm(plain_back[k] - plain[k])) / iod for k in plain}
    assert max(plain_off.values()) > 2 * max(off.values()), (plain_off, off)
    assert all(set(a) == set(found) and a != dict(found) for a in found.alternatives)


def test_a_head_turned_in_its_file_gets_the_landmarks_of_the_straight_head(shared_data):
    """Lee Perry-Smith turned 25 degrees (yaw) and 10 (pitch) and moved, baked into its positions (as a scan
    exported off-axis): MediaPipe found the turned face on the file-axis render, and its points, cast back along
    that axis, lay up to 0.11 IOD (the far eye's outer corner, the chin) from those of the straight file, moved
    and turned the same way. A turned eye line is now looked at straight (yaw and roll): within 0.06 IOD (the
    10 degrees of pitch are kept); a straight file keeps its render."""
    from dataclasses import replace

    mesh = load_mesh(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    yaw, pitch = np.radians(25.0), np.radians(10.0)
    ry = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    rx = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    rot, offset = ry @ rx, np.array([3.0, -4.0, 2.0])
    turned = replace(mesh, vertices=mesh.vertices @ rot.T + offset)
    straight = {k: np.asarray(p) for k, p in find_landmarks(mesh).items()}
    back = {k: (np.asarray(p) - offset) @ rot for k, p in find_landmarks(turned).items()}
    eyes = [0.5 * (straight[f"eye_outer_{s}"] + straight[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    off = {k: float(np.linalg.norm(back[k] - straight[k])) / iod for k in straight}
    assert max(off.values()) < 0.06, off
    assert max(off[k] for k in straight if k.startswith("eye_")) < 0.03, off


def test_mouth_corners_of_lips_parted_at_rest_are_found_on_the_lips(shared_data):
    """Lee Perry-Smith with its lips parted at rest, as many scans are: its own rig at mouth_open 0.1 IOD (the lips
    cut apart), with no mouth inside (the rig's cavity left out), so the opening shows the inside of the hollow
    head. MediaPipe puts a mouth corner at the opening's end; cast there, its pixel showed the inside of the head
    (here the left corner 0.13 IOD from the straight head's; in the held-out glb the right one 0.6 IOD, below the
    mouth). A corner cast through the lips is now looked for outwards along the mouth: both lie within 0.1 IOD of
    the straight head's corners (the parted rest moved them 0.06-0.08 IOD)."""
    from assets.heads.head import resolve_head
    from assets.heads.mesh import HeadMesh

    lps = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    head = resolve_head(lps)
    v = head.rig.deformed(np.array([0.0, 0.0, 0.1, 0.0])).astype(np.float64)
    keep = head.mesh.part != list(head.mesh.part_names).index("mouth cavity")
    t = head.mesh.triangles[keep[head.mesh.triangles].all(axis=1)]
    parted = HeadMesh(
        vertices=v[keep], triangles=(np.cumsum(keep) - 1)[t], uvs=head.mesh.uvs[keep], texture=head.mesh.texture
    )
    straight = {k: np.asarray(p) for k, p in find_landmarks(load_mesh(lps)).items()}
    found = {k: np.asarray(p) for k, p in find_landmarks(parted).items()}
    eyes = [0.5 * (straight[f"eye_outer_{s}"] + straight[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    for k in ("corner_left", "corner_right"):
        assert np.linalg.norm(found[k] - straight[k]) / iod < 0.1, k


def test_inner_lip_points_of_lips_modelled_apart_lie_on_the_lips_not_the_teeth(tmp_path):
    """The built-in head (its teeth in the same file, separate pieces of it) with 0.1 of its jawOpen baked into the
    mesh: the lips modelled 0.06 IOD apart show the teeth between them, only 0.085 IOD behind the lips' front, and the
    upper inner-lip point was cast onto an upper tooth (an upper-lip raise then "crossed the lips" by 0.022 IOD). Both
    inner-lip points now lie on the skin, each on the lip it belongs to: the upper one above the lower one, and
    each within 0.05 IOD of the hand-placed landmark on that lip moved with the jaw."""
    from assets.heads.glb import mesh_glb
    from assets.heads.head import builtin_morph_head
    from assets.heads.mesh import HeadMesh

    head = builtin_morph_head()
    b = head.mesh
    v0 = np.asarray(b.vertices, dtype=np.float64)
    marks = head.rig.meta["landmarks"]
    hand = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in marks.items()}
    path = tmp_path / "parted.glb"  # as a user's file (drawn from the file, the pixel fell on a tooth)
    path.write_bytes(
        mesh_glb(HeadMesh(vertices=v0 + 0.1 * b.targets["jawOpen"], triangles=b.triangles, colors=b.colors, name="p"))
    )
    parted = load_mesh(path)
    found = {k: np.asarray(p, dtype=np.float64) for k, p in find_landmarks(parted).items()}
    v = np.asarray(parted.vertices, dtype=np.float64)
    skin = np.asarray(b.part) == list(b.part_names).index("skin")
    eyes = [0.5 * (v[hand[f"eye_outer_{s}"]] + v[hand[f"eye_inner_{s}"]]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    for k in ("upper_inner", "lower_inner"):
        nearest = int(np.argmin(np.linalg.norm(v - found[k], axis=1)))
        assert skin[nearest], (k, nearest)
        assert np.linalg.norm(found[k] - v[hand[k]]) / iod < 0.05, k
    up = v[hand["upper_lip"]] - v[hand["chin"]]
    assert (found["upper_inner"] - found["lower_inner"]) @ up > 0


# The vertices nearest each automatic landmark (the found set, then its alternatives) as found before the mesh's pieces
# were welded once per search (they were welded again for each of its landmark sets: 0.25 s a time on Lee Perry-Smith
# subdivided twice, 143k vertices).
NEAREST = {
    "builtin": [
        [2243, 3571, 1054, 73, 302, 2724, 544, 466, 496, 474, 493, 1593],
        [2245, 2294, 24, 73, 302, 2724, 544, 467, 496, 474, 493, 1593],
        [3554, 2294, 1428, 73, 307, 3504, 1375, 467, 496, 493, 494, 1593],
        [3556, 2295, 1427, 73, 307, 3531, 1375, 467, 496, 523, 494, 1593],
    ],
    "lee-perry-smith": [
        [420, 827, 5627, 5299, 2835, 2582, 7257, 2539, 2920, 2884, 2884, 7338],
        [420, 827, 5627, 5530, 2835, 2716, 7259, 2540, 2920, 2461, 2884, 7338],
        [420, 828, 5627, 5299, 2835, 2714, 7258, 2539, 2920, 2882, 2884, 7338],
        [418, 884, 5627, 5530, 7500, 2717, 7245, 2540, 7563, 2467, 7534, 7338],
    ],
}


@pytest.mark.parametrize("name", list(NEAREST))
def test_the_automatic_landmarks_stay_on_their_vertices(name, shared_data, builtin_head):
    """The built-in head and Lee Perry-Smith (textured): every landmark set found lies nearest the vertices it did."""
    from clients.render.landmarks import MEDIAPIPE_INDEX

    if name == "builtin":
        mesh = builtin_head.mesh
    else:
        mesh = load_mesh(shared_data / "heads" / name / "LeePerrySmith.glb")
    found = find_landmarks(mesh)
    v = np.asarray(mesh.vertices)
    nearest = [
        [int(np.argmin(np.linalg.norm(v - np.asarray(s[k]), axis=1))) for k in MEDIAPIPE_INDEX]
        for s in (found.points, *found.alternatives)
    ]
    assert nearest == NEAREST[name]


def test_a_meshs_pieces_are_those_of_every_mesh_its_landmark_search_draws(builtin_head):
    """The welded pieces are computed once per search (:func:`_face_pieces`) and used for every render's mesh: the
    search draws the file's triangles, rewound (:func:`facing_viewer`) or without colours, never reordered. (The
    built-in head: its face, teeth, tongue and eyes are pieces of their own.)"""
    from dataclasses import replace

    from clients.render.landmarks import ORIENTATIONS, _axes, _face_pieces, facing_viewer

    mesh = builtin_head.mesh
    pieces = _face_pieces(mesh)
    assert len(pieces) == len(mesh.triangles) and len(set(pieces.tolist())) == 6
    reversed_ = replace(mesh, triangles=np.ascontiguousarray(mesh.triangles[:, ::-1]), texture=None, uvs=None)
    for up, fwd in ORIENTATIONS:
        drawn = facing_viewer(reversed_, _axes(np.array(up, float), np.array(fwd, float)))
        np.testing.assert_array_equal(_face_pieces(drawn), pieces)
