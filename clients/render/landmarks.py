"""Automatic landmarks for human-like heads: render the head, find the face with MediaPipe, cast back.

1. Render the mesh offscreen (:class:`clients.render.renderer.HeadRenderer`, EGL) from the front,
   trying the usual orientations in turn (glTF's +y up / face towards +z first, then -z, +x, -x,
   and z-up files), framed on the whole mesh and, for full-body avatars, on its top.
2. Run MediaPipe Face Mesh (``mediapipe`` 0.10.14, legacy ``solutions.face_mesh``, static image mode)
   on the render: 468 points in pixels.
3. Re-render framed on the detected face (a larger face gives steadier points) and detect again.
4. Cast each needed point back onto the mesh: the mesh triangles are projected with the renderer's
   camera; the front-most triangle under the pixel gives the 3D point (barycentric interpolation).

The twelve facecast landmarks are MediaPipe indices (the subject's own left/right, as facecast):
eye corners 263/362 (left) and 33/133 (right), nose tip 1, mouth corners 291 (left) / 61 (right),
outer lips 0/17, inner lips 13/14, chin 152. Raises LandmarkError naming the file when no face is
found ("give --landmarks").
"""

from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import replace

import numpy as np

from assets.errors import LandmarkError
from assets.heads.mesh import HeadMesh

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
INNER_LIP_STEPS = 32  # pixels tried between an inner-lip point and its outer lip point

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


@contextlib.contextmanager
def _native_stderr_quiet():
    """Silence file descriptor 2 for a block: MediaPipe's C++ runtime logs warnings there (TFLite
    "feedback manager" lines) that would bury the one-line error a user gets when no face is found."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def _detect(image: np.ndarray) -> np.ndarray | None:
    """(468, 2) pixel coordinates of the face in an RGB image, or None."""
    import mediapipe as mp

    with (
        _native_stderr_quiet(),
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
    from realtime_core.face.interpolation import barycentric_2d

    v = np.asarray(mesh.vertices, dtype=np.float64)
    clip = np.c_[v, np.ones(len(v))] @ mvp.T
    w = clip[:, 3]
    px = np.c_[(clip[:, 0] / w + 1) / 2 * size, (1 - clip[:, 1] / w) / 2 * size]
    t = np.asarray(mesh.triangles, dtype=np.int64)
    out = np.full((len(pixels), 3), np.nan)
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
    return out


def _onto_lips(
    mesh: HeadMesh, mvp: np.ndarray, pixels: dict[str, np.ndarray], points: dict[str, np.ndarray], forward: np.ndarray
) -> dict[str, np.ndarray]:
    """``points`` (name -> (3,), as cast from ``pixels``, name -> (2,)) with each inner-lip point that went
    through the lips (INNER_LIP_DEPTH) moved to the first point on the lip surface met on the pixel segment
    from it to its outer lip midpoint's pixel; left as it is when none is found (the rig checks then judge)."""
    eyes = [0.5 * (points[f"eye_outer_{s}"] + points[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    front = min(float(points[k] @ forward) for k in INNER_LIP_OUTER.values())
    out = dict(points)
    for inner, outer in INNER_LIP_OUTER.items():
        if float(points[inner] @ forward) >= front - INNER_LIP_DEPTH * iod:
            continue
        s = np.linspace(0.0, 1.0, INNER_LIP_STEPS + 1)[1:, None]
        line = pixels[inner][None, :] * (1.0 - s) + pixels[outer][None, :] * s
        hit = _cast(mesh, mvp, line, SIZE)
        on_lip = np.flatnonzero(np.isfinite(hit).all(axis=1) & (hit @ forward >= front - INNER_LIP_DEPTH * iod))
        if len(on_lip):
            out[inner] = hit[on_lip[0]]
    return out


def find_landmarks(mesh: HeadMesh) -> dict[str, list[float]]:
    """The twelve landmarks as [x, y, z] points on ``mesh`` (file units). LandmarkError when no face is found."""
    from clients.errors import RenderError
    from clients.render.renderer import HeadRenderer, RenderConfig

    v = np.asarray(mesh.vertices, dtype=np.float64)
    cfg = RenderConfig(width=SIZE, height=SIZE, samples=4)
    try:
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
                with HeadRenderer(mesh, centre=centre, axes=axes, size=span, config=cfg) as r:
                    pts = _detect(r.render())
                    if pts is None:
                        continue
                    # Re-frame on the face for steadier points.
                    face = _cast(mesh, r.mvp, pts[[1, 10, 152, 234, 454]], SIZE)
                if np.isnan(face).any():
                    continue
                fc = face.mean(0)
                fspan = float(np.linalg.norm(face[3] - face[4])) * 1.6
                with HeadRenderer(mesh, centre=fc, axes=axes, size=fspan, config=cfg) as r:
                    pts2 = _detect(r.render())
                    use = pts2 if pts2 is not None else None
                    if use is None:
                        continue
                    names = list(MEDIAPIPE_INDEX)
                    pix = use[[MEDIAPIPE_INDEX[k] for k in names]]
                    p3 = _cast(mesh, r.mvp, pix, SIZE)
                    if np.isnan(p3).any():
                        continue
                    found = _onto_lips(
                        mesh, r.mvp, dict(zip(names, pix)), dict(zip(names, p3)), np.asarray(axes[2], np.float64)
                    )
                return {k: found[k].tolist() for k in names}
    except RenderError as exc:
        raise LandmarkError(
            f"{mesh.name}: cannot render the head to find its landmarks ({exc}); give --landmarks L.json"
        ) from exc
    raise LandmarkError(
        f"{mesh.name}: no face-like region found on renders of the head (stylised or not human-like?); "
        "give --landmarks L.json (see docs/animation.md, 'Landmarks')"
    )
