"""The one glTF 2.0 binary (``.glb``) writer: the head for viewers to download, and animated heads for export.

Vertex order is kept exactly (no re-indexing), so moving-vertex indices and vertex deltas address
the written mesh directly. UVs are written as stored (glTF's convention, v down: facecast's own).

Every primitive carries smooth NORMALs of the neutral mesh (without them glTF clients shade flat), and a head's
own morph targets (weights in [0, 1]) carry NORMAL deltas (:func:`assets.heads.mesh.target_normal_deltas`), so
a viewer lights each pose as its shape rather than with the rest normals; vertex colours (sRGB in a HeadMesh) are
written linear, as glTF's COLOR_0 is read.

- :func:`mesh_glb` / :func:`mesh_json`: the static head the server offers (``/head/mesh``,
  ``/head/mesh.json``), with the head's morph targets when it has any.
- :func:`animated_glb`: a head whose morph targets are animated by one LINEAR sampler
  (``mesh.extras.targetNames``, the convention three.js and Blender read).
- :func:`head_glb`: the animated glb of a rigged head. A :class:`realtime_core.face.Rig` is linear
  but for its lip-contact push, ``deformed(p) = neutral + sum_j p_j D_j + sum_k c_k(p) C_k``: its four
  ``D_j`` animated by the parameter curves (IOD, may be negative) and one sparse target ``C_k`` per lip
  column animated by that column's crossing ``c_k(p)`` (head units, 0 unless the lips would cross).
  A :class:`realtime_core.face.keyframes.MorphRig` animates the head's own targets with the weights it
  computes per frame (in [0, 1]).
"""

from __future__ import annotations

import json
import struct
from dataclasses import replace

import numpy as np

from assets.errors import GlbError
from assets.heads.mesh import (
    CUTOUT_ALPHA,
    HeadMesh,
    srgb_to_linear,
    target_normal_deltas,
    texture_cutout,
    vertex_normals,
)

_FLOAT, _UINT32 = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def image_mime(data: bytes) -> str:
    """MIME type of PNG/JPEG bytes (GlbError otherwise)."""
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg"
    raise GlbError("texture must be PNG or JPEG bytes")


