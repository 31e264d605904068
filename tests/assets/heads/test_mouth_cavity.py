"""Behind the lips: a lip membrane opened (the MediaPipe face's lips meet at closure), a dark mouth
cavity for heads whose mouth opens onto nothing (Candide-3, the MediaPipe face), none for heads with
an inner mouth, and a head without landmarks (a full-body avatar) framed on its face."""

from __future__ import annotations

import numpy as np
import pytest

from assets.heads.cavity import lip_membrane, opens_onto_nothing
from assets.heads.head import head_checks, resolve_head
from assets.heads.mesh import HeadMesh
from assets.heads.rigging import mouth_landmarks
from realtime_core.face import face_frame


def _two_lips_with_a_membrane():
    """Two lip rows (y = +0.1 upper inner edge, y = -0.1 lower inner edge) joined at shared corners,
    an outer row above and below, and a strip of triangles between the inner edges (the membrane)."""
    xs = np.linspace(-1, 1, 9)
    rows = {"top": 0.5, "upper": 0.1, "lower": -0.1, "bottom": -0.5}
    v, idx = [], {}
    for name, y in rows.items():
        for i, x in enumerate(xs):
            if name in ("upper", "lower") and i in (0, len(xs) - 1):
                continue  # the corners are shared, listed once below
            idx[name, i] = len(v)
            v.append([x, y, 0.3 * (1 - x * x)])
    for i in (0, len(xs) - 1):
        idx["upper", i] = idx["lower", i] = len(v)
        v.append([xs[i], 0.0, 0.0])

    def band(a, b):
        out = []
        for i in range(len(xs) - 1):
            p, q, r, s = idx[a, i], idx[a, i + 1], idx[b, i], idx[b, i + 1]
            out += [t for t in ([p, r, q], [q, r, s]) if len(set(t)) == 3]
        return out

    skin = band("top", "upper") + band("lower", "bottom")
    membrane = band("upper", "lower")
    t = np.array(skin + membrane)
    return np.array(v, float), t, idx, len(skin)


def test_lip_membrane_is_the_strip_between_the_inner_lips():
    v, t, idx, n_skin = _two_lips_with_a_membrane()
    m = lip_membrane(v, t, idx["upper", 0], idx["upper", 8], idx["upper", 4], idx["lower", 4])
    assert m.sum() == len(t) - n_skin and m[n_skin:].all() and not m[:n_skin].any()
    # A closed seam (one vertex for both inner lips) is no membrane: it is cut instead.
    assert not lip_membrane(v, t, idx["upper", 0], idx["upper", 8], idx["upper", 4], idx["upper", 4]).any()


@pytest.mark.slow
def test_mediapipe_lips_meet_at_closure_and_open_onto_a_cavity(shared_data):
    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    head = resolve_head(mp)
    rep = head_checks(head)
    assert rep.closure_gap_iod <= 0.01, rep.summary()
    assert rep.passed, rep.summary()
    assert head.rig.meta["lip_membrane_removed"] > 0 and "lip_seam_cut" not in head.rig.meta
    # Modelled 0.09 IOD apart, the lips touch at rest (mouth_open 0 = lips touching): silence, /m b p/.
    lm = head.rig.meta["landmarks"]
    v = np.asarray(head.rig.deformed(np.zeros(4)), float)
    near = {k: int(np.argmin(np.linalg.norm(v - np.asarray(p), axis=1))) for k, p in lm.items()}
    frame = face_frame(v, mouth_landmarks(near))
    assert abs((v[near["upper_inner"]] - v[near["lower_inner"]]) @ frame.axes[1]) / frame.iod <= 0.01
    assert head.mesh.part_names[-1] == "mouth cavity"


def _mouth_pixels(head, params, size=240):
    """The render at params and a mask of the pixels inside the mouth opening (between the deformed
    inner-lip landmarks, the middle third of the mouth's width)."""
    from clients.render.renderer import RenderConfig, renderer_for_rig

    lm = head.rig.meta["landmarks"]
    v = np.asarray(head.rig.deformed(np.asarray(params, float)), float)
    v0 = np.asarray(head.rig.neutral, float)
    near = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in lm.items()}
    with renderer_for_rig(head.rig, head.mesh, RenderConfig(width=size, height=size, samples=0)) as r:
        img = r.render(v).astype(float)
        corners = r.project(v[[near["corner_left"], near["corner_right"]]])
        # The inner lips: every vertex at either inner-lip point at rest (a closed seam has several).
        at = np.linalg.norm(v0[:, None] - v0[[near["upper_inner"], near["lower_inner"]]], axis=2).min(1) < 1e-9
        lips = r.project(v[at])
        background = np.asarray(r.config.background, float) * 255
    x0, x1 = sorted(corners[:, 0])
    y0, y1 = lips[:, 1].min(), lips[:, 1].max()
    assert y1 - y0 > 8, "the mouth did not open"
    cols = slice(int(x0 + (x1 - x0) / 3), int(x1 - (x1 - x0) / 3))
    rows = slice(int(y0 + 0.25 * (y1 - y0)), int(y1 - 0.25 * (y1 - y0)))
    return img[rows, cols], background


