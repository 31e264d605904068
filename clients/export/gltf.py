"""A binary glTF 2.0 (``.glb``) of the head with the animation as morph-target weights.

The rig is linear: ``rig.deformed(p) = neutral + sum_j p_j * D_j`` where ``D_j`` (n, 3) is the head
displacement for a unit value (1 IOD) of mouth parameter j (zero on vertices the rig cannot move).
So the four ``D_j`` are exact morph targets and the parameter curves are exact morph weights: any
glTF player (three.js, Blender, Unity's glTFast, ...) reproduces facecast's deformation. The weights
are in IOD and may be negative or exceed 1 (glTF does not clamp morph weights).

Layout: one node "head" with one mesh (POSITION, NORMAL-free, TEXCOORD_0 + embedded texture or COLOR_0
when the head has them, uint32 indices, vertex order kept), ``mesh.extras.targetNames`` (the
convention three.js and Blender read) and one animation whose LINEAR sampler maps the frame times
(s, from 0) to the weights. ``asset.extras.facecast`` names the audio file written beside the .glb.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from clients.export.errors import ExportError
from realtime_core.track import Track

_FLOAT, _UINT32 = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def rig_targets(rig) -> np.ndarray:
    """Morph targets (4, n, 3) float32 of a :class:`realtime_core.face.Rig`: the head displacement
    (mesh units) per unit (1 IOD) of each mouth parameter."""
    n = len(rig.neutral)
    out = np.zeros((4, n, 3), dtype=np.float32)
    for j in range(4):
        e = np.zeros(4, dtype=np.float32)
        e[j] = 1.0
        out[j, rig.moving] = rig.displacements(e)
    return out


def _image_mime(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg"
    raise ExportError("texture must be PNG or JPEG bytes")


class _Buffer:
    """Accumulates buffer views and accessors of the single GLB binary chunk."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        view = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        pad = b"\x00" * (-len(data) % 4)  # every view starts 4-byte aligned (float32 accessors)
        self.blobs.append(data + pad)
        self.size += len(data) + len(pad)
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, kind: str, ctype: int, target: int | None, minmax: bool = False) -> int:
        acc = {"bufferView": self.view(arr.tobytes(), target), "componentType": ctype, "count": int(len(arr)), "type": kind}
        if minmax:
            a = arr.reshape(len(arr), -1)
            acc["min"] = [float(x) for x in a.min(axis=0)]
            acc["max"] = [float(x) for x in a.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def animated_glb(*, vertices: np.ndarray, triangles: np.ndarray, targets: np.ndarray, target_names: tuple[str, ...],
                 track: Track, uvs: np.ndarray | None = None, colors: np.ndarray | None = None,
                 texture: bytes | None = None, audio: str | None = None) -> bytes:
    """GLB bytes. vertices (n, 3) neutral positions (mesh units); triangles (m, 3) vertex indices;
    targets (T, n, 3) displacement per unit weight; target_names (T,); track: weights (F, T) at
    its frame times (the animation starts at 0 s = the track's first frame); uvs (n, 2) with texture
    (PNG/JPEG bytes) or colors (n, 3) in [0, 1]; audio: file name recorded in asset.extras."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    t = np.ascontiguousarray(triangles, dtype="<u4")
    d = np.ascontiguousarray(targets, dtype="<f4")
    n = len(v)
    if v.ndim != 2 or v.shape[1] != 3 or n == 0:
        raise ExportError(f"vertices must be (n, 3), got {v.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0 or t.max() >= n:
        raise ExportError(f"triangles must be (m, 3) indices below {n}")
    if d.ndim != 3 or d.shape[1:] != (n, 3) or d.shape[0] != len(target_names):
        raise ExportError(f"targets must be ({len(target_names)}, {n}, 3), got {d.shape}")
    if track.values.shape[1] != len(target_names):
        raise ExportError(f"the track has {track.values.shape[1]} curves for {len(target_names)} targets")
    if track.n_frames == 0:
        raise ExportError("the track has no frames")
    buf = _Buffer()
    attributes = {"POSITION": buf.accessor(v, "VEC3", _FLOAT, _ARRAY_BUFFER, minmax=True)}
    material: dict = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.8}, "doubleSided": True}
    doc: dict = {"asset": {"version": "2.0", "generator": "facecast",
                           "extras": {"facecast": {"audio": audio, "fps": track.fps, "units": "IOD",
                                                   "curves": list(target_names)}}}}
    if uvs is not None:
        attributes["TEXCOORD_0"] = buf.accessor(np.ascontiguousarray(uvs, dtype="<f4"), "VEC2", _FLOAT, _ARRAY_BUFFER)
    if colors is not None:
        attributes["COLOR_0"] = buf.accessor(np.ascontiguousarray(colors, dtype="<f4"), "VEC3", _FLOAT, _ARRAY_BUFFER)
    if texture is not None and uvs is not None:
        doc["images"] = [{"bufferView": buf.view(texture), "mimeType": _image_mime(texture)}]
        doc["textures"] = [{"source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    morphs = [{"POSITION": buf.accessor(d[j], "VEC3", _FLOAT, _ARRAY_BUFFER, minmax=True)} for j in range(len(d))]
    indices = buf.accessor(t.reshape(-1), "SCALAR", _UINT32, _ELEMENT_ARRAY_BUFFER)
    times = np.ascontiguousarray(np.arange(track.n_frames) / track.fps, dtype="<f4")
    weights = np.ascontiguousarray(track.values, dtype="<f4").reshape(-1)  # frame-major: F x T scalars
    t_in = buf.accessor(times, "SCALAR", _FLOAT, None, minmax=True)  # glTF requires min/max on inputs
    w_out = buf.accessor(weights, "SCALAR", _FLOAT, None)
    body = b"".join(buf.blobs)
    doc.update({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "head"}],
        "meshes": [{"name": "head", "primitives": [{"attributes": attributes, "indices": indices, "material": 0,
                                                     "targets": morphs}],
                    "weights": [0.0] * len(d), "extras": {"targetNames": list(target_names)}}],
        "materials": [material],
        "animations": [{"name": "speech", "samplers": [{"input": t_in, "output": w_out, "interpolation": "LINEAR"}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}],
        "buffers": [{"byteLength": len(body)}],
        "bufferViews": buf.views,
        "accessors": buf.accessors,
    })
    js = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()
    js += b" " * (-len(js) % 4)  # the JSON chunk is padded with spaces, the binary chunk with zeros
    total = 12 + 8 + len(js) + 8 + len(body)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(body), b"BIN\x00") + body)


def head_glb(rig, mesh, track: Track, *, audio: str | None = None) -> bytes:
    """:func:`animated_glb` of a rigged head (``rig`` and its :class:`assets.heads.mesh.HeadMesh`)."""
    from realtime_core import VISUAL_PARAMS

    if len(mesh.vertices) != len(rig.neutral):
        raise ExportError(f"mesh has {len(mesh.vertices)} vertices, its rig {len(rig.neutral)}")
    return animated_glb(vertices=rig.neutral, triangles=mesh.triangles, targets=rig_targets(rig),
                        target_names=VISUAL_PARAMS, track=track, uvs=mesh.uvs, colors=mesh.colors,
                        texture=mesh.texture if mesh.uvs is not None else None, audio=audio)


def builtin_arkit_targets() -> dict[str, np.ndarray]:
    """The built-in head's 52 ARKit blendshapes: name -> (n, 3) float64 displacement (mesh units) at
    weight 1, in the vertex order of ``builtin_rig()``'s mesh (both come from the same cut head)."""
    from assets.heads.builtin import load_builtin_head

    return load_builtin_head().targets


def arkit_glb(mesh, targets: dict[str, np.ndarray], track: Track, *, audio: str | None = None) -> bytes:
    """:func:`animated_glb` with ARKit's 52 blendshapes as the morph targets (Apple's order) and the
    track's mouth parameters mapped to their weights by ``realtime_core.blendshapes`` (the same
    weights a "blendshapes" viewer receives, in [0, 1]); for engines that drive faces by ARKit names.
    ``mesh``: the HeadMesh; ``targets``: name -> (n, 3) displacement at weight 1 for all 52 names."""
    from realtime_core import VISUAL_PARAMS
    from realtime_core.blendshapes import ARKIT_NAMES, blendshape_weights

    missing = sorted(set(ARKIT_NAMES) - set(targets))
    if missing:
        raise ExportError(f"the head lacks ARKit blendshapes {missing[:5]}{'...' if len(missing) > 5 else ''}")
    if track.names != VISUAL_PARAMS:
        raise ExportError(f"ARKit weights are computed from the mouth parameters {VISUAL_PARAMS}")
    weights = Track(values=blendshape_weights(track.values, "arkit52"), fps=track.fps, start_s=track.start_s,
                    names=ARKIT_NAMES)
    return animated_glb(vertices=mesh.vertices, triangles=mesh.triangles,
                        targets=np.stack([targets[n] for n in ARKIT_NAMES]), target_names=ARKIT_NAMES,
                        track=weights, uvs=mesh.uvs, colors=mesh.colors,
                        texture=mesh.texture if mesh.uvs is not None else None, audio=audio)
