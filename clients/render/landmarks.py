"""Automatic landmarks for human-like heads: render the head, find the face with MediaPipe, cast back.

1. Render the mesh offscreen (:class:`clients.render.renderer.HeadRenderer`, EGL) from the front,
   trying the usual orientations in turn (glTF's +y up / face towards +z first, then -z, +x, -x,
   and z-up files), framed on the whole mesh and, for full-body avatars, on its top.
2. Run MediaPipe Face Mesh (``mediapipe`` 0.10.14, legacy ``solutions.face_mesh``, static image mode)
   on the render: 468 points in pixels.
3. Re-render framed on the detected face (a larger face gives steadier points) and detect again: the found set.
   Its alternatives (:data:`ALTERNATIVES`), rigged from only when every rig from the found set fails: the same on a
   render lit mirror-symmetrically (RenderConfig's "frontal" lighting), MediaPipe on several views of it (zoomed,
   shifted, each mirrored: :func:`_views`), each point's pixel the views' median (a head and its mirror image get
   mirrored points), then single views' sets.
4. Cast each needed point back onto the mesh: the mesh triangles are projected with the renderer's
   camera; the front-most triangle under the pixel gives the 3D point (barycentric interpolation).
5. Take two points to facecast's definitions (:func:`_refined`): on lips modelled apart, a mouth corner hidden
   behind skin moves into the lips' crease behind it; the lower lip point is the lowest point of the lip's front
   (MediaPipe 17 is the vermilion's lower edge). The rig then takes each point at its nearest vertex.

The twelve facecast landmarks are MediaPipe indices (the subject's own left/right, as facecast):
eye corners 263/362 (left) and 33/133 (right), nose tip 1, mouth corners 291 (left) / 61 (right),
outer lips 0/17, inner lips 13/14, chin 152. Raises LandmarkError naming the file when no face is
found ("give --landmarks").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from assets.errors import LandmarkError
from assets.heads.landmarks import FoundLandmarks
from assets.heads.mesh import HeadMesh
from assets.heads.rigging import lips_connected
from assets.mediapipe_log import native_stderr_quiet
from clients.render.renderer import RenderConfig
from realtime_core.face import face_frame_at
from realtime_core.normals import triangle_normals

MEDIAPIPE_INDEX: dict[str, int] = {
    "eye_outer_left": 263,
    "eye_inner_left": 362,
    "eye_outer_right": 33,
    "eye_inner_right": 133,
    "nose_tip": 1,
    "corner_left": 291,
    "corner_right": 61,
    "upper_lip": 0,
    "lower_lip": 17,
    "upper_inner": 13,
    "lower_inner": 14,
    "chin": 152,
}
INNER_LIP_OUTER = {"upper_inner": "upper_lip", "lower_inner": "lower_lip"}
INNER_LIP_DEPTH = 0.25
"""IOD: an inner-lip point cast further than this behind the outer lip midpoints (along the camera's
view) went through the lips: between closed lips whose crease is a slit (a decimated or low-poly
head: Lee Perry-Smith at ~4,000 triangles cast its upper inner-lip point 1 IOD deep, into the head),
or past open lips into a mouth bag. The point is then the first one on the lip met from it towards the
outer lip midpoint (:func:`_onto_lips`). Every head of the test set casts its inner-lip points within
0.02 IOD of the outer lip's depth or in front of it."""
CORNER_OUTWARD = 0.3
"""A mouth corner cast through the lips (INNER_LIP_DEPTH behind the outer lip midpoints) is looked for on the pixel
segment from its pixel outwards, away from the mouth's centre, over this fraction of the mouth's half-width. Lips
parted at rest with no mouth inside (a scan, Lee Perry-Smith with its lips 0.1 IOD apart): MediaPipe puts a corner
in the opening's end, and its pixel showed the inside of the back of the head, 0.6 IOD below the mouth as cast
(docs/animation.md, "Held-out heads", branch i12new)."""
INNER_LIP_STEPS = 32  # pixels tried between an inner-lip point and its outer lip point
SLIT_WALL_STEP = 0.05
"""IOD: where the next lip point met on the pixel segment of :func:`_onto_lips` lies more than this in front of the
one before it (along the camera's view), the points before are the slit's wall seen edge-on, not the lip's front,
and are passed over.
The 3,810-triangle Lee Perry-Smith copy with its mouth jittered by +-0.002 IOD (seed 1) met its upper lip's slit wall
0.106 IOD behind the outer lips' front and then the front at 0.020: the upper inner-lip point cast there took the
cut inside the slit and the rig failed (8 flips, no opening; docs/animation.md, "The 3,810 copy under jitter").
Consecutive points on a rounded lip's edge, 1/INNER_LIP_STEPS of the segment apart, differ by about 0.007 IOD."""
LOWER_LIP_STEPS = 32  # pixels tried from the lower inner-lip point down to MediaPipe's lower vermilion edge
LOWER_LIP_FLAT = 0.01
"""IOD: the lower lip's outer midpoint (``lower_lip``) is the lowest midline point of the lip's front, i.e. the
lowest point on the render's segment from the lower inner-lip point (MediaPipe 14) to the vermilion's lower edge
(MediaPipe 17) lying within this of the segment's front-most depth (:func:`_lower_lip_front`). MediaPipe 17 sits
where the lip has turned back towards the chin's crease (0.08 IOD below the hand-picked point on the built-in
head's geometry); the front-most point alone is ill-defined on a flat lip (Lee Perry-Smith's front varies by
under 0.01 IOD over 0.06 IOD of height)."""
CORNER_RAY_REACH = 0.05
"""IOD: how far from the view ray through a mouth corner's pixel a vertex of the lips' crease may lie."""
CORNER_DEPTH = 0.25
"""IOD: how far behind the cast mouth-corner point the crease is looked for. A corner hidden in a frontal view
(lips modelled apart whose corners tuck in behind the lip and cheek: the built-in head's geometry, 0.15 IOD behind
the front-most skin) lies in the lips' crease behind the skin the pixel shows (:func:`_into_corner_crease`)."""
CREASE_FACING = 0.3
"""A crease vertex: among its triangles one faces up and one faces down by more than this (the cosine of the
normal with the render's up axis): the lower lip's top meeting the upper lip's underside."""