def texture_mime(mesh: HeadMesh) -> str | None:
    """MIME type of the mesh's texture, or None without one."""
    return None if mesh.texture is None else image_mime(mesh.texture)


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
        acc = {"bufferView": self.view(arr.tobytes(), target), "componentType": ctype, "count": len(arr), "type": kind}
        if minmax:
            a = arr.reshape(len(arr), -1)
            acc["min"] = [float(x) for x in a.min(axis=0)]
            acc["max"] = [float(x) for x in a.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def sparse_vec3(self, arr: np.ndarray) -> int:
        """A float32 VEC3 accessor (n, 3) stored as glTF sparse: no base view (zeros), the rows that are
        not zero as uint32 indices + values (a morph target that moves a few vertices of a large head)."""
        idx = np.flatnonzero(np.abs(arr).max(axis=1) > 0).astype("<u4")
        vals = np.ascontiguousarray(arr[idx], dtype="<f4")
        acc: dict = {
            "componentType": _FLOAT,
            "count": len(arr),
            "type": "VEC3",
            "min": [float(x) for x in arr.min(axis=0)],
            "max": [float(x) for x in arr.max(axis=0)],
        }
        if len(idx):  # glTF: sparse.count >= 1; an all-zero target is just the zero-initialised accessor
            acc["sparse"] = {
                "count": len(idx),
                "indices": {"bufferView": self.view(idx.tobytes()), "componentType": _UINT32},
                "values": {"bufferView": self.view(vals.tobytes())},
            }
        self.accessors.append(acc)
        return len(self.accessors) - 1


def glb_container(doc: dict, body: bytes = b"") -> bytes:
    """A GLB file of the glTF JSON ``doc`` and ``body``, its binary chunk (left out when empty): the header,
    then the JSON chunk padded with spaces and the binary chunk with zeros, each to 4 bytes."""
    js = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()
    js += b" " * (-len(js) % 4)
    body += b"\x00" * (-len(body) % 4)
    chunks = struct.pack("<I4s", len(js), b"JSON") + js
    if body:
        chunks += struct.pack("<I4s", len(body), b"BIN\x00") + body
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def _glb(doc: dict, buf: _Buffer) -> bytes:
    body = b"".join(buf.blobs)
    doc.update({"buffers": [{"byteLength": len(body)}], "bufferViews": buf.views, "accessors": buf.accessors})
    return glb_container(doc, body)


def _primitive(
    buf: _Buffer,
    doc: dict,
    vertices: np.ndarray,
    triangles: np.ndarray,
    uvs: np.ndarray | None,
    colors: np.ndarray | None,
    texture: bytes | None,
    targets: np.ndarray | None,
    sparse: bool = False,
    part: np.ndarray | None = None,
    target_normals: bool = False,
) -> dict:
    """sparse: store a target that moves under a quarter of the vertices as a sparse accessor; part: each vertex's
    part, whose seams with other parts are shaded as one surface (:func:`assets.heads.mesh.vertex_normals`);
    target_normals: each target also carries its NORMAL deltas (morph weights in [0, 1]; not the rig's IOD-unit
    targets, whose weight-1 shape is far outside any pose)."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    t = np.ascontiguousarray(triangles, dtype="<u4")
    n = len(v)
    if v.ndim != 2 or v.shape[1] != 3 or n == 0:
        raise GlbError(f"vertices must be (n, 3), got {v.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0 or t.max() >= n:
        raise GlbError(f"triangles must be (m, 3) indices below {n}")
    attributes = {"POSITION": buf.accessor(v, "VEC3", _FLOAT, _ARRAY_BUFFER, minmax=True)}
    # Without NORMAL a glTF client must shade flat (glTF 2.0 3.7.2.1): three.js showed the head faceted.
    # The neutral face's smooth normals (facecast's own renderer recomputes them per frame, clients/render/renderer.py;
    # a glTF viewer adds the targets' NORMAL deltas when they carry them, else lights every frame with these).
    normals = vertex_normals(np.asarray(vertices, dtype=np.float64), t, part)
    attributes["NORMAL"] = buf.accessor(np.ascontiguousarray(normals, dtype="<f4"), "VEC3", _FLOAT, _ARRAY_BUFFER)
    material: dict = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.8}, "doubleSided": True}
    if uvs is not None:
        attributes["TEXCOORD_0"] = buf.accessor(np.ascontiguousarray(uvs, dtype="<f4"), "VEC2", _FLOAT, _ARRAY_BUFFER)
    if colors is not None:
        # glTF's COLOR_0 is linear, facecast's colours sRGB: unconverted, every glTF viewer showed the head
        # paler and each write + read brightened it (skin 0.80, 0.60, 0.50 -> 0.91, 0.80, 0.74).
        linear = np.ascontiguousarray(srgb_to_linear(colors), dtype="<f4")
        attributes["COLOR_0"] = buf.accessor(linear, "VEC3", _FLOAT, _ARRAY_BUFFER)
    if texture is not None and uvs is not None:
        doc["images"] = [{"bufferView": buf.view(texture), "mimeType": image_mime(texture)}]
        doc["textures"] = [{"source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
        if texture_cutout(texture):  # see-through texels (eyelashes, a cornea) stay so in every glTF viewer
            material["alphaMode"] = "MASK"
            material["alphaCutoff"] = CUTOUT_ALPHA
    prim: dict = {"attributes": attributes, "material": 0}
    if targets is not None and len(targets):
        d = np.ascontiguousarray(targets, dtype="<f4")
        if d.ndim != 3 or d.shape[1:] != (n, 3):
            raise GlbError(f"targets must be (T, {n}, 3), got {d.shape}")
        moved = (np.abs(d).max(axis=2) > 0).sum(axis=1)  # (T,) vertices each target moves
        prim["targets"] = [
            {
                "POSITION": buf.sparse_vec3(d[j])
                if sparse and moved[j] * 4 < n
                else buf.accessor(d[j], "VEC3", _FLOAT, _ARRAY_BUFFER, minmax=True)
            }
            for j in range(len(d))
        ]
        if target_normals:
            dn = target_normal_deltas(np.asarray(vertices, dtype=np.float64), t, d, part)
            turned = (np.abs(dn).max(axis=2) > 0).sum(axis=1)
            for j, target in enumerate(prim["targets"]):
                # Sparse whatever ``sparse`` says: the deltas are 0 beyond the moved vertices' neighbours, and dense
                # ones doubled the built-in head's ARKit glb (3.3 -> 6.3 MB).
                target["NORMAL"] = (
                    buf.sparse_vec3(dn[j])
                    if turned[j] * 4 < n
                    else buf.accessor(np.ascontiguousarray(dn[j]), "VEC3", _FLOAT, _ARRAY_BUFFER)
                )
    prim["indices"] = buf.accessor(t.reshape(-1), "SCALAR", _UINT32, _ELEMENT_ARRAY_BUFFER)
    doc["materials"] = [material]
    return prim


def mesh_targets(mesh: HeadMesh, names: tuple[str, ...] | None = None) -> tuple[tuple[str, ...], np.ndarray | None]:
    """The mesh's morph targets (all, or ``names`` in that order) as (names, (T, n, 3) float32)."""
    if not mesh.targets:
        return (), None
    names = tuple(mesh.targets) if names is None else names
    return names, np.stack([np.asarray(mesh.targets[k], dtype=np.float32) for k in names])


def mesh_glb(mesh: HeadMesh) -> bytes:
    """One-mesh GLB: POSITION and NORMAL (float32), TEXCOORD_0 + the embedded texture when present, COLOR_0
    when the mesh has vertex colours, its morph targets (POSITION and NORMAL deltas, names in
    ``mesh.extras.targetNames``), uint32 indices."""
    buf = _Buffer()
    doc: dict = {"asset": {"version": "2.0", "generator": "facecast"}}
    names, targets = mesh_targets(mesh)
    prim = _primitive(
        buf,
        doc,
        mesh.vertices,
        mesh.triangles,
        mesh.uvs,
        mesh.colors,
        mesh.texture if mesh.uvs is not None else None,
        targets,
        part=mesh.part,
        target_normals=True,
    )
    m: dict = {"name": "head", "primitives": [prim]}
    if names:
        m["weights"] = [0.0] * len(names)
        m["extras"] = {"targetNames": list(names)}
    doc.update({"scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "head"}], "meshes": [m]})
    return _glb(doc, buf)


def mesh_json(mesh: HeadMesh, morph_names: tuple[str, ...] | None = None) -> bytes:
    """{"vertices": [x, y, z, ...], "triangles": [i, j, k, ...], "uvs": [u, v, ...] | null,
    "colors": [r, g, b, ...] | null, "morph": {"names": [...], "vertices": [...], "deltas": [[...]],
    "normals": {"vertices": [...], "deltas": [[...]]}} | null} as UTF-8 JSON (vertex order as in the GLB). ``morph``
    lists the targets ``morph_names`` (the ones a :class:`MorphRig` drives; default all) sparsely: the vertices any of
    them moves and per target their x, y, z; ``normals`` the same for their normal deltas
    (:func:`assets.heads.mesh.target_normal_deltas`), on the vertices any of them turns (the moved ones and their
    neighbours)."""

    def flat(a: np.ndarray | None, dtype: str) -> list | None:
        return None if a is None else np.asarray(a, dtype=dtype).reshape(-1).tolist()

    morph = None
    if morph_names is None:
        morph_names = tuple(mesh.targets or ())
    if morph_names and mesh.targets:
        d = np.stack([np.asarray(mesh.targets[k], dtype=np.float32) for k in morph_names])
        idx = np.flatnonzero(np.abs(d).max(axis=(0, 2)) > 0)
        # Relative to the rest normals the browser computes (three.js's computeVertexNormals: this area-weighted
        # rule without part seams), so that rest + delta at weight 1 is the target's own shading there.
        dn = target_normal_deltas(np.asarray(mesh.vertices, dtype=np.float32), mesh.triangles, d)
        turned = np.flatnonzero(np.abs(dn).max(axis=(0, 2)) > 0)
        morph = {
            "names": list(morph_names),
            "vertices": idx.tolist(),
            "deltas": [flat(d[j, idx], "float64") for j in range(len(d))],
            # 1e-4 of a unit normal (0.006 degrees) is finer than any lighting: the full float32 digits added 2.2 MB.
            "normals": {
                "vertices": turned.tolist(),
                "deltas": [np.round(dn[j, turned], 4).reshape(-1).tolist() for j in range(len(d))],
            },
        }
    doc = {
        "vertices": flat(np.asarray(mesh.vertices, np.float32), "float64"),
        "triangles": flat(mesh.triangles, "int64"),
        "uvs": flat(None if mesh.uvs is None else np.asarray(mesh.uvs, np.float32), "float64"),
        "colors": flat(None if mesh.colors is None else np.asarray(mesh.colors, np.float32), "float64"),
        "morph": morph,
    }
    return json.dumps(doc, separators=(",", ":")).encode()


def animated_glb(
    *,
    vertices: np.ndarray,
    triangles: np.ndarray,
    targets: np.ndarray,
    target_names: tuple[str, ...],
    weights: np.ndarray,
    fps: float,
    uvs: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    texture: bytes | None = None,
    audio: str | None = None,
    units: str = "IOD",
    sparse: bool = False,
    part: np.ndarray | None = None,
    target_normals: bool = False,
) -> bytes:
    """GLB bytes. vertices (n, 3) neutral positions (mesh units); triangles (m, 3) vertex indices;
    targets (T, n, 3) displacement per unit weight; target_names (T,); weights (F, T) per frame at
    ``fps`` (the animation starts at 0 s); uvs (n, 2) with texture (PNG/JPEG bytes) or colors (n, 3)
    in [0, 1]; audio: file name recorded in asset.extras; units: what the weights measure; sparse: a
    target that moves under a quarter of the vertices is stored as a glTF sparse accessor; part (n,): each vertex's
    part, for the normals (:func:`assets.heads.mesh.vertex_normals`); target_normals: the targets carry NORMAL deltas
    (weights in [0, 1]: a head's own morph targets)."""
    w = np.asarray(weights, dtype=np.float64)
    d = np.asarray(targets)
    if d.ndim != 3 or d.shape[0] != len(target_names):
        raise GlbError(f"targets must be ({len(target_names)}, n, 3), got {d.shape}")
    if w.ndim != 2 or w.shape[1] != len(target_names):
        raise GlbError(f"the track has {w.shape[-1] if w.ndim else 0} curves for {len(target_names)} targets")
    if len(w) == 0:
        raise GlbError("the track has no frames")
    if not (np.isfinite(fps) and fps > 0):
        raise GlbError(f"fps must be > 0, got {fps}")
    buf = _Buffer()
    doc: dict = {
        "asset": {
            "version": "2.0",
            "generator": "facecast",
            "extras": {"facecast": {"audio": audio, "fps": float(fps), "units": units, "curves": list(target_names)}},
        }
    }
    prim = _primitive(
        buf, doc, vertices, triangles, uvs, colors, texture, d, sparse, part=part, target_normals=target_normals
    )
    times = np.ascontiguousarray(np.arange(len(w)) / fps, dtype="<f4")
    t_in = buf.accessor(times, "SCALAR", _FLOAT, None, minmax=True)  # glTF requires min/max on inputs
    w_out = buf.accessor(np.ascontiguousarray(w, dtype="<f4").reshape(-1), "SCALAR", _FLOAT, None)  # frame-major
    doc.update(
        {
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0, "name": "head"}],
            "meshes": [
                {
                    "name": "head",
                    "primitives": [prim],
                    "weights": [0.0] * len(target_names),
                    "extras": {"targetNames": list(target_names)},
                }
            ],
            "animations": [
                {
                    "name": "speech",
                    "samplers": [{"input": t_in, "output": w_out, "interpolation": "LINEAR"}],
                    "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
                }
            ],
        }
    )
    return _glb(doc, buf)


def rig_targets(rig) -> np.ndarray:
    """Morph targets (4, n, 3) float32 of a :class:`realtime_core.face.Rig`: the head displacement
    (mesh units) per unit (1 IOD) of each mouth parameter: the rig's linear field, without its
    lip-contact push (a whole IOD of one parameter crosses the lips of a rig with contact columns, and
    the push at that unit pose would be baked into every frame's blend). Unbounded: a unit pose lies outside
    a head's :attr:`~realtime_core.face.Rig.bound`; the animation's weights are bounded instead (:func:`head_glb`)."""
    rig = replace(rig, bound=None)
    out = np.zeros((4, len(rig.neutral), 3), dtype=np.float32)
    for j in range(4):
        e = np.zeros(4, dtype=np.float32)
        e[j] = 1.0
        out[j, rig.moving] = rig.displacements(e) - rig.contact_push(e)
    return out


def head_glb(
    rig,
    mesh: HeadMesh,
    params: np.ndarray,
    fps: float,
    *,
    audio: str | None = None,
    expression: np.ndarray | None = None,
) -> bytes:
    """The animated GLB of a rigged head for mouth parameters (F, 4) at ``fps``: a MorphRig animates the
    head's own targets (its weights per frame; ``expression`` (F, E) intensities drive its face shapes, None: none),
    a Rig its four exact parameter targets (IOD curves; an expression reaches it through the parameters only)."""
    from realtime_core import VISUAL_PARAMS
    from realtime_core.face.keyframes import MorphRig

    if len(mesh.vertices) != len(rig.neutral):
        raise GlbError(f"mesh has {len(mesh.vertices)} vertices, its rig {len(rig.neutral)}")
    p = np.asarray(params, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 4:
        raise GlbError(f"params must be (frames, 4), got {p.shape}")
    texture = mesh.texture if mesh.uvs is not None else None
    if isinstance(rig, MorphRig):
        return animated_glb(
            vertices=rig.neutral,
            triangles=mesh.triangles,
            targets=rig.dense_targets(),
            target_names=rig.names,
            weights=rig.weights(p, expression),
            fps=fps,
            uvs=mesh.uvs,
            colors=mesh.colors,
            texture=texture,
            audio=audio,
            units="morph weight",
            part=mesh.part,
            target_normals=True,
        )
    # The lip-contact push is not linear in the parameters, but it is linear in each lip column's
    # crossing (deficit): one sparse target per column, animated by its deficit per frame, makes the
    # file deform exactly as the renderer and the server's deltas do (lips never pass each other).
    contact = np.zeros((len(rig.contact), len(rig.neutral), 3), dtype=np.float32)
    contact[:, rig.moving] = rig.contact_targets()
    p = rig.bounded(p)  # the parameter curves as the renderer and the server drive the rig
    names = tuple(VISUAL_PARAMS) + tuple(f"lip_contact_{k:02d}" for k in range(len(rig.contact)))
    return animated_glb(
        vertices=rig.neutral,
        triangles=mesh.triangles,
        targets=np.concatenate([rig_targets(rig), contact]),
        target_names=names,
        weights=np.hstack([p, rig.contact_deficits(p)]),
        fps=fps,
        uvs=mesh.uvs,
        colors=mesh.colors,
        texture=texture,
        audio=audio,
        units="IOD (mouth parameters); head units (lip_contact_k: that lip column's crossing, pushed apart)",
        sparse=True,
        part=mesh.part,
    )