@pytest.mark.system
@pytest.mark.parametrize("name", ("candide3-3.1.6.wfm", "candide3-uv-variant.wfm"))
def test_candide_open_mouth_shows_a_dark_cavity_not_the_background(shared_data, name):
    head = resolve_head(shared_data / "candide3" / name)
    assert head.mesh.part_names[-1] == "mouth cavity"
    assert head_checks(head).passed
    inside, background = _mouth_pixels(head, (0.02, 0.027, 0.45, -0.007))  # /a/, the widest opening
    # Not see-through: the background is blue-grey, the cavity's dark red-brown (its highlight as bright).
    assert background[2] > background[0]
    off_background = (np.abs(inside - background).sum(axis=2) > 30) | (inside[..., 0] > inside[..., 2] + 5)
    assert off_background.mean() > 0.95
    assert np.mean(inside.sum(axis=2) < 200) > 0.95  # dark
    # With the lips closed the cavity is hidden everywhere (a mask's short chin does not show its rim),
    # front and three-quarter: the picture equals the one of the head without it.
    from assets.heads.wfm import candide_head
    from clients.render.renderer import RenderConfig, renderer_for_rig

    bare = candide_head(shared_data / "candide3" / name)
    for view in ("front", "three_quarter"):
        cfg = RenderConfig(width=200, height=200, samples=0, view=view)
        with renderer_for_rig(head.rig, head.mesh, cfg) as r:
            a = r.render().astype(int)
        with renderer_for_rig(bare.rig, bare.mesh, cfg) as r:
            b = r.render().astype(int)
        # (a crack between two of the wireframe's triangles, seen at an angle, may show a pixel of it)
        assert (np.abs(a - b).sum(axis=2) > 6).sum() <= 3, view


def test_hollow_test_tells_a_mask_from_a_head_with_an_inner_mouth(shared_data):
    from assets.heads.builtin import load_builtin_head
    from assets.heads.wfm import candide_head

    b = load_builtin_head()
    frame = face_frame(b.mesh.vertices, mouth_landmarks(b.landmarks))
    assert not opens_onto_nothing(b.mesh.vertices, b.mesh.triangles, frame, b.landmarks)  # mouth bag, teeth
    c = candide_head(shared_data / "candide3" / "candide3-3.1.6.wfm")
    v = np.asarray(c.mesh.vertices, float)
    idx = {k: int(np.argmin(np.linalg.norm(v - np.asarray(p), axis=1))) for k, p in c.rig.meta["landmarks"].items()}
    assert opens_onto_nothing(v, c.mesh.triangles, face_frame(v, mouth_landmarks(idx)), idx)