SIZE = 640  # render size in pixels (MediaPipe works on any size; the face should cover ~1/3 of it)

# (up, forward) axis pairs to try: glTF/three.js (+y up, face +z) first.
ORIENTATIONS: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    ((0, 1, 0), (0, 0, 1)),
    ((0, 1, 0), (0, 0, -1)),
    ((0, 1, 0), (1, 0, 0)),
    ((0, 1, 0), (-1, 0, 0)),
    ((0, 0, 1), (0, -1, 0)),
    ((0, 0, 1), (0, 1, 0)),
)


def _axes(up: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    x = np.cross(up, fwd)
    return np.stack([x, up, fwd]).astype(np.float64)


def _detect(image: np.ndarray) -> np.ndarray | None:
    """(468, 2) pixel coordinates of the face in an RGB image, or None."""
    import mediapipe as mp

    with (
        native_stderr_quiet(),
        mp.solutions.face_mesh.FaceMesh(
            static_image_mode=True, max_num_faces=1, refine_landmarks=False, min_detection_confidence=0.5
        ) as fm,
    ):
        res = fm.process(np.ascontiguousarray(image))
    if not res.multi_face_landmarks:
        return None
    h, w = image.shape[:2]
    lm = res.multi_face_landmarks[0].landmark
    return np.array([[p.x * w, p.y * h] for p in lm[:468]])


MIRROR_PARTNER: dict[int, int] = {263: 33, 362: 133, 291: 61, 234: 454}
"""MediaPipe points used here whose mirror image is another point (the subject's left and right); the others used are
on the midline (1, 10, 0, 17, 13, 14, 152)."""
VIEW_ZOOMS: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.0, 0.0),
    (0.92, 0.0, 0.0),
    (1.08, 0.0, 0.0),
    (1.0, 0.02, 0.02),
)
"""(zoom, x shift, y shift as fractions of the image) of the views of one render MediaPipe is run on, each also
mirrored (:func:`_views`). MediaPipe's points move with how the face sits in the image and on which side it is: on
one render of the untextured Lee Perry-Smith and its mirror image the inner-lip points lay up to 0.046 IOD apart.
The views are the same render resampled (no render, ~0.02 s each), so their points map back to its pixels exactly."""


def _mirror_order() -> np.ndarray:
    """(468,) MediaPipe index -> the index of its mirror image (MIRROR_PARTNER both ways, the rest itself)."""
    order = np.arange(468)
    for a, b in MIRROR_PARTNER.items():
        order[a], order[b] = b, a
    return order


