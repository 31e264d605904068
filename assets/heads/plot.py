"""Picture of the control points on a head (like paper 000 Fig. 5), written as PNG with matplotlib."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from realtime_core.face import Rig, face_frame


def check_picture_path(path: str | Path) -> Path:
    """``path`` as a Path, or MeshError naming it when matplotlib cannot write its suffix (checked before
    rigging, which takes minutes, rather than failing in savefig with a traceback)."""
    from matplotlib.backend_bases import FigureCanvasBase

    from assets.errors import MeshError

    p = Path(path)
    known = FigureCanvasBase.get_supported_filetypes()
    if p.suffix.lower().lstrip(".") not in known:
        raise MeshError(f"{p}: not a picture file name; use .png (or {', '.join(f'.{k}' for k in sorted(known))})")
    return p


def plot_control_points(
    rig: Rig,
    path: str | Path,
    *,
    title: str = "",
    credit: str = "",
    image: np.ndarray | None = None,
    pixels: np.ndarray | None = None,
) -> Path:
    """Frontal view (face frame) of the head vertices (grey), moving vertices (light blue), the
    simple-model triangles on their control points (black) and the control points (red).

    With ``image`` (h, w, 3) uint8, a render of the head, and ``pixels`` (n_simple, 2), the control
    points' pixel positions in it, the triangles and points are drawn over the render instead.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from assets.heads.rigging import mouth_landmarks

    v = np.asarray(rig.neutral, dtype=np.float64)
    simple_lm = rig.meta.get("simple_landmarks")
    frame = None
    if simple_lm:
        sv = rig.simple.vertices
        frame = face_frame(sv, mouth_landmarks(simple_lm))
    if frame is None:
        ax3 = np.eye(3)
        origin = v.mean(0)
        iod = float(np.ptp(v[:, 0])) / 3
    else:
        ax3, origin, iod = frame.axes, frame.origin, frame.iod
    q = (v - origin) @ ax3.T / iod
    front = q[:, 2] > np.percentile(q[:, 2], 35)
    c = q[rig.control]
    if image is not None and pixels is not None:
        h, w = image.shape[:2]
        fig, ax = plt.subplots(figsize=(w / 100, h / 100 + 0.4), dpi=100)
        ax.imshow(image)
        ax.triplot(pixels[:, 0], pixels[:, 1], rig.simple.triangles, color="k", lw=0.4, alpha=0.7)
        ax.scatter(pixels[:, 0], pixels[:, 1], s=5, c="red", zorder=3)
        ax.set_axis_off()
        ax.set_title(title or f"{len(rig.control)} control points, {len(rig.moving)} moving vertices", fontsize=9)
        if credit:
            fig.text(0.01, 0.01, credit, fontsize=7, color="k")
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, bbox_inches="tight")
        plt.close(fig)
        return path
    fig, ax = plt.subplots(figsize=(6, 7), dpi=110)
    ax.scatter(q[front, 0], q[front, 1], s=0.3, c="0.75")
    mv = np.zeros(len(v), dtype=bool)
    mv[rig.moving] = True
    ax.scatter(q[front & mv, 0], q[front & mv, 1], s=0.3, c="#9ecae1")
    ax.triplot(c[:, 0], c[:, 1], rig.simple.triangles, color="k", lw=0.4)
    ax.scatter(c[:, 0], c[:, 1], s=6, c="red", zorder=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x (IOD)")
    ax.set_ylabel("y (IOD)")
    ax.set_title(title or f"{len(rig.control)} control points, {len(rig.moving)} moving vertices", fontsize=9)
    if credit:
        fig.text(0.01, 0.01, credit, fontsize=7)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


LANDMARK_HELP: dict[str, str] = {
    "eye_outer_left": "outer corner of the face's LEFT eye (viewer's right)",
    "eye_inner_left": "inner corner of the face's left eye",
    "eye_outer_right": "outer corner of the face's RIGHT eye (viewer's left)",
    "eye_inner_right": "inner corner of the face's right eye",
    "nose_tip": "tip of the nose (most forward point)",
    "corner_left": "mouth corner on the face's left",
    "corner_right": "mouth corner on the face's right",
    "upper_lip": "outer midpoint of the upper lip (vermilion border)",
    "lower_lip": "outer midpoint of the lower lip",
    "upper_inner": "inner midpoint of the upper lip (where the lips part)",
    "lower_inner": "inner midpoint of the lower lip (closed lips: the same vertex as upper_inner)",
    "chin": "lowest point of the chin on the midline",
}
"""Each landmark's definition, in the order of landmark files (``assets.heads.rigging.REQUIRED_LANDMARKS``)."""


LABEL_GAP_IOD = 0.14
"""Vertical distance between the stacked labels of the points on the face's midline (IOD)."""
LABEL_COLUMN_IOD = 0.6
"""x of the midline points' labels (IOD right of the midline): past the mouth corners (~0.4), inside the eyes."""


def _label_places(p: np.ndarray) -> list[tuple[float, float]]:
    """Where each landmark's number goes, (x, y) in the picture's IOD units, p (n, 2): beside a point off the midline;
    for the points on it (nose, the four lip midpoints, chin: 0.05-0.1 IOD apart on a mouth, their numbers overlapped)
    a column at LABEL_COLUMN_IOD, one LABEL_GAP_IOD apart in the points' top-down order, joined to them by leader
    lines; a point level with a mouth corner gets its label 0.3 IOD below the corner, so that its line passes under
    the corner, not through it."""
    mid = np.abs(p[:, 0]) < 0.2
    places = [(float(x) + (0.08 if x >= 0 else -0.08), float(y) + 0.06) for x, y in p]
    below = np.inf
    for i in sorted(np.flatnonzero(mid), key=lambda i: -p[i, 1]):
        y = float(p[i, 1]) - 0.1
        level = p[~mid, 1][np.abs(p[~mid, 1] - p[i, 1]) < 0.3]  # a mouth corner beside it
        if level.size:
            y = min(y, float(level.min()) - 0.3)
        y = min(y, below - LABEL_GAP_IOD)
        places[i] = (LABEL_COLUMN_IOD, y)
        below = y
    return places


def plot_landmarks(mesh, points: dict[str, np.ndarray], path: str | Path, *, title: str = "") -> Path:
    """Frontal picture of the head (its vertices shaded by depth) with each landmark numbered and
    named, and the definitions beside it. mesh: a HeadMesh; points: name -> (3,) position."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from realtime_core.face import MouthLandmarks

    names = [k for k in LANDMARK_HELP if k in points]
    pv = np.stack([np.asarray(points[k], dtype=np.float64) for k in names])
    lm = MouthLandmarks(**{k: names.index(k) for k in MouthLandmarks.__dataclass_fields__})
    fr = face_frame(pv, lm)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    q = (v - fr.origin) @ fr.axes.T / fr.iod
    near = (np.abs(q[:, 0]) < 1.6) & (q[:, 1] > -2.6) & (q[:, 1] < 1.2) & (q[:, 2] > -1.5)
    p = (pv - fr.origin) @ fr.axes.T / fr.iod
    fig, (ax, tx) = plt.subplots(1, 2, figsize=(11, 6.5), dpi=110, gridspec_kw={"width_ratios": [1.1, 1]})
    order = np.argsort(q[near, 2])
    ax.scatter(q[near, 0][order], q[near, 1][order], s=1.2, c=q[near, 2][order], cmap="Greys")
    ax.scatter(p[:, 0], p[:, 1], s=28, c="red", zorder=3, edgecolors="white", linewidths=0.5)
    places = _label_places(p[:, :2])
    for i, xy in enumerate(places):
        ax.annotate(
            str(i),
            (p[i, 0], p[i, 1]),
            xytext=xy,
            fontsize=8,
            color="darkred",
            ha="left" if xy[0] >= p[i, 0] else "right",
            va="center",
            zorder=4,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85},
            arrowprops={"arrowstyle": "-", "color": "darkred", "lw": 0.6, "shrinkA": 0, "shrinkB": 3},
        )
    # the labels inside the plot (annotations do not widen its limits): the chin's may sit below the face
    xs, ys = np.array(places).T
    ax.set_xlim(min(ax.get_xlim()[0], xs.min() - 0.2), max(ax.get_xlim()[1], xs.max() + 0.2))
    ax.set_ylim(min(ax.get_ylim()[0], ys.min() - 0.1), max(ax.get_ylim()[1], ys.max() + 0.1))
    ax.set_aspect("equal")
    ax.set_xlabel("x (IOD), as a viewer sees the face: the face's left is on the right of the picture")
    ax.set_ylabel("y (IOD)")
    # wrapped to the plot's width: a long title (a landmark file's path) ran off the figure's left edge
    ax.set_title(textwrap.fill(title or "landmarks", 70), fontsize=9)
    tx.set_axis_off()
    lines = [f"{i:2d}  {k}: {LANDMARK_HELP[k]}" for i, k in enumerate(names)]
    lines += [
        "",
        "'left'/'right' are the face's own sides (a viewer sees the face's left on the right).",
        "Values: a vertex index (file order) or [x, y, z] in the file's units.",
        "Closed lips: upper_inner = lower_inner (the seam vertex); the mesh is cut there.",
    ]
    tx.text(0, 1, "\n".join(lines), va="top", fontsize=8, family="monospace", wrap=True)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