@pytest.mark.system
def test_a_full_body_avatar_without_landmarks_is_framed_on_its_face(tmp_path):
    """The built-in head's viseme targets on a head standing on a body 8 heads tall (a still box), no
    landmarks: the face fills the picture as the built-in head's does, and the mouth is in it."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.glb import mesh_glb
    from assets.heads.head import builtin_morph_head
    from assets.heads.targets import VISEME_ARKIT
    from clients.render.renderer import RenderConfig, renderer_for_rig

    b = builtin_morph_head().mesh
    bh = load_builtin_head()
    v = np.asarray(b.vertices, float)
    h = float(np.ptp(v[:, 1]))
    lo = v.min(0)
    box = np.array([[x, y, z] for x in (-1.5, 1.5) for y in (0, 1) for z in (-0.6, 0.6)]) * [h, 7 * h, h]
    box = box + np.array([0.0, lo[1] - 7 * h, 0.0])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    bt = np.array([[a, b_, c] for q in quads for a, b_, c in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]) + len(v)
    n_body = len(box)
    vis = {
        f"viseme_{k}": np.vstack([sum(w * bh.targets[a] for a, w in mix.items()), np.zeros((n_body, 3))])
        for k, mix in VISEME_ARKIT.items()
        if mix
    }
    glb = tmp_path / "avatar.glb"
    glb.write_bytes(
        mesh_glb(HeadMesh(vertices=np.vstack([v, box]), triangles=np.vstack([b.triangles, bt]), name="a", targets=vis))
    )
    avatar = resolve_head(glb)
    assert avatar.kind == "morph" and not avatar.rig.meta.get("landmarks")
    own = resolve_head("builtin")
    cfg = RenderConfig(width=200, height=200, samples=0)
    eyes = [bh.landmarks[k] for k in ("eye_outer_left", "eye_outer_right", "corner_left", "corner_right", "chin")]
    spans = []
    for hd in (avatar, own):
        with renderer_for_rig(hd.rig, hd.mesh, cfg) as r:
            px = r.project(np.asarray(hd.rig.neutral, float)[eyes])
        assert (px >= 0).all() and (px <= 200).all()  # eyes, mouth and chin in the picture
        spans.append(float(np.ptp(px[:2, 0])))
    assert spans[0] == pytest.approx(spans[1], rel=0.25)  # the face as large as the built-in head's


def test_a_closed_seam_with_neighbouring_inner_lip_points_is_no_membrane():
    """Inner-lip points snapped to two neighbouring vertices of one closed seam (automatic landmarks on
    a scan): the two paths are mostly the same seam, nothing is removed (the seam is cut instead)."""
    v, t, idx, n_skin = _two_lips_with_a_membrane()
    closed = t[:n_skin]  # no membrane: the upper and lower rows' inner edges are separate ...
    # ... so weld the lower inner row onto the upper one: one closed seam.
    lower = [idx["lower", i] for i in range(1, 8)]
    upper = [idx["upper", i] for i in range(1, 8)]
    weld = np.arange(len(v))
    weld[lower] = upper
    seam = weld[closed]
    a, b = idx["upper", 4], idx["upper", 5]  # neighbours on the seam
    assert not lip_membrane(v, seam, idx["upper", 0], idx["upper", 8], a, b).any()


def _contact(v: np.ndarray, fr, lm) -> tuple[np.ndarray, np.ndarray]:
    """``v`` (n, 3) in the face frame (n, 3, z forward), and the lips' contact depth (n,) at each vertex's place
    across the mouth: the inner-lip points' front-most depth in the middle, the corners' (if further back) at and
    past the corners."""
    q = (v - fr.origin) @ fr.axes.T
    middle = max(q[lm["upper_inner"], 2], q[lm["lower_inner"], 2])
    cx = 0.5 * (q[lm["corner_left"], 0] + q[lm["corner_right"], 0])
    half = 0.5 * abs(q[lm["corner_left"], 0] - q[lm["corner_right"], 0])
    ends = min(0.5 * (q[lm["corner_left"], 2] + q[lm["corner_right"], 2]), middle)
    return q, middle + (ends - middle) * np.clip(np.abs(q[:, 0] - cx) / half, 0, 1)


def _covered(q: np.ndarray, t: np.ndarray, i: int, margin: float) -> bool:
    """Whether some triangle of ``t`` lies more than ``margin`` in front of vertex ``i`` of ``q`` (face frame, z
    forward) where it projects (brute force over every triangle)."""
    from realtime_core.face.interpolation import barycentric_2d

    g = barycentric_2d(np.repeat(q[i : i + 1, :2], len(t), axis=0), q[t[:, 0], :2], q[t[:, 1], :2], q[t[:, 2], :2])
    over = np.all(g >= -1e-9, axis=1) & np.all(np.isfinite(g), axis=1)
    return bool((np.einsum("ij,ij->i", g[over], q[t[over], 2]) > q[i, 2] + margin).any())


def _cavity_dark(colors: np.ndarray) -> np.ndarray:
    """(k,) bool: colours (k, 3) of the cavity colour's hue, no brighter than it (the depth shade darkens it)."""
    from assets.heads.cavity import CAVITY_COLOR

    f = np.asarray(colors, dtype=np.float64) / np.asarray(CAVITY_COLOR)
    return (np.ptp(f, axis=1) <= 1e-4 * np.maximum(f.max(axis=1), 1e-3)) & (f.max(axis=1) <= 1 + 1e-5)


