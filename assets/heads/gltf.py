"""glTF 2.0 reader (``.glb``/``.gltf``; ``.vrm``, a binary glTF, :mod:`assets.heads.vrm`) for heads: geometry, node
transforms, skins, morph targets, materials.

Read with numpy from the file itself, because the head needs what general mesh loaders drop:
morph targets with their names (``mesh.extras.targetNames``, the three.js/Blender convention, or
``primitive.extras.targetNames``), one texture per material, and the exact vertex order (landmark
files index vertices in the order primitives appear: scene nodes depth-first, primitives in
order). Supported: every accessor component type with ``normalized`` and ``KHR_mesh_quantization``
attributes, byte strides, sparse accessors, triangle lists/strips/fans, node matrices and TRS,
skinned meshes posed by their joints' node transforms (the bind pose unless the file animates the
rest pose), embedded (bufferView/data URI) and external images, ``KHR_texture_transform`` on the base colour
texture (gltfpack's quantized UVs), material ``alphaMode`` (see-through cards and shells). Files that need a decoder
(``EXT_meshopt_compression``, ``KHR_draco_mesh_compression``, ``KHR_texture_basisu``) are first
rewritten without it by :mod:`assets.heads.decompress`.

UV convention: glTF's (u right, v down; image row 0 at v = 0), kept as is; it is facecast's
convention everywhere (renderer, browser, exports). OBJ files (v up) are flipped on reading.
"""

from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from assets.errors import MeshError

_CTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
NEEDS_DECODER = ("EXT_meshopt_compression", "KHR_draco_mesh_compression", "KHR_texture_basisu")


@dataclass
class Primitive:
    """One drawable piece: vertices (n, 3) world units, triangles (m, 3) local indices, uvs (n, 2)
    or None, colors (n, 3) or None, material index (-1 none), morph displacements name -> (n, 3).
    node_index / mesh_index: the glTF node drawing it and its mesh; by_index: the same displacements by the
    primitive's target index (None where a target has no POSITION), for files that bind targets by index
    (a VRM's expressions, :mod:`assets.heads.vrm`) and may give several the same name."""

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None
    colors: np.ndarray | None
    material: int
    targets: dict[str, np.ndarray] = field(default_factory=dict)
    node: str = ""
    node_index: int = -1
    mesh_index: int = -1
    by_index: tuple[np.ndarray | None, ...] = ()


@dataclass
class Material:
    """base colour factor (4,) and the encoded base-colour image (PNG/JPEG bytes) or None; alpha_mode: glTF's
    "OPAQUE" (the image's alpha ignored), "MASK" (drawn where alpha * factor >= alpha_cutoff) or "BLEND" (see-through
    by alpha * factor); coverage: an image whose luminance is the coverage instead of the base image's alpha (an OBJ
    material's ``map_d``) or None."""

    color: np.ndarray
    image: bytes | None
    name: str = ""
    alpha_mode: str = "OPAQUE"
    alpha_cutoff: float = 0.5
    coverage: bytes | None = None


def read_gltf_document(path: Path) -> tuple[dict, list[bytes]]:
    """The JSON document and its buffers (bytes) of a .glb or .gltf file."""
    data = path.read_bytes()
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise MeshError(f"{path}: truncated GLB header")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise MeshError(f"{path}: glTF version {version} is not supported (need 2.0)")
        off, doc, bin_chunk = 12, None, b""
        while off + 8 <= min(length, len(data)):
            clen, ctype = struct.unpack_from("<I4s", data, off)
            chunk = data[off + 8 : off + 8 + clen]
            if ctype == b"JSON":
                doc = json.loads(chunk.decode("utf-8"))
            elif ctype == b"BIN\x00":
                bin_chunk = chunk
            off += 8 + clen
        if doc is None:
            raise MeshError(f"{path}: GLB without a JSON chunk")
    else:
        doc = json.loads(data.decode("utf-8"))
        bin_chunk = b""
    buffers = []
    for _i, b in enumerate(doc.get("buffers", [])):
        uri = b.get("uri")
        if uri is None:
            buffers.append(bin_chunk)
        else:
            buffers.append(_read_uri(path, uri))
    return doc, buffers


