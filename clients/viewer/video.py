"""A recorded vertex-deltas stream rendered offscreen (moderngl on EGL) into an MP4 with its audio.

Reuses the offline renderer and video writer (:mod:`clients.render`). The camera frames the
vertices the rig can move (the description's moving_vertices), seen from +z with y up, the glTF
convention the built-in head follows; a head facing elsewhere is better watched in the browser,
whose camera orbits.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from assets.heads.mesh import HeadMesh
from clients.errors import ClientError
from clients.render.renderer import HeadRenderer, RenderConfig
from clients.render.video import VideoConfig, write_video
from clients.viewer.stream import Recording


def framing(vertices: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(centre (3,), axes (3, 3) rows x, y, z, size) for HeadRenderer: the box of the moving
    vertices (all when none), seen along -z; vertices (n, 3) mesh units, moving (k,) indices."""
    pts = vertices[moving] if len(moving) else vertices
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (lo + hi) / 2, np.eye(3), float(max(hi[1] - lo[1], (hi[0] - lo[0]) * 0.75))


def render_recording(
    rec: Recording, mesh: HeadMesh, out: str | Path, *, config: RenderConfig = RenderConfig(margin=1.25)
) -> tuple[Path, int]:
    """Write ``out`` (.mp4): one video frame per session frame (rec.fps), the relayed audio muxed
    in; returns (path, frames). ``rec`` must be a "deltas" recording of ``mesh``'s server."""
    from assets.files import atomic_write_bytes
    from clients.export.files import wav_bytes

    d = rec.description
    if d.get("kind") != "deltas" or not d.get("head"):
        raise ClientError("rendering needs a vertex-deltas recording of a server with a head")
    if d["head"]["vertex_count"] != len(mesh.vertices):
        raise ClientError(f"the served head has {d['head']['vertex_count']} vertices, the mesh {len(mesh.vertices)}")
    frames, first = rec.timeline()
    moving = np.asarray(d["head"]["moving_vertices"], dtype=np.int64)
    neutral = np.asarray(mesh.vertices, dtype=np.float32)
    centre, axes, size = framing(neutral, moving)
    audio = rec.audio_track(first / rec.fps, len(frames))
    work = np.empty_like(neutral)

    def draw(row: np.ndarray) -> np.ndarray:
        work[:] = neutral
        work[moving] += row.reshape(-1, 3)
        return r.render(work)

    with tempfile.TemporaryDirectory(prefix="facecast-view-") as tmp:
        wav = atomic_write_bytes(Path(tmp) / "audio.wav", wav_bytes(audio, rec.audio_rate_hz))
        with HeadRenderer(mesh, centre=centre, axes=axes, size=size, config=config) as r:
            path = write_video(
                frames, draw, out, size=(config.width, config.height), audio=wav, config=VideoConfig(fps=rec.fps)
            )
    return path, len(frames)