def _views(
    image: np.ndarray, zooms: tuple[tuple[float, float, float], ...] = VIEW_ZOOMS, mirrored: bool = True
) -> list[np.ndarray]:
    """MediaPipe's points (468, 2) in ``image``'s pixels on each view of it (VIEW_ZOOMS, each also mirrored left to
    right, its points flipped back and their sides swapped, unless not ``mirrored``); views with no face found are left
    out. Their median is
    mirror-symmetric by construction: a head's mirror image (rendered with mirror-symmetric light, RenderConfig's
    "frontal") gives the same views mirrored."""
    from PIL import Image

    h, w = image.shape[:2]
    half = np.array([w, h], dtype=np.float64) / 2.0
    out: list[np.ndarray] = []
    for flip in (False, True) if mirrored else (False,):
        img = Image.fromarray(np.ascontiguousarray(image[:, ::-1] if flip else image))
        bg = tuple(int(c) for c in image[0, 0])
        for zoom, dx, dy in zooms:
            shift = np.array([dx * w, dy * h])
            # Output pixel q shows the render at half + (q - half) / zoom + shift (PIL's affine maps output to input).
            a = 1.0 / zoom
            c = half - a * half + shift
            if flip:
                c[0] = half[0] - a * half[0] - shift[0]  # the mirrored view's shift mirrored too (symmetric set)
            if (zoom, dx, dy) == (1.0, 0.0, 0.0):
                view = img  # the render itself (or its mirror image): nothing to resample
            else:
                affine = (a, 0.0, float(c[0]), 0.0, a, float(c[1]))
                view = img.transform((w, h), Image.Transform.AFFINE, affine, Image.Resampling.BILINEAR, fillcolor=bg)
            pts = _detect(np.asarray(view))
            if pts is None:
                continue
            pts = pts * a + c
            if flip:
                pts[:, 0] = w - pts[:, 0]
                pts = pts[_mirror_order()]
            out.append(pts)
    return out


FACING_GRID = 24
"""Samples per side of the frontal grid :func:`facing_viewer` looks at the front-most surface through."""


