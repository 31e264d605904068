"""The head mesh as binary glTF 2.0 (``.glb``) and as plain JSON, for viewers to download.

Vertex order is kept exactly (no re-indexing), so the moving-vertex indices of the viewer
description and the vertex deltas address the downloaded mesh directly.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from assets.heads.mesh import HeadMesh


def _image_mime(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg"
    return "application/octet-stream"


def texture_mime(mesh: HeadMesh) -> str | None:
    return None if mesh.texture is None else _image_mime(mesh.texture)


def mesh_glb(mesh: HeadMesh) -> bytes:
    """One-mesh GLB: POSITION (float32), TEXCOORD_0 and the embedded texture when present,
    COLOR_0 when the mesh has vertex colours, uint32 indices."""
    pos = np.ascontiguousarray(mesh.vertices, dtype="<f4")
    idx = np.ascontiguousarray(mesh.triangles, dtype="<u4").reshape(-1)
    blobs: list[bytes] = []
    views: list[dict] = []
    accessors: list[dict] = []

    def add_view(data: bytes, target: int | None = None) -> int:
        offset = sum(len(b) for b in blobs)
        blobs.append(data + b"\x00" * (-len(data) % 4))
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        return len(views) - 1

    def add_accessor(arr: np.ndarray, kind: str, ctype: int, target: int, minmax: bool = False) -> int:
        acc = {"bufferView": add_view(arr.tobytes(), target), "componentType": ctype, "count": int(len(arr)), "type": kind}
        if minmax:
            acc["min"] = [float(x) for x in arr.min(axis=0)]
            acc["max"] = [float(x) for x in arr.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    attributes = {"POSITION": add_accessor(pos, "VEC3", 5126, 34962, minmax=True)}
    material: dict = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.8}, "doubleSided": True}
    doc: dict = {"asset": {"version": "2.0", "generator": "facecast"}}
    if mesh.uvs is not None:
        attributes["TEXCOORD_0"] = add_accessor(np.ascontiguousarray(mesh.uvs, dtype="<f4"), "VEC2", 5126, 34962)
    if mesh.colors is not None:
        attributes["COLOR_0"] = add_accessor(np.ascontiguousarray(mesh.colors, dtype="<f4"), "VEC3", 5126, 34962)
    if mesh.texture is not None and mesh.uvs is not None:
        doc["images"] = [{"bufferView": add_view(mesh.texture), "mimeType": _image_mime(mesh.texture)}]
        doc["textures"] = [{"source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    indices = add_accessor(idx, "SCALAR", 5125, 34963)
    body = b"".join(blobs)
    doc.update({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "head"}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": indices, "material": 0}]}],
        "materials": [material],
        "buffers": [{"byteLength": len(body)}],
        "bufferViews": views,
        "accessors": accessors,
    })
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(body)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(body), b"BIN\x00") + body)


def mesh_json(mesh: HeadMesh) -> bytes:
    """{"vertices": [x, y, z, ...], "triangles": [i, j, k, ...], "uvs": [u, v, ...] | null,
    "colors": [r, g, b, ...] | null} as UTF-8 JSON (vertex order as in the GLB)."""
    def flat(a: np.ndarray | None, dtype: str) -> list | None:
        return None if a is None else np.asarray(a, dtype=dtype).reshape(-1).tolist()

    doc = {
        "vertices": flat(np.asarray(mesh.vertices, np.float32), "float64"),
        "triangles": flat(mesh.triangles, "int64"),
        "uvs": flat(None if mesh.uvs is None else np.asarray(mesh.uvs, np.float32), "float64"),
        "colors": flat(None if mesh.colors is None else np.asarray(mesh.colors, np.float32), "float64"),
    }
    return json.dumps(doc, separators=(",", ":")).encode()