def test_an_untextured_mouth_inside_is_shaded_dark_and_the_face_keeps_its_colour():
    """The built-in head's geometry without colours or texture (the stylised held-out head's kind): the walls of
    its mouth bag behind the lips, which the lips hide from the front, go dark with their depth behind the lips'
    contact, the cavity colour's hue from INSIDE_RAMP IOD on (no darker than it: deeper, the shade darkens it
    further); what the front view shows (a changed vertex has a
    triangle of the head in front of it, found here by testing every triangle) and the landmarks (the corners,
    tucked in behind the lips on this head, too) keep the skin colour."""
    from dataclasses import replace

    from assets.heads.builtin import load_builtin_head
    from assets.heads.cavity import INSIDE_RAMP, with_dark_mouth_inside
    from assets.heads.mesh import SKIN_COLOR

    b = load_builtin_head()
    mesh = replace(b.mesh, colors=None, uvs=None, texture=None)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    fr = face_frame(v, mouth_landmarks(b.landmarks))
    out = with_dark_mouth_inside(mesh, v, fr, b.landmarks)
    assert out.colors is not None and len(out.colors) == len(v)
    changed = np.flatnonzero(np.abs(out.colors - np.asarray(SKIN_COLOR)).max(axis=1) > 1e-6)
    assert len(changed) > 20
    q, contact = _contact(v, fr, b.landmarks)
    # Depth behind the contact (from the inner-lip points' to the corners' across the mouth) sets the shade: the
    # cavity colour's hue from INSIDE_RAMP IOD on; nothing in front of the contact changes.
    assert (q[changed, 2] < contact[changed]).all()
    deep = changed[contact[changed] - q[changed, 2] >= INSIDE_RAMP * fr.iod]
    assert len(deep) and _cavity_dark(out.colors[deep]).all()
    # Each changed vertex has some triangle of the head in front of it (brute force over all triangles).
    t = np.asarray(mesh.triangles)
    for i in changed[:: max(1, len(changed) // 40)]:
        assert _covered(q, t, i, 0.005 * fr.iod), i
    for name in ("upper_lip", "lower_lip", "corner_left", "corner_right", "chin", "nose_tip"):
        assert b.landmarks[name] not in set(changed.tolist()), name


def test_an_untextured_mouth_inside_is_dark_whatever_its_depth_and_away_from_the_crease():
    """The stylised held-out head showed at /a/ a light triangle (its bag's floor 0.7-0.8 IOD behind the lips'
    contact, past a 0.6 IOD depth limit: skin-coloured) and light bands (walls just behind the contact but 0.2-0.3
    IOD above the mouth line, only partly darkened by a depth-only ramp). On the built-in head's geometry without
    colours: every vertex of the mouth's separate pieces (those apart from the skin that lie within the mouth's
    reach: its bag, reaching 1.5 IOD back) hidden from the front and INSIDE_RAMP IOD or more behind the contact
    is the cavity colour (its hue, as dark or darker), some of them more than 0.6 IOD back; every vertex shaded at
    least INSIDE_RAMP IOD above or below the lips' crease is the cavity colour; nothing past INSIDE_BOX's reach
    sideways, up or down changes."""
    from dataclasses import replace

    from scipy.sparse.csgraph import connected_components

    from assets.heads.builtin import load_builtin_head
    from assets.heads.cavity import (
        INSIDE_BOX,
        INSIDE_RAMP,
        INSIDE_SEED,
        with_dark_mouth_inside,
    )
    from assets.heads.mesh import SKIN_COLOR
    from realtime_core.face.projection import vertex_adjacency

    b = load_builtin_head()
    mesh = replace(b.mesh, colors=None, uvs=None, texture=None)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles)
    lm = b.landmarks
    fr = face_frame(v, mouth_landmarks(lm))
    out = with_dark_mouth_inside(mesh, v, fr, lm)
    assert out.colors is not None
    dark = _cavity_dark(out.colors)
    changed = np.abs(out.colors - np.asarray(SKIN_COLOR)).max(axis=1) > 1e-6
    q, contact = _contact(v, fr, lm)
    iod = fr.iod
    mid = 0.5 * (q[lm["corner_left"]] + q[lm["corner_right"]])
    half = 0.5 * abs(q[lm["corner_left"], 0] - q[lm["corner_right"], 0])
    side, up, down = INSIDE_BOX
    dx, dy = np.abs(q[:, 0] - mid[0]), q[:, 1] - mid[1]
    reach = (dx <= half + side * iod) & (dy <= up * iod) & (dy >= -down * iod)
    assert changed.any() and reach[changed].all()
    _, piece = connected_components(vertex_adjacency(len(v), t), directed=False)
    skin = piece[lm["upper_lip"]]
    inner = [p for p in np.unique(piece) if p != skin and reach[piece == p].all()]
    deep = np.flatnonzero(np.isin(piece, inner) & (contact - q[:, 2] >= INSIDE_RAMP * iod))
    deep = np.array([i for i in deep if _covered(q, t, i, 0.01 * iod)])
    assert len(deep) > 100 and (contact[deep] - q[deep, 2] > 0.6 * iod).sum() > 20
    assert dark[deep].all(), np.round((contact - q[:, 2])[deep[~dark[deep]]] / iod, 2)
    far = changed & (np.abs(dy) >= (INSIDE_SEED + INSIDE_RAMP) * iod)
    assert far.any() and dark[far].all()


def test_a_mouth_inside_painted_by_the_file_keeps_its_hue_and_one_material_colour_is_shaded():
    """Vertex colours that vary over the inside (the file's author painted it) keep their hue, darkened only with
    depth (each shaded vertex its own colour times one factor below 1, on fewer vertices than an unpainted inside:
    no lining colour); one colour over the whole head (a material's) is no painting: shaded as an uncoloured head's
    skin is."""
    from dataclasses import replace

    from assets.heads.builtin import load_builtin_head
    from assets.heads.cavity import with_dark_mouth_inside
    from assets.heads.mesh import SKIN_COLOR

    b = load_builtin_head()
    v = np.asarray(b.mesh.vertices, dtype=np.float64)
    fr = face_frame(v, mouth_landmarks(b.landmarks))
    painted = np.random.default_rng(0).uniform(0.2, 0.9, size=(len(v), 3)).astype(np.float32)
    mesh = replace(b.mesh, colors=painted, uvs=None, texture=None)
    kept = with_dark_mouth_inside(mesh, v, fr, b.landmarks).colors
    grey = np.tile(np.float32([0.7, 0.7, 0.75]), (len(v), 1))
    out = with_dark_mouth_inside(replace(b.mesh, colors=grey, uvs=None, texture=None), v, fr, b.landmarks)
    bare = with_dark_mouth_inside(replace(b.mesh, colors=None, uvs=None, texture=None), v, fr, b.landmarks)
    assert out.colors is not None and bare.colors is not None and kept is not None
    shaded = np.abs(out.colors - grey).max(axis=1) > 1e-6
    skin = np.asarray(SKIN_COLOR, dtype=np.float32)
    assert shaded.sum() > 20 and np.array_equal(shaded, np.abs(bare.colors - skin).max(axis=1) > 1e-6)
    darker = np.abs(kept - painted).max(axis=1) > 1e-6
    assert 20 < darker.sum() < shaded.sum() and not (darker & ~shaded).any()
    factor = kept[darker] / painted[darker]
    assert np.allclose(factor, factor[:, :1], rtol=1e-4) and (factor < 1).all()


def _material_head():
    """The built-in head as a file gives it (the test set's multi-material OBJ): its skin, eyes, teeth and tongue
    as parts of one flat material colour each, nothing shaded; with its landmarks and its own targets' rig."""
    from dataclasses import replace

    from assets.heads.builtin import PART_COLORS, load_builtin_head
    from assets.heads.head import Head, builtin_morph_head

    b = load_builtin_head()
    head = builtin_morph_head()
    assert {"upper teeth", "lower teeth", "tongue"} <= set(head.mesh.part_names)
    colors = PART_COLORS[np.asarray(b.part)].astype(np.float32)
    return Head(head.rig, replace(head.mesh, colors=colors, uvs=None, texture=None)), b, colors


def _rest_frame_wide(head):
    """The rig's rest (n, 3) float64, its face frame from the built-in head's landmarks and its widest opening."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import WIDE_OPEN

    v = np.asarray(head.rig.neutral, dtype=np.float64)
    return (
        v,
        face_frame(v, mouth_landmarks(load_builtin_head().landmarks)),
        head.rig.deformed(np.array([0.0, 0.0, WIDE_OPEN, 0.0])),
    )


def test_a_files_teeth_and_tongue_go_dark_with_depth_keeping_their_hue_and_the_face_keeps_its_colour():
    """Issue 12: a file head's own teeth and tongue (one material each) were lit like the face at /a/ (a bright
    pink tongue and white teeth filling the opening), because a painted inside was left as it came. Now, by their
    depth behind the upper inner lip (measured here, not from the code's lip contact line, which lies at most
    0.07 IOD behind it on this head): every tooth and tongue vertex 0.4 IOD or more behind it keeps at most 15% of
    its file colour, with its hue; the upper incisors' front (the upper teeth within 0.1 IOD behind the upper inner
    lip) keeps its colour exactly; every skin vertex outside the built-in head's own mouth bag (skin hidden from the
    front joined to the lips' contact line, :func:`assets.heads.builtin.mouth_bag`) and the eyes keep theirs exactly;
    the bag's cheek walls more than 0.1 IOD past a corner (they showed as a light wall at the near corner in
    three-quarter view at /a/) keep at most 20% of their colour."""
    from assets.heads.builtin import mouth_bag
    from assets.heads.cavity import with_dark_mouth_inside
    from realtime_core.face.simple import lip_contact_vertices

    head, b, colors = _material_head()
    v, fr, wide = _rest_frame_wide(head)
    lm = b.landmarks
    out = with_dark_mouth_inside(head.mesh, v, fr, lm, wide=wide).colors
    assert out is not None
    q = (v - fr.origin) @ fr.axes.T / fr.iod
    part = np.asarray(b.part)
    inner = np.flatnonzero(part >= 2)
    deep = inner[q[lm["upper_inner"], 2] - q[inner, 2] >= 0.4]
    assert len(deep) > 200
    factor = out[deep] / colors[deep]
    assert np.allclose(factor, factor[:, :1], rtol=1e-4) and (factor <= 0.15).all()
    upper = np.flatnonzero(part == 2)
    front = upper[q[lm["upper_inner"], 2] - q[upper, 2] <= 0.1]
    assert len(front) >= 5 and np.array_equal(out[front], colors[front])
    bv = np.asarray(b.mesh.vertices, dtype=np.float64)
    centre = 0.5 * (bv[lm["corner_left"]] + bv[lm["corner_right"]])
    line = lip_contact_vertices(bv, b.targets["jawOpen"], fr, mouth_centre=centre, candidates=part == 0, spacing=0.01)
    bag = np.zeros(len(v), dtype=bool)
    bag[mouth_bag(bv, b.mesh.triangles, part, line, fr)] = True
    keep = ((part == 0) & ~bag) | (part == 1)
    assert keep.sum() > 3000 and np.array_equal(out[keep], colors[keep])
    mid = 0.5 * (q[lm["corner_left"]] + q[lm["corner_right"]])
    half = 0.5 * abs(q[lm["corner_left"], 0] - q[lm["corner_right"], 0])
    wall = np.flatnonzero(bag & (np.abs(q[:, 0] - mid[0]) > half + 0.1))
    assert len(wall) >= 10 and (out[wall].max(axis=1) <= 0.2 * colors[wall].max(axis=1)).all()


def test_the_back_of_a_head_with_teeth_at_the_mouths_height_stays_skin():
    """A head with its own teeth has the built-in head's bag, unbounded: hidden skin joined to the lips' crease. The
    back of a head (and the neck below it, a full-body avatar's) is hidden from the front too, and at the mouth line's
    height it lies between the corners: it is no crease. Here a closed skin box 2.5 IOD behind the mouth (hidden
    behind the face, spanning the mouth line) keeps its colour, and the inside is shaded as without it."""
    from dataclasses import replace

    from assets.heads.cavity import with_dark_mouth_inside

    head, b, colors = _material_head()
    v, fr, wide = _rest_frame_wide(head)
    lm = b.landmarks
    alone = with_dark_mouth_inside(head.mesh, v, fr, lm, wide=wide).colors
    mouth = 0.5 * (v[lm["corner_left"]] + v[lm["corner_right"]]) - 2.5 * fr.iod * fr.axes[2]
    corners = np.array([[x, y, z] for x in (-0.15, 0.15) for y in (-0.02, 0.3) for z in (-0.3, 0.3)]) * fr.iod
    box = mouth + corners @ fr.axes
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    bt = np.array([[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads]) + len(v)
    n = len(v)
    mesh = replace(
        head.mesh,
        vertices=np.vstack([head.mesh.vertices, box]),
        triangles=np.vstack([head.mesh.triangles, bt]),
        colors=np.vstack([colors, np.tile(colors[lm["chin"]], (8, 1))]),
        part=np.r_[np.asarray(head.mesh.part), np.zeros(8, dtype=np.asarray(head.mesh.part).dtype)],
        targets=None,
    )
    out = with_dark_mouth_inside(mesh, np.vstack([v, box]), fr, lm, wide=np.vstack([wide, box])).colors
    assert out is not None and alone is not None
    assert np.array_equal(out[n:], mesh.colors[n:])  # the back stays skin
    assert np.allclose(out[:n], alone, atol=1e-6)


def test_an_own_target_head_with_a_lit_inner_mouth_gets_the_same_dark_inside():
    """A head driven by its own targets (a glb with ARKit targets) was given no shading at all: the same function
    shades it (:func:`assets.heads.cavity.with_mouth_cavity`, its landmarks from the rig), and a head shaded once
    (the built-in head's own colours) is not shaded twice."""
    from assets.heads.cavity import with_dark_mouth_inside, with_mouth_cavity
    from assets.heads.head import Head, builtin_morph_head

    head, b, colors = _material_head()
    out = with_mouth_cavity(head)
    v, fr, wide = _rest_frame_wide(head)
    same = with_dark_mouth_inside(head.mesh, v, fr, b.landmarks, wide=wide).colors
    assert np.allclose(out.mesh.colors, same, atol=1e-6)  # (its frame from the float64 mesh, here the float32 rig)
    assert (np.asarray(out.mesh.colors) < colors - 1e-3).any(axis=1).sum() > 300
    shaded = builtin_morph_head()
    assert with_mouth_cavity(Head(shaded.rig, shaded.mesh)).mesh is shaded.mesh


def test_an_own_target_head_without_landmarks_is_located_by_the_finder_and_keeps_its_points():
    """A glb with its own targets and teeth but no landmarks (the full-body avatar) is located by the landmark
    finder (here the built-in head's hand points, as a finder returns them: name -> point), shaded as with
    landmarks, and the points travel with its rig: found again on the shaded mesh they moved (the finder reads a
    render), and the checks measured the avatar's lips at other vertices. Without a finder it comes back as it is."""
    from dataclasses import replace

    from assets.heads.cavity import with_mouth_cavity
    from assets.heads.head import Head

    head, b, colors = _material_head()
    points = {k: head.mesh.vertices[i].tolist() for k, i in b.landmarks.items()}
    bare = Head(replace(head.rig, meta={k: v for k, v in head.rig.meta.items() if k != "landmarks"}), head.mesh)
    assert with_mouth_cavity(bare) is bare
    found = with_mouth_cavity(bare, landmark_finder=lambda mesh: points)
    assert found.rig.meta["landmarks"] == points
    assert np.allclose(found.mesh.colors, with_mouth_cavity(head).mesh.colors, atol=1e-6)
    assert (np.asarray(found.mesh.colors) < colors - 1e-3).any(axis=1).sum() > 300


def test_a_textured_heads_teeth_are_darkened_by_vertex_colours_that_multiply_its_texture(tmp_path):
    """The built-in head given a white texture (a Character Creator export's kind): its skin keeps the texture as it
    is (colour multiplier 1, the bag included: a texture paints it as its author meant), its teeth and tongue
    get multipliers under 1 growing darker with depth behind the lips, and the renderer draws texture x colour:
    a deep molar's pixel is darker than the same mesh drawn without the colours. Before, a textured head's teeth
    were lit as the face: white wedges at the mouth corners."""
    import io
    from dataclasses import replace

    from PIL import Image

    from assets.heads.builtin import load_builtin_head
    from assets.heads.cavity import inner_mouth_vertices, with_dark_mouth_inside
    from clients.render.renderer import HeadRenderer, RenderConfig

    b = load_builtin_head()
    v = np.asarray(b.mesh.vertices, dtype=np.float64)
    fr = face_frame(v, mouth_landmarks(b.landmarks))
    buf = io.BytesIO()
    Image.new("RGB", (8, 8), (240, 240, 240)).save(buf, "PNG")
    uv = np.full((len(v), 2), 0.5)
    names = ("skin", "eyes", "upper teeth", "lower teeth", "tongue")  # load_builtin_head's part labels
    part = np.asarray(b.part, dtype=np.int16)
    mesh = replace(b.mesh, colors=None, uvs=uv, texture=buf.getvalue(), part=part, part_names=names)
    out = with_dark_mouth_inside(mesh, v, fr, b.landmarks)
    assert out.colors is not None and out.texture == mesh.texture
    inner = inner_mouth_vertices(mesh)
    assert inner.sum() > 50
    np.testing.assert_array_equal(out.colors[~inner], 1.0)
    q, contact = _contact(v, fr, b.landmarks)
    depth = contact[inner] - q[inner, 2]
    shade = out.colors[inner, 0]
    order = np.argsort(depth)
    quarter = len(order) // 4
    assert shade.min() < 0.5 and shade[order[-quarter:]].mean() < 0.8 * shade[order[:quarter]].mean()
    deepest = np.flatnonzero(inner)[np.argmin(shade)]
    # Drawn through the mouth of a head with no lips in front: the deepest tooth vertex's pixel, with and without.
    centre = v[deepest]
    seen = []
    for m in (out, mesh):
        front = replace(m, triangles=m.triangles[inner[m.triangles].all(axis=1)])
        with HeadRenderer(front, centre=centre, axes=fr.axes, size=0.05 * fr.iod, config=RenderConfig(64, 64)) as r:
            seen.append(r.render()[32, 32].astype(int))
    assert seen[0].sum() < 0.7 * seen[1].sum()


def test_the_cavity_floor_follows_the_jaw_and_stays_behind_the_skin(shared_data):
    """Candide-3 (a face mask) gets a mouth cavity whose floor follows the jaw (add_mouth_cavity): at rest nothing
    moves and the head's own vertices move exactly as without it at every pose; at the widest opening and at every
    corner of the speech box (CAVITY_POSES) no cavity vertex lies in front of a surface within CAVITY_FAR_WALL
    behind it, nor less than 0.1 IOD behind one in front of it (trimesh's barycentric coordinates over every face,
    not the placement's own depth search); the floor drops with the chin and the roof stays."""
    from trimesh.triangles import points_to_barycentric

    from assets.heads.cavity import with_mouth_cavity
    from assets.heads.rigging import CAVITY_FAR_WALL, CAVITY_POSES, WIDE_OPEN
    from assets.heads.wfm import candide_head

    bare = candide_head(shared_data / "candide3" / "candide3-3.1.6.wfm")
    head = with_mouth_cavity(bare)
    rig = head.rig
    n0 = len(bare.rig.neutral)
    n_c = int(rig.meta["mouth_cavity"])
    assert len(rig.neutral) == n0 + n_c
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    idx = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in rig.meta["landmarks"].items()}
    fr = face_frame(v0[:n0], mouth_landmarks(idx))
    iod, ax = fr.iod, fr.axes
    np.testing.assert_array_equal(rig.deformed(np.zeros(4)), rig.neutral)
    poses = [(0.0, 0.0, WIDE_OPEN, 0.0), *CAVITY_POSES]
    for p in poses:
        np.testing.assert_allclose(rig.deformed(np.array(p))[:n0], bare.rig.deformed(np.array(p)), atol=1e-6)
    t = np.asarray(rig.triangles, dtype=np.int64)
    skin_t = t[(t < n0).all(axis=1)]
    for p in poses:
        q = (np.asarray(rig.deformed(np.array(p)), dtype=np.float64) - fr.origin) @ ax.T
        # Every skin face under every cavity vertex seen from the front: barycentric coordinates of the vertex in
        # the face flattened onto the view plane (trimesh), the face's depth there interpolated from its corners.
        tri = np.repeat(q[skin_t][None], n_c, axis=0).reshape(-1, 3, 3)
        flat = tri * np.array([1.0, 1.0, 0.0])
        pts = np.repeat(q[n0:] * np.array([1.0, 1.0, 0.0]), len(skin_t), axis=0)
        bary = points_to_barycentric(flat, pts)
        under = (bary >= -1e-9).all(axis=1)
        ahead = (np.einsum("ij,ij->i", bary, tri[:, :, 2]) - np.repeat(q[n0:, 2], len(skin_t))) / iod
        # A surface behind the vertex within CAVITY_FAR_WALL is skin it would cover; one in front, skin it must stay
        # 0.1 IOD behind.
        assert not (under & (ahead > -CAVITY_FAR_WALL + 1e-6) & (ahead < 0.1 - 1e-6)).any(), p
    # The floor (the lowest cavity vertices) drops with the chin at the widest opening; the roof does not move.
    vw = np.asarray(rig.deformed(np.array([0.0, 0.0, WIDE_OPEN, 0.0])), dtype=np.float64)
    y = (v0 - fr.origin) @ ax[1]
    drop = (vw - v0) @ ax[1] / iod
    line = 0.5 * (y[idx["corner_left"]] + y[idx["corner_right"]])
    cavity_y = y[n0:]
    floor = n0 + np.argsort(cavity_y)[:8]
    chin = drop[:n0][(y[:n0] < line) & ((v0[:n0] - fr.origin) @ ax[0] == 0)].min()  # the lowest drop on the middle
    assert drop[floor].min() < -0.15 and drop[floor].min() > chin - 1e-6
    roof = n0 + np.flatnonzero(cavity_y >= line)
    assert len(roof) > 10 and np.abs(vw[roof] - v0[roof]).max() == 0.0


class _HeldApart:
    """A rig whose lips never meet: every pose deformed with ``extra`` more mouth_open (the closure pose's lips held
    apart, the slit of a lip membrane removed from lips that were never parted)."""

    def __init__(self, rig, extra: float) -> None:
        self.rig, self.extra = rig, extra
        self.neutral, self.triangles = rig.neutral, rig.triangles

    def deformed(self, params):
        return self.rig.deformed(np.asarray(params, float) + np.array([0.0, 0.0, self.extra, 0.0]))


@pytest.mark.slow
def test_closed_lips_seen_dark_flags_lips_held_apart_and_passes_the_mediapipe_face(shared_data):
    """The MediaPipe face's lips meet at closure over its cavity: nothing of its lips' band is drawn dark there. Its
    rig held 0.1 mouth_open apart shows the cavity between the lips at the closure pose: the figure sees it and fails
    the rig. By an independent estimate, the opening seen from the front is a lens between the inner lips: at most
    their gap in the middle times the corners' width, at least 0.4 of it (a lens of two parabolas is 2/3)."""
    from realtime_core.face.checks import LIPS_DARK_LIMIT, check_rig, lips_dark_seen

    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    head = resolve_head(mp)
    rep = head_checks(head)
    assert rep.lips_dark_iod2 is not None and rep.lips_dark_iod2 <= LIPS_DARK_LIMIT, rep.summary()
    lm = head.rig.meta["landmarks"]
    v0 = np.asarray(head.rig.neutral, float)
    near = mouth_landmarks({k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in lm.items()})
    cavity = int(head.rig.meta["mouth_cavity"])
    apart = _HeldApart(head.rig, 0.1)
    closed = (0.0, 0.0, 0.0, 0.0)
    got = lips_dark_seen(apart, near, poses=(closed,), cavity_vertices=cavity)
    assert got is not None and got[1] == closed
    v = np.asarray(apart.deformed(np.zeros(4)), float)
    fr = face_frame(v0, near)
    gap = float((v[near.upper_inner] - v[near.lower_inner]) @ fr.axes[1]) / fr.iod
    width = float((v[near.corner_left] - v[near.corner_right]) @ fr.axes[0]) / fr.iod
    assert gap > 0.05
    assert 0.4 * gap * abs(width) <= got[0] <= gap * abs(width)
    failed = check_rig(apart, near, cavity_vertices=cavity, expression_poses=())
    assert not failed.passed and any("slit between closed lips" in f for f in failed.failures)
    # Its closure pose lies 0.0008 mouth_open below rest: nearly the same slit.
    assert failed.lips_dark_iod2 == pytest.approx(got[0], rel=0.05) and got[0] > LIPS_DARK_LIMIT
