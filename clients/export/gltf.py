"""Animated ``.glb`` exports of a :class:`realtime_core.track.Track`, written by the one glTF writer
:mod:`assets.heads.glb` (shared with the server's head download).

- :func:`head_glb`: a rigged head (a :class:`realtime_core.face.Rig`: its four exact parameter
  targets animated by the parameter curves in IOD; a :class:`realtime_core.face.keyframes.MorphRig`:
  the head's own morph targets animated by the weights it computes per frame).
- :func:`arkit_glb`: a head with all 52 ARKit targets animated by the ARKit weights facecast streams.
- :func:`morph_glb`: a head's own morph targets animated by weights given per frame (what ``facecast record``
  writes from a server's head and its "morph" frames, without the head's file).
``asset.extras.facecast`` names the audio file written beside the .glb.
"""

from __future__ import annotations

import numpy as np

from assets.errors import GlbError
from assets.heads import glb
from assets.heads.glb import rig_targets
from clients.export.errors import ExportError
from realtime_core.track import Track

__all__ = ["animated_glb", "arkit_glb", "builtin_arkit_targets", "head_glb", "morph_glb", "rig_targets"]


def animated_glb(
    *,
    vertices: np.ndarray,
    triangles: np.ndarray,
    targets: np.ndarray,
    target_names: tuple[str, ...],
    track: Track,
    uvs: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    texture: bytes | None = None,
    audio: str | None = None,
    units: str = "IOD",
    target_normals: bool = False,
) -> bytes:
    """:func:`assets.heads.glb.animated_glb` with the track's values as the weights (ExportError on bad input);
    ``units``: what the weights measure, recorded in ``asset.extras.facecast``; ``target_normals``: the targets
    carry NORMAL deltas (morph weights in [0, 1])."""
    try:
        return glb.animated_glb(
            vertices=vertices,
            triangles=triangles,
            targets=targets,
            target_names=target_names,
            weights=track.values,
            fps=track.fps,
            uvs=uvs,
            colors=colors,
            texture=texture,
            audio=audio,
            units=units,
            target_normals=target_normals,
        )
    except GlbError as exc:
        raise ExportError(str(exc)) from exc


def head_glb(rig, mesh, track: Track, *, audio: str | None = None, expression: np.ndarray | None = None) -> bytes:
    """The animated glb of a rigged head (``rig`` and its :class:`assets.heads.mesh.HeadMesh`); ``expression``
    (frames, E) intensities drive a MorphRig's face shapes (None: none)."""
    try:
        return glb.head_glb(rig, mesh, track.values, track.fps, audio=audio, expression=expression)
    except GlbError as exc:
        raise ExportError(str(exc)) from exc


def morph_glb(mesh, track: Track, *, audio: str | None = None) -> bytes:
    """The animated glb of a head driven by its own morph targets, from their weights per frame: ``mesh`` a
    :class:`assets.heads.mesh.HeadMesh` whose ``targets`` include every name of ``track.names`` (the weights, in [0, 1]
    but a lips-apart head's jaw below 0). The file :func:`head_glb` writes for a MorphRig from the parameters (the same
    writer, units and normals), here from the weights a server sent (its "morph" kind: docs/protocol.md). Normals
    without part seams: a served head carries no parts, and the browser viewer shades it so too."""
    targets = mesh.targets or {}
    missing = [n for n in track.names if n not in targets]
    if missing:
        more = "..." if len(missing) > 5 else ""
        raise ExportError(f"{mesh.name}: the head has no morph targets {missing[:5]}{more}")
    return animated_glb(
        vertices=mesh.vertices,
        triangles=mesh.triangles,
        targets=np.stack([np.asarray(targets[n], dtype=np.float32) for n in track.names]),
        target_names=track.names,
        track=track,
        uvs=mesh.uvs,
        colors=mesh.colors,
        texture=mesh.texture if mesh.uvs is not None else None,
        audio=audio,
        units="morph weight",
        target_normals=True,
    )


def builtin_arkit_targets() -> dict[str, np.ndarray]:
    """The built-in head's 52 ARKit blendshapes: name -> (n, 3) float64 displacement (mesh units) at
    weight 1, in the vertex order of ``builtin_rig()``'s mesh (both come from the same cut head)."""
    from assets.heads.builtin import load_builtin_head

    return load_builtin_head().targets


def arkit_glb(
    mesh,
    targets: dict[str, np.ndarray],
    track: Track,
    *,
    audio: str | None = None,
    expression: np.ndarray | None = None,
) -> bytes:
    """An animated glb with ARKit's 52 blendshapes as the morph targets (Apple's order) and the
    track's mouth parameters mapped to their weights by ``realtime_core.blendshapes`` (the same
    weights a "blendshapes" viewer receives, in [0, 1]); for engines that drive faces by ARKit names.
    ``mesh``: the HeadMesh; ``targets``: name -> (n, 3) displacement at weight 1 for all 52 names;
    ``expression``: ``(n_frames, len(EXPRESSIONS))`` intensities whose ARKit recipes are added to the
    weights (mouthSmile, brows, cheeks ...), as a live session's ARKit output does; ``track`` is then the
    speech parameters before the expression."""
    from realtime_core import VISUAL_PARAMS
    from realtime_core.blendshapes import ARKIT_NAMES, blendshape_weights

    missing = sorted(set(ARKIT_NAMES) - set(targets))
    if missing:
        raise ExportError(f"the head lacks ARKit blendshapes {missing[:5]}{'...' if len(missing) > 5 else ''}")
    if track.names != VISUAL_PARAMS:
        raise ExportError(f"ARKit weights are computed from the mouth parameters {VISUAL_PARAMS}")
    if expression is not None and np.shape(expression)[0] != len(track.values):
        raise ExportError(f"{np.shape(expression)[0]} expression rows for {len(track.values)} frames")
    weights = Track(
        values=blendshape_weights(track.values, "arkit52", expression=expression),
        fps=track.fps,
        start_s=track.start_s,
        names=ARKIT_NAMES,
    )
    return animated_glb(
        vertices=mesh.vertices,
        triangles=mesh.triangles,
        targets=np.stack([targets[n] for n in ARKIT_NAMES]),
        target_names=ARKIT_NAMES,
        track=weights,
        uvs=mesh.uvs,
        colors=mesh.colors,
        texture=mesh.texture if mesh.uvs is not None else None,
        audio=audio,
        units="morph weight",  # ARKit weights in [0, 1], as a morph head's own targets' glb says
        target_normals=True,
    )