def facing_viewer(mesh: HeadMesh, axes: np.ndarray) -> HeadMesh:
    """``mesh`` wound so that the surface a viewer looking along -``axes[2]`` (the camera in front, (3,) rows
    x, up, towards the camera) sees first faces it: reversed when, over a FACING_GRID x FACING_GRID grid across
    the mesh's frontal extent, more of the front-most triangles face away than towards the viewer.

    The renderer draws back faces dark (the inside of a mouth), so a file wound the other way (a mirrored export)
    renders as a dark face, and MediaPipe's points on it land elsewhere: Lee Perry-Smith as an OBJ with its
    winding reversed gave a nose tip 0.12 IOD and lip points 0.02-0.03 IOD from the same OBJ's wound normally,
    and its cut ran elsewhere (mouth opening 0.48, flaps across the opening). Orthographic (the grid only
    samples which surface is in front), winding-independent, so every file wound consistently either way gives
    the same render."""
    from realtime_core.face.interpolation import barycentric_2d

    v = np.asarray(mesh.vertices, dtype=np.float64) @ np.asarray(axes, dtype=np.float64).T
    t = np.asarray(mesh.triangles, dtype=np.int64)
    if not len(t):
        return mesh
    p2 = v[:, :2]
    lo_t, hi_t = p2[t].min(axis=1), p2[t].max(axis=1)
    lo, hi = p2.min(axis=0), p2.max(axis=0)
    s = (np.arange(FACING_GRID) + 0.5) / FACING_GRID
    grid = np.stack(np.meshgrid(lo[0] + s * (hi[0] - lo[0]), lo[1] + s * (hi[1] - lo[1])), axis=-1).reshape(-1, 2)
    # Twice the signed area in the view plane: > 0 when the triangle runs anticlockwise as seen, i.e. faces
    # the viewer (OpenGL's default front face).
    a, b, c = p2[t[:, 0]], p2[t[:, 1]], p2[t[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    towards = away = 0
    for q in grid:
        cand = np.flatnonzero(np.all((lo_t <= q) & (hi_t >= q), axis=1) & (area != 0))
        if not len(cand):
            continue
        g = barycentric_2d(q[None, :], a[cand], b[cand], c[cand])
        ok = np.all(g >= -1e-9, axis=1)
        if not ok.any():
            continue
        depth = (g[ok] * v[t[cand[ok]], 2]).sum(axis=1)  # towards the camera
        front = cand[ok][int(np.argmax(depth))]
        towards += int(area[front] > 0)
        away += int(area[front] < 0)
    if away <= towards:
        return mesh
    return replace(mesh, triangles=np.ascontiguousarray(t[:, ::-1]))


def _cast(mesh: HeadMesh, mvp: np.ndarray, pixels: np.ndarray, size: int) -> np.ndarray:
    """3D points (k, 3) on the front-most triangle under each pixel (k, 2); NaN where none is."""
    return _cast_hits(mesh, mvp, pixels, size)[0]


def _cast_hits(mesh: HeadMesh, mvp: np.ndarray, pixels: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(3D points (k, 3), triangle indices (k,)) of the front-most triangle under each pixel (k, 2); NaN / -1
    where none is."""
    from realtime_core.face.interpolation import barycentric_2d

    v = np.asarray(mesh.vertices, dtype=np.float64)
    clip = np.c_[v, np.ones(len(v))] @ mvp.T
    w = clip[:, 3]
    px = np.c_[(clip[:, 0] / w + 1) / 2 * size, (1 - clip[:, 1] / w) / 2 * size]
    t = np.asarray(mesh.triangles, dtype=np.int64)
    out = np.full((len(pixels), 3), np.nan)
    face = np.full(len(pixels), -1, dtype=np.int64)
    lo = px[t].min(axis=1)
    hi = px[t].max(axis=1)
    for i, p in enumerate(pixels):
        cand = np.flatnonzero(np.all((lo <= p) & (hi >= p), axis=1) & (w[t] > 0).all(axis=1))
        if not len(cand):
            continue
        tc = t[cand]
        g = barycentric_2d(p[None, :], px[tc[:, 0]], px[tc[:, 1]], px[tc[:, 2]])
        ok = np.all(g >= -1e-6, axis=1) & np.all(np.isfinite(g), axis=1)
        if not ok.any():
            continue
        depth = (g[ok] * w[tc[ok]]).sum(1)
        k = int(np.argmin(depth))
        out[i] = g[ok][k] @ v[tc[ok][k]]
        face[i] = cand[ok][k]
    return out, face


def _face_pieces(mesh: HeadMesh) -> np.ndarray:
    """(m,) int: each triangle's mesh piece once texture seams are welded (:func:`welded_pieces`). The same for every
    mesh the landmark search draws (the file's, or :func:`facing_viewer`'s rewound copy: same vertices, same triangles
    in the same order), so it is computed once per search: welding a 106k-vertex scan took 0.3 s a call."""
    from realtime_core.face.welding import welded_pieces

    canon, _, piece = welded_pieces(np.asarray(mesh.vertices, dtype=np.float64), mesh.triangles)
    return np.asarray(piece[canon[np.asarray(mesh.triangles, dtype=np.int64)[:, 0]]])


def _onto_lips(
    mesh: HeadMesh,
    mvp: np.ndarray,
    pixels: dict[str, np.ndarray],
    points: dict[str, np.ndarray],
    forward: np.ndarray,
    face_piece: np.ndarray,
) -> dict[str, np.ndarray]:
    """``points`` (name -> (3,), as cast from ``pixels``, name -> (2,)) with each inner-lip point that went
    through the lips (INNER_LIP_DEPTH) or onto another mesh piece than its outer lip midpoint's moved to the first
    point on that lip's piece met on the pixel segment from it to its outer lip midpoint's pixel, and each mouth corner
    that went through the lips to the first met going outwards along the mouth (CORNER_OUTWARD), both past a slit's
    wall (SLIT_WALL_STEP); left as it is when none is found (the rig checks then judge).

    Another piece (texture seams welded): lips modelled apart in a one-file head with its teeth in it show the teeth
    between them at MediaPipe's inner-lip pixel, only 0.085 IOD behind the lips' front (within INNER_LIP_DEPTH): the
    built-in head with 0.1 of its jawOpen baked in took its upper inner-lip point on an upper tooth, and an upper-lip
    raise then crossed "the lips" by 0.022 IOD (docs/animation.md, "Own targets with the lips modelled apart").
    ``face_piece``: the mesh's :func:`_face_pieces`."""
    eyes = [0.5 * (points[f"eye_outer_{s}"] + points[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    front = min(float(points[k] @ forward) for k in INNER_LIP_OUTER.values())
    out = dict(points)
    mid = 0.5 * (pixels["corner_left"] + pixels["corner_right"])
    towards = {inner: pixels[outer] for inner, outer in INNER_LIP_OUTER.items()}
    towards |= {c: pixels[c] + CORNER_OUTWARD * (pixels[c] - mid) for c in ("corner_left", "corner_right")}
    # The piece each inner-lip point's own lip is on (its outer midpoint's): an inner-lip point cast onto another
    # piece (the teeth, seen between lips modelled apart) is not on its lip however shallow it lies.
    names = list(INNER_LIP_OUTER) + list(INNER_LIP_OUTER.values())
    _, faces = _cast_hits(mesh, mvp, np.stack([pixels[k] for k in names]), SIZE)
    piece_of = {k: int(face_piece[f]) if f >= 0 else -1 for k, f in zip(names, faces, strict=True)}
    lip_piece = {inner: piece_of[outer] for inner, outer in INNER_LIP_OUTER.items()}
    for inner, end in towards.items():
        want = lip_piece.get(inner, -1)
        off_piece = want >= 0 and piece_of[inner] != want
        if float(points[inner] @ forward) >= front - INNER_LIP_DEPTH * iod and not off_piece:
            continue
        s = np.linspace(0.0, 1.0, INNER_LIP_STEPS + 1)[1:, None]
        line = pixels[inner][None, :] * (1.0 - s) + end[None, :] * s
        hit, hit_face = _cast_hits(mesh, mvp, line, SIZE)
        ok = np.isfinite(hit).all(axis=1) & (hit @ forward >= front - INNER_LIP_DEPTH * iod)
        if want >= 0:
            ok &= (hit_face >= 0) & (face_piece[np.maximum(hit_face, 0)] == want)
        on_lip = np.flatnonzero(ok)
        if len(on_lip):
            depth = hit[on_lip] @ forward
            # The points before the last forward jump (SLIT_WALL_STEP) are the slit's wall, seen edge-on.
            jumps = np.flatnonzero(np.diff(depth) > SLIT_WALL_STEP * iod)
            out[inner] = hit[on_lip[int(jumps[-1]) + 1 if len(jumps) else 0]]
    return out


def _ray(mvp: np.ndarray, pixel: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The view ray through ``pixel`` (2,): (a point on it (3,), its unit direction (3,) away from the camera)."""
    ndc = np.array([2.0 * pixel[0] / size - 1.0, 1.0 - 2.0 * pixel[1] / size])
    inv = np.linalg.inv(mvp)
    # Two depths inside any camera's range; clip w grows away from the camera, which orients the ray.
    ends = [inv @ np.array([ndc[0], ndc[1], z, 1.0]) for z in (0.0, 0.5)]
    a, b = (e[:3] / e[3] for e in ends)
    d = (b - a) / np.linalg.norm(b - a)
    return a, d if float(mvp[3, :3] @ d) > 0 else -d


def _crease_vertices(mesh: HeadMesh, up: np.ndarray) -> np.ndarray:
    """(n,) bool: vertices with a triangle facing up and one facing down (CREASE_FACING) about them."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int64)
    n = triangle_normals(v, t)
    facing = (n @ up) / np.maximum(np.linalg.norm(n, axis=1), 1e-300)
    hi = np.full(len(v), -np.inf)
    lo = np.full(len(v), np.inf)
    for j in range(3):
        np.maximum.at(hi, t[:, j], facing)
        np.minimum.at(lo, t[:, j], facing)
    return (hi > CREASE_FACING) & (lo < -CREASE_FACING)


def _into_corner_crease(
    mesh: HeadMesh, mvp: np.ndarray, pixel: np.ndarray, point: np.ndarray, crease: np.ndarray, iod: float
) -> np.ndarray:
    """The mouth corner cast at ``point`` (3,) from ``pixel`` (2,), moved into the lips' crease behind it when
    it is hidden: the deepest crease vertex (``crease``, (n,) bool) of the cast point's part within
    CORNER_RAY_REACH of the view ray and CORNER_DEPTH behind the point. A visible corner (the pixel shows the
    crease: a crease vertex on the triangle under it or on one sharing a vertex with it), or no crease found:
    the point as cast. (The built-in head's geometry, open lips tucked in, shows skin 3 edges from its crease.)
    Called for lips modelled apart only (:func:`_refined`)."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    hit = _cast_hits(mesh, mvp, pixel[None, :], SIZE)[1][0]
    t = np.asarray(mesh.triangles, dtype=np.int64)
    if hit < 0:
        return point
    beside = t[np.isin(t, t[hit]).any(axis=1)]  # the triangle under the pixel and the ones sharing a vertex
    if crease[beside].any():
        return point
    _, d = _ray(mvp, pixel, SIZE)
    rel = v - point
    depth = rel @ d  # distance behind the cast point along the ray
    lateral = np.linalg.norm(rel - np.outer(depth, d), axis=1)
    ok = crease & (lateral <= CORNER_RAY_REACH * iod) & (depth >= 0.0) & (depth <= CORNER_DEPTH * iod)
    if mesh.part is not None:
        ok &= mesh.part == mesh.part[int(np.argmin(np.linalg.norm(rel, axis=1)))]
    if not ok.any():
        return point
    i = np.flatnonzero(ok)
    return v[i[np.argmax(depth[i])]]


def _lower_lip_front(
    mesh: HeadMesh, mvp: np.ndarray, inner: np.ndarray, edge: np.ndarray, forward: np.ndarray, iod: float
) -> np.ndarray | None:
    """``lower_lip`` (3,): the lowest point of the lower lip's front on the midline (LOWER_LIP_FLAT; front along
    the face's ``forward`` (3,)), cast from the pixels from ``inner`` (MediaPipe 14) to ``edge`` (MediaPipe 17),
    both (2,); None when nothing is hit."""
    s = np.linspace(0.0, 1.0, LOWER_LIP_STEPS + 1)[:, None]
    hit = _cast(mesh, mvp, inner[None, :] * (1.0 - s) + edge[None, :] * s, SIZE)
    ok = np.isfinite(hit).all(axis=1)
    if not ok.any():
        return None
    front = hit @ forward
    best = np.nanmax(np.where(ok, front, np.nan))
    last = np.flatnonzero(ok & (front >= best - LOWER_LIP_FLAT * iod))[-1]
    return hit[last]


def _refined(
    mesh: HeadMesh, mvp: np.ndarray, pixels: dict[str, np.ndarray], points: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """``points`` with the mouth corners moved into the lips' crease and the lower lip at its front's lowest
    point (see CORNER_DEPTH, LOWER_LIP_FLAT): the definitions of docs/animation.md, "Landmarks". Up and forward
    are the face frame's (:func:`realtime_core.face.model.face_frame`) of the points as cast."""
    eyes = [0.5 * (points[f"eye_outer_{s}"] + points[f"eye_inner_{s}"]) for s in ("left", "right")]
    mouth = 0.5 * (points["corner_left"] + points["corner_right"])
    frame = face_frame_at(eye_left=eyes[0], eye_right=eyes[1], mouth=mouth)
    iod, up, forward = frame.iod, frame.axes[1], frame.axes[2]
    out = dict(points)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    inner = [int(np.argmin(np.linalg.norm(v - points[k], axis=1))) for k in ("upper_inner", "lower_inner")]
    if not lips_connected(v, mesh.triangles, inner[0], inner[1], iod=iod):
        # Only lips modelled apart tuck their corners in; closed lips' seam ends where the corner is seen (on
        # the untextured render of Lee Perry-Smith a corner pixel lies 2 edges from the seam's crease, and
        # moving it 0.09 IOD into the crease tore that corner at /a/, /u/ and /m/).
        crease = _crease_vertices(mesh, up)
        for k in ("corner_left", "corner_right"):
            out[k] = _into_corner_crease(mesh, mvp, pixels[k], points[k], crease, iod)
    lower = _lower_lip_front(mesh, mvp, pixels["lower_inner"], pixels["lower_lip"], forward, iod)
    if lower is not None:
        out["lower_lip"] = lower
    return out


TURNED_DEGREES = 5.0
"""A face whose eye line is turned more than this (yaw and roll) from the render's horizontal is found again on a
render looking straight at it (:func:`_facing_axes`). MediaPipe's points on a turned face, cast back along the
file's axis, lie elsewhere on the mesh: Lee Perry-Smith turned 25 degrees (yaw) and 10 (pitch) in its file gave
points up to 0.11 IOD (the far eye's outer corner, the chin) from the straight file's, and its lip cut 82 vertices
long instead of 49 (docs/animation.md, "Held-out heads", branch i12new). Files made straight keep their render, and
their points, to the bit: the cast eye lines of Lee Perry-Smith (0.3 degrees), the MediaPipe face (0.9), the
avatar (0.6) and the stylised head (2.4, its eye corners found on a cartoon face)."""


@dataclass(frozen=True)
class Look:
    """How :func:`_located` looks at a head: the render's ``config`` (its lighting), the views of it MediaPipe runs on
    (``zooms``, :data:`VIEW_ZOOMS`) and whether each is also mirrored."""

    config: RenderConfig
    zooms: tuple[tuple[float, float, float], ...]
    mirrored: bool


STEADY = Look(
    config=RenderConfig(width=SIZE, height=SIZE, samples=4, lighting="frontal"), zooms=VIEW_ZOOMS, mirrored=True
)
"""The first alternative's look: mirror-symmetric light, eight views, their median (docs/animation.md, "Steadier
automatic landmarks"). The untextured Lee Perry-Smith mirrored fails every rig from the PLAIN set (44 flips) and passes
from this one; as the found set it made three test-set heads fail every try (Lee Perry-Smith textured, the 3,810 and
1,428 copies: corners and lips 0.02-0.03 IOD away), so it is not the found set."""
PLAIN = Look(config=RenderConfig(width=SIZE, height=SIZE, samples=4), zooms=((1.0, 0.0, 0.0),), mirrored=False)
"""The found set's look (the finder's until RIG_ALGORITHM 73 too): the studio-lit render, MediaPipe once. Every head
of the test set rigs from its points."""


def _framed(
    mesh: HeadMesh, centre: np.ndarray, axes: np.ndarray, size: float, look: Look
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray], list[np.ndarray]] | None:
    """(the render's mvp, the landmarks' pixels, their points cast on ``mesh``, each view's pixels (12, 2) in
    MEDIAPIPE_INDEX's order) from a render of ``mesh`` framed on ``centre`` (``size`` wide) along ``axes``: the
    pixels are the median of MediaPipe's on its views (:func:`_views`, as ``look`` says); None when no face is found or
    a point misses the mesh."""
    from clients.render.renderer import HeadRenderer

    with HeadRenderer(mesh, centre=centre, axes=axes, size=size, config=look.config) as r:
        views = _views(r.render(), look.zooms, look.mirrored)
        mvp = r.mvp
    if not views:
        return None
    names = list(MEDIAPIPE_INDEX)
    each = [p[[MEDIAPIPE_INDEX[k] for k in names]] for p in views]
    pix = np.median(np.stack(each), axis=0)
    p3 = _cast(mesh, mvp, pix, SIZE)
    if np.isnan(p3).any():
        return None
    return mvp, dict(zip(names, pix)), dict(zip(names, p3)), each


def _facing_axes(points: dict[str, np.ndarray], axes: np.ndarray) -> np.ndarray | None:
    """Render axes (3, 3) (rows x, up, towards the camera) whose x is the face's eye line (from the cast eye
    corners) and whose view is the old one's turned about the new up only, or None when the eye line lies within
    TURNED_DEGREES of ``axes[0]``. The pitch is kept: the eye-mouth plane leans back by a face's own shape, so it
    does not tell how far the file tilts the head."""
    eyes = [0.5 * (points[f"eye_outer_{s}"] + points[f"eye_inner_{s}"]) for s in ("left", "right")]
    x = eyes[0] - eyes[1]
    x = x / np.linalg.norm(x)
    if float(x @ axes[0]) >= np.cos(np.radians(TURNED_DEGREES)):
        return None
    fwd = axes[2] - x * float(axes[2] @ x)
    fwd = fwd / np.linalg.norm(fwd)
    return np.stack([x, np.cross(fwd, x), fwd])


ALTERNATIVES = 3
"""How many other landmark sets :func:`find_landmarks` gives besides the PLAIN look's: the STEADY look's median, its
plain view's and its plain mirrored view's (fewer where they coincide). A rig from the found set that fails its checks
is made again from these in turn (assets.heads.head.rig_checked)."""


def _placed(
    mesh: HeadMesh, mvp: np.ndarray, pix: np.ndarray, forward: np.ndarray, face_piece: np.ndarray
) -> dict[str, list[float]] | None:
    """The twelve landmarks (name -> [x, y, z]) from their pixels ``pix`` (12, 2) in MEDIAPIPE_INDEX's order on the
    render ``mvp``: cast, then taken to facecast's definitions (:func:`_onto_lips` with the mesh's ``face_piece``,
    :func:`_refined`); None when a pixel misses the mesh."""
    names = list(MEDIAPIPE_INDEX)
    p3 = _cast(mesh, mvp, pix, SIZE)
    if np.isnan(p3).any():
        return None
    pixels = dict(zip(names, pix))
    found = _onto_lips(mesh, mvp, pixels, dict(zip(names, p3)), forward, face_piece)
    found = _refined(mesh, mvp, pixels, found)
    return {k: found[k].tolist() for k in names}


def _alternatives(
    mesh: HeadMesh, mvp: np.ndarray, each: list[np.ndarray], forward: np.ndarray, chosen: dict, face_piece: np.ndarray
) -> list[dict[str, list[float]]]:
    """Landmark sets from the plain view and the plain mirrored view (``each``, (12, 2) pixels, VIEW_ZOOMS' order,
    unmirrored first), none equal to ``chosen`` (the found set) or to one another."""
    picks = [0, len(each) // 2 if len(each) > 1 else 0]
    out: list[dict[str, list[float]]] = []
    for i in dict.fromkeys(picks):
        got = _placed(mesh, mvp, each[i], forward, face_piece)
        if got is not None and got != chosen and got not in out:
            out.append(got)
    return out[:ALTERNATIVES]


def _located(
    mesh: HeadMesh, centre: np.ndarray, axes: np.ndarray, span: float, look: Look
) -> tuple[HeadMesh, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]] | None:
    """One look at ``mesh`` framed on ``centre`` (``span`` wide) along ``axes``, then re-framed on the face found and
    turned to face it (:func:`_facing_axes`): (the mesh as wound for the view, its axes, the render's mvp, the
    landmarks' median pixels (12, 2) in MEDIAPIPE_INDEX's order, each view's), or None when no face is found."""
    from clients.render.renderer import HeadRenderer

    with HeadRenderer(mesh, centre=centre, axes=axes, size=span, config=look.config) as r:
        seen = _views(r.render(), look.zooms[:1], look.mirrored)
        if not seen:
            return None
        # Re-frame on the face for steadier points (framed alike on the render and its mirror image).
        face = _cast(mesh, r.mvp, np.mean(seen, axis=0)[[1, 10, 152, 234, 454]], SIZE)
    if np.isnan(face).any():
        return None
    fc = face.mean(0)
    fspan = float(np.linalg.norm(face[3] - face[4])) * 1.6
    got = _framed(mesh, fc, axes, fspan, look)
    if got is None:
        return None
    turned = _facing_axes(got[2], axes)
    if turned is not None:  # a head turned in its file: look again, straight at its face
        facing = facing_viewer(mesh, turned)
        again = _framed(facing, fc, turned, fspan, look)
        if again is not None:
            got, axes, mesh = again, turned, facing
    mvp, pixels, _, each = got
    return mesh, axes, mvp, np.stack([pixels[k] for k in MEDIAPIPE_INDEX]), each


def _searched(mesh: HeadMesh, face_piece: np.ndarray) -> FoundLandmarks | None:
    """:func:`find_landmarks`' search over the usual orientations and framings of ``mesh`` as drawn (``face_piece``: its
    :func:`_face_pieces`); None when no face is found on any of its renders."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    for up, fwd in ORIENTATIONS:
        axes = _axes(np.array(up, float), np.array(fwd, float))
        mesh = facing_viewer(mesh, axes)
        q = v @ axes.T
        lo, hi = q.min(0), q.max(0)
        height = hi[1] - lo[1]
        # Whole mesh, then its top (a full-body avatar's head), then the top fifth.
        for top in (1.0, 0.25, 0.12):
            y0 = hi[1] - top * height
            sel = q[:, 1] >= y0
            c_q = 0.5 * (q[sel].min(0) + q[sel].max(0))
            span = float(max(np.ptp(q[sel, 0]), np.ptp(q[sel, 1])))
            centre = c_q @ axes
            # The found set is the PLAIN look's (one studio-lit render: every head that rigged from it still
            # rigs the same); the STEADY look's median and single views are its alternatives, rigged from only
            # when every rig from the found set fails (assets.heads.head.rig_checked).
            plain = _located(mesh, centre, axes, span, PLAIN)
            if plain is None:
                continue
            p_mesh, p_axes, p_mvp, p_pix, _ = plain
            found = _placed(p_mesh, p_mvp, p_pix, np.asarray(p_axes[2], np.float64), face_piece)
            if found is None:
                continue
            others: list[dict[str, list[float]]] = []
            steady = _located(mesh, centre, axes, span, STEADY)
            if steady is not None:
                seen, s_axes, mvp, median, each = steady
                forward = np.asarray(s_axes[2], np.float64)
                middle = _placed(seen, mvp, median, forward, face_piece)
                if middle is not None and middle != found:
                    others.append(middle)
                for single in _alternatives(seen, mvp, each, forward, found, face_piece):
                    if single not in others:
                        others.append(single)
            return FoundLandmarks(found, tuple(others[:ALTERNATIVES]))
    return None


def find_landmarks(mesh: HeadMesh) -> FoundLandmarks:
    """The twelve landmarks as [x, y, z] points on ``mesh`` (file units), with other plausible sets of them as its
    ``alternatives`` (:data:`ALTERNATIVES`). LandmarkError when no face is found.

    The found set: MediaPipe on one studio-lit render (:data:`PLAIN`). The first alternative: the render lit
    mirror-symmetrically, MediaPipe on several views of it and their mirror images (:data:`STEADY`, :func:`_views`),
    each point's pixel the views' median, cast once; then single views' sets."""
    from clients.errors import RenderError

    try:
        face_piece = _face_pieces(mesh)  # the same for every render's mesh: welded once
        found = _searched(mesh, face_piece)
        if found is None and (mesh.colors is not None or mesh.texture is not None):
            # Its own colours hide the face from MediaPipe (a dense-correspondence template painted by position in
            # rainbow hues: menpo3d's template.ply), so look at its shape alone, drawn as plain skin. Only after the
            # painted look fails: every head found so far is found as before.
            found = _searched(replace(mesh, colors=None, texture=None, uvs=None), face_piece)
        if found is not None:
            return found
    except RenderError as exc:
        raise LandmarkError(
            f"{mesh.name}: cannot render the head to find its landmarks ({exc}); give --landmarks L.json"
        ) from exc
    raise LandmarkError(
        f"{mesh.name}: no face-like region found on renders of the head (stylised or not human-like?); "
        "give --landmarks L.json (see docs/heads.md, 'Landmarks')"
    )
