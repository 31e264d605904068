"""Picture of the control points on a head (like paper 000 Fig. 5), written as PNG with matplotlib."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from realtime_core.face import Rig, face_frame


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