def _read_uri(path: Path, uri: str) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    from urllib.parse import unquote

    p = path.parent / unquote(uri)
    if not p.is_file():
        raise MeshError(f"{path}: referenced file {uri!r} not found beside it")
    return p.read_bytes()


class _Reader:
    def __init__(self, path: Path, doc: dict, buffers: list[bytes]) -> None:
        self.path, self.doc, self.buffers = path, doc, buffers

    def view_bytes(self, index: int) -> tuple[bytes, int | None]:
        v = self.doc["bufferViews"][index]
        buf = self.buffers[v["buffer"]]
        off = v.get("byteOffset", 0)
        return buf[off : off + v["byteLength"]], v.get("byteStride")

    def accessor(self, index: int) -> np.ndarray:
        """(count, ncomp) float64 (normalized integers scaled to [0, 1] / [-1, 1])."""
        a = self.doc["accessors"][index]
        dtype: np.dtype[Any] = np.dtype(_CTYPES[a["componentType"]]).newbyteorder("<")
        nc = _NCOMP[a["type"]]
        count = a["count"]
        if "bufferView" in a:
            raw, stride = self.view_bytes(a["bufferView"])
            off = a.get("byteOffset", 0)
            item = dtype.itemsize * nc
            stride = stride or item
            if stride == item:
                out = np.frombuffer(raw, dtype=dtype, count=count * nc, offset=off).reshape(count, nc)
            else:
                rows = (
                    np.lib.stride_tricks.as_strided(
                        np.frombuffer(raw, dtype=np.uint8), shape=(count, item), strides=(stride, 1), writeable=False
                    )
                    if off == 0
                    else np.lib.stride_tricks.as_strided(
                        np.frombuffer(raw[off:], dtype=np.uint8),
                        shape=(count, item),
                        strides=(stride, 1),
                        writeable=False,
                    )
                )
                out = np.ascontiguousarray(rows).view(dtype).reshape(count, nc)
            out = out.astype(np.float64)
        else:
            out = np.zeros((count, nc))
        if a.get("normalized"):
            info = np.iinfo(dtype)
            out = np.maximum(out / info.max, -1.0) if info.min < 0 else out / info.max
        sparse = a.get("sparse")
        if sparse:
            si = sparse["indices"]
            raw, _ = self.view_bytes(si["bufferView"])
            idt = np.dtype(_CTYPES[si["componentType"]]).newbyteorder("<")
            idx = np.frombuffer(raw, dtype=idt, count=sparse["count"], offset=si.get("byteOffset", 0)).astype(np.int64)
            sv = sparse["values"]
            raw, _ = self.view_bytes(sv["bufferView"])
            vals = np.frombuffer(raw, dtype=dtype, count=sparse["count"] * nc, offset=sv.get("byteOffset", 0))
            vals = vals.reshape(-1, nc).astype(np.float64)
            if a.get("normalized"):
                info = np.iinfo(dtype)
                vals = np.maximum(vals / info.max, -1.0) if info.min < 0 else vals / info.max
            out = out.copy()
            out[idx] = vals
        return out

    def image(self, tex_index: int) -> bytes | None:
        tex = self.doc.get("textures", [])[tex_index]
        src = tex.get("source")
        if src is None:
            # Only in an image-format extension (Ready Player Me's WebP textures): Pillow reads those formats and
            # assets.heads.mesh turns them into PNG for the renderer, the browser and exports.
            ext = tex.get("extensions") or {}
            src = next((ext[k]["source"] for k in ("EXT_texture_webp", "EXT_texture_avif") if k in ext), None)
        if src is None:
            return None
        img = self.doc["images"][src]
        if "bufferView" in img:
            return self.view_bytes(img["bufferView"])[0]
        if "uri" in img:
            return _read_uri(self.path, img["uri"])
        return None


def texture_transformed(uvs: np.ndarray, ext: dict | None) -> np.ndarray:
    """UVs (n, 2) as a texture reads them through KHR_texture_transform ``ext`` (offset, rotation in radians
    counter-clockwise, scale; the extension's matrix T R S): gltfpack quantizes UVs to a box and restores them so,
    so a reader that ignored it put the texture off by the box. None or {}: the UVs as they are."""
    if not ext:
        return uvs
    ox, oy = (float(x) for x in ext.get("offset", (0.0, 0.0)))
    sx, sy = (float(x) for x in ext.get("scale", (1.0, 1.0)))
    r = float(ext.get("rotation", 0.0))
    c, s = np.cos(r), np.sin(r)
    u, v = np.asarray(uvs, dtype=np.float64).T * np.array([[sx], [sy]])
    return np.column_stack([c * u + s * v + ox, -s * u + c * v + oy])


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major in the file
    t = np.array(node.get("translation", [0, 0, 0]), dtype=np.float64)
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    s = np.array(node.get("scale", [1, 1, 1]), dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def _turned(d: np.ndarray, lin: np.ndarray) -> np.ndarray:
    """Displacements d (n, 3) turned by the linear part of a node's world matrix (3, 3) or of each vertex's
    blended joints (n, 3, 3)."""
    return np.einsum("nij,nj->ni", lin, d) if lin.ndim == 3 else d @ lin.T


def _triangles(mode: int, idx: np.ndarray) -> np.ndarray:
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip: alternate winding
        t = np.stack([idx[:-2], idx[1:-1], idx[2:]], axis=1)
        t[1::2] = t[1::2][:, [1, 0, 2]]
        return t
    if mode == 6:  # fan
        return np.stack([np.full(len(idx) - 2, idx[0]), idx[1:-1], idx[2:]], axis=1)
    return np.zeros((0, 3), dtype=np.int64)


UNREADABLE_HINT = (
    "export it again from the modelling tool as .glb, or see what is wrong with `npx gltf-transform validate FILE`"
)
"""How to proceed, after a glTF file that cannot be read (issue 12: one line naming the file, the problem and what to
do); glTF-Transform's command line comes with the project's npm packages (scripts/setup.sh)."""


def read_gltf(path: Path) -> tuple[list[Primitive], list[Material]]:
    """Every triangle primitive of the default scene in world coordinates, and the materials."""
    try:
        doc, buffers = read_gltf_document(path)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, struct.error) as exc:
        raise MeshError(f"{path}: not a readable glTF file ({exc}); {UNREADABLE_HINT}") from exc
    used = set(doc.get("extensionsRequired", [])) | set(doc.get("extensionsUsed", []))
    if used & set(NEEDS_DECODER):
        raise MeshError(f"{path}: compressed with {sorted(used & set(NEEDS_DECODER))}; decompress it first")
    rd = _Reader(path, doc, buffers)
    nodes = doc.get("nodes", [])
    try:
        world = [np.eye(4) for _ in nodes]
        parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}

        def world_of(i: int, seen: tuple[int, ...] = ()) -> np.ndarray:
            if i in seen:
                raise MeshError(f"{path}: node hierarchy has a cycle")
            m = _node_matrix(nodes[i])
            return world_of(parent[i], (*seen, i)) @ m if i in parent else m

        world = [world_of(i) for i in range(len(nodes))]
        scenes = doc.get("scenes", [])
        roots = scenes[doc.get("scene", 0)]["nodes"] if scenes else [i for i in range(len(nodes)) if i not in parent]
        order: list[int] = []

        def visit(i: int) -> None:
            order.append(i)
            for c in nodes[i].get("children", []):
                visit(c)

        for r in roots:
            visit(r)
        prims: list[Primitive] = []
        for ni in order:
            node = nodes[ni]
            if "mesh" not in node:
                continue
            mesh = doc["meshes"][node["mesh"]]
            names = (mesh.get("extras") or {}).get("targetNames")
            skin = doc["skins"][node["skin"]] if "skin" in node and doc.get("skins") else None
            joint_mats = None
            if skin is not None:
                ibm = (
                    rd.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
                    if "inverseBindMatrices" in skin
                    else np.tile(np.eye(4), (len(skin["joints"]), 1, 1))
                )
                joint_mats = np.stack([world[j] for j in skin["joints"]]) @ ibm  # (J, 4, 4)
            for prim in mesh.get("primitives", []):
                attrs = prim.get("attributes", {})
                if "POSITION" not in attrs or prim.get("mode", 4) not in (4, 5, 6):
                    continue
                pos = rd.accessor(attrs["POSITION"])[:, :3]
                n = len(pos)
                idx = (
                    rd.accessor(prim["indices"])[:, 0].astype(np.int64)
                    if "indices" in prim
                    else np.arange(n, dtype=np.int64)
                )
                tris = _triangles(prim.get("mode", 4), idx)
                uv_key = "TEXCOORD_0"
                mat_i = prim.get("material", -1)
                bct = None
                if mat_i >= 0:
                    bct = (doc["materials"][mat_i].get("pbrMetallicRoughness") or {}).get("baseColorTexture")
                    if bct:
                        shift = (bct.get("extensions") or {}).get("KHR_texture_transform") or {}
                        uv_key = f"TEXCOORD_{shift.get('texCoord', bct.get('texCoord', 0))}"
                uvs = rd.accessor(attrs[uv_key])[:, :2] if uv_key in attrs else None
                if uvs is not None and bct:
                    uvs = texture_transformed(uvs, (bct.get("extensions") or {}).get("KHR_texture_transform"))
                colors = rd.accessor(attrs["COLOR_0"])[:, :3] if "COLOR_0" in attrs else None
                pnames = (prim.get("extras") or {}).get("targetNames") or names
                targets: dict[str, np.ndarray] = {}
                indexed: list[np.ndarray | None] = []
                for k, tgt in enumerate(prim.get("targets", [])):
                    indexed.append(None)
                    if "POSITION" not in tgt:
                        continue
                    name = pnames[k] if pnames and k < len(pnames) else f"target_{k}"
                    indexed[k] = targets[str(name)] = rd.accessor(tgt["POSITION"])[:, :3]
                if joint_mats is not None and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
                    j = rd.accessor(attrs["JOINTS_0"]).astype(np.int64)
                    w = rd.accessor(attrs["WEIGHTS_0"])
                    w = w / np.maximum(w.sum(1, keepdims=True), 1e-12)
                    m = np.einsum("nk,nkij->nij", w, joint_mats[j])  # (n, 4, 4) linear blend skinning
                    pos = np.einsum("nij,nj->ni", m[:, :3, :3], pos) + m[:, :3, 3]
                    lin = m[:, :3, :3]  # (n, 3, 3): displacements turn with each vertex's blended joints
                else:
                    wm = world[ni]
                    pos = pos @ wm[:3, :3].T + wm[:3, 3]
                    lin = wm[:3, :3]
                moved = {id(d): _turned(d, lin) for d in indexed if d is not None}
                targets = {k: moved[id(d)] for k, d in targets.items()}
                prims.append(
                    Primitive(
                        vertices=pos,
                        triangles=tris,
                        uvs=uvs,
                        colors=colors,
                        material=mat_i,
                        targets=targets,
                        node=str(node.get("name", ni)),
                        node_index=ni,
                        mesh_index=int(node["mesh"]),
                        by_index=tuple(None if d is None else moved[id(d)] for d in indexed),
                    )
                )
        materials: list[Material] = []
        for m in doc.get("materials", []):
            pbr = m.get("pbrMetallicRoughness") or {}
            color = np.array(pbr.get("baseColorFactor", [1, 1, 1, 1]), dtype=np.float64)
            bct = pbr.get("baseColorTexture")
            image = rd.image(bct["index"]) if bct else None
            mode = str(m.get("alphaMode", "OPAQUE"))
            if mode not in ("OPAQUE", "MASK", "BLEND"):
                raise MeshError(f"{path}: material {m.get('name', len(materials))!r}: unknown alphaMode {mode!r}")
            cutoff = float(m.get("alphaCutoff", 0.5))
            materials.append(
                Material(color=color, image=image, name=str(m.get("name", "")), alpha_mode=mode, alpha_cutoff=cutoff)
            )
    except MeshError:
        raise
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise MeshError(f"{path}: malformed glTF ({type(exc).__name__}: {exc}); {UNREADABLE_HINT}") from exc
    return prims, materials
