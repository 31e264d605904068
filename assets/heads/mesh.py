"""Head meshes at the edge: read glb/gltf (:mod:`assets.heads.gltf`) and obj/ply (trimesh) into a :class:`HeadMesh`.

All pieces (primitives, objects) are merged with their node transforms applied; vertex order is
kept as in the file so landmark vertex indices stay valid. glTF morph targets are kept by name
(they drive the head directly, :mod:`assets.heads.targets`). Texture: one per material; a mesh
with several textured materials gets one atlas (the tiles side by side, each piece's UVs moved
into its tile), so renderer, browser and exports all handle a single texture. Untextured pieces
take their material colour as vertex colours. Without any material texture, a single colour-map
image next to the file (``*col*``, ``*diffuse*``, ``*albedo*`` or the only image there) is used.
UVs follow glTF's convention (v down, image row 0 at v = 0); OBJ/PLY UVs (v up) are flipped.
Compressed glTF (meshopt, Draco, KTX2) is decoded first (:mod:`assets.heads.decompress`).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.errors import MeshError

MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".ply")
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


@dataclass(frozen=True)
class HeadMesh:
    """vertices (n, 3) float64 (file units), triangles (m, 3) int64, uvs (n, 2) or None,
    texture: encoded image bytes (PNG/JPEG) or None, colors (n, 3) float32 in [0, 1] or None,
    name: where it came from (a path or "builtin"); targets: morph-target name -> (n, 3) float64
    displacement at weight 1, or None; part: (n,) int16 index into part_names (the file's
    objects/primitives, e.g. "Eye_L", "Teeth") or None."""

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None = None
    texture: bytes | None = None
    colors: np.ndarray | None = None
    name: str = ""
    targets: dict[str, np.ndarray] | None = None
    part: np.ndarray | None = None
    part_names: tuple[str, ...] = ()


def _sibling_texture(path: Path) -> bytes | None:
    images = sorted(p for p in path.parent.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    for key in ("col", "diffuse", "albedo", path.stem.lower()):
        hits = [p for p in images if key in p.stem.lower()]
        if len(hits) == 1:
            return hits[0].read_bytes()
    if len(images) == 1:
        return images[0].read_bytes()
    return None


def _image_bytes(img: object) -> bytes | None:
    if img is None or img.size[0] * img.size[1] <= 16:  # type: ignore[attr-defined]
        return None  # trimesh's placeholder for "no texture" is a tiny grey image
    buf = io.BytesIO()
    img.save(buf, format="PNG")  # type: ignore[attr-defined]
    return buf.getvalue()


def check_mesh(mesh: HeadMesh) -> None:
    """Raise MeshError (naming ``mesh.name``) if the mesh cannot be rigged."""
    v, t = mesh.vertices, mesh.triangles
    if len(t) == 0:
        raise MeshError(f"{mesh.name}: mesh has no faces")
    if len(v) < 4 or not np.all(np.isfinite(v)):
        raise MeshError(f"{mesh.name}: mesh has too few vertices or non-finite coordinates")
    area = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    extent = float(np.ptp(v, axis=0).max())
    if not extent > 0 or area.sum() <= 1e-12 * extent**2:
        raise MeshError(f"{mesh.name}: mesh is degenerate (zero extent or zero total area)")
    sv = np.linalg.svd(v - v.mean(0), compute_uv=False)
    if sv[2] < 1e-6 * sv[0]:
        raise MeshError(f"{mesh.name}: mesh is flat (all vertices in one plane); a head must be 3D")


def load_mesh(path: str | Path, *, cache: Path | None = None) -> HeadMesh:
    """Read a head mesh (glb/gltf/obj/ply). Raises MeshError naming the file on any problem."""
    p = Path(path)
    if not p.is_file():
        raise MeshError(f"{p}: mesh file not found (give a .glb, .gltf, .obj or .ply head, or 'builtin')")
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{p}: unsupported mesh format {p.suffix!r}; convert it to one of {', '.join(MESH_SUFFIXES)}")
    if p.suffix.lower() in (".glb", ".gltf"):
        pieces = _gltf_pieces(p, cache)
    else:
        pieces = _trimesh_pieces(p)
    pieces = [x for x in pieces if len(x.triangles)]
    if not pieces:
        raise MeshError(f"{p}: file contains no triangle mesh (point cloud or empty scene); export the head as triangles")
    mesh = _merge(p, pieces)
    check_mesh(mesh)
    return mesh


def _gltf_pieces(p: Path, cache: Path | None) -> list:
    from assets.heads.decompress import decompressed
    from assets.heads.gltf import NEEDS_DECODER, read_gltf, read_gltf_document

    try:
        doc, _ = read_gltf_document(p)
    except Exception as exc:  # a bad file raises many unrelated types (struct, json, unicode)
        raise MeshError(f"{p}: not a readable glTF file: {exc}") from exc
    used = set(doc.get("extensionsRequired", [])) | set(doc.get("extensionsUsed", []))
    src = decompressed(p, cache) if used & set(NEEDS_DECODER) else p
    prims, materials = read_gltf(src)
    return [_Piece(x.vertices, x.triangles, x.uvs, x.colors, materials[x.material] if x.material >= 0 else None,
                   x.targets, x.node or (materials[x.material].name if x.material >= 0 else "")) for x in prims]


def _trimesh_pieces(p: Path) -> list:
    import trimesh

    from assets.heads.gltf import Material

    try:
        loaded = trimesh.load(str(p), process=False, maintain_order=True)
    except Exception as exc:  # trimesh raises many unrelated types for a bad file
        raise MeshError(f"{p}: cannot read mesh: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        geoms = []
        for node in loaded.graph.nodes_geometry:
            transform, gname = loaded.graph[node]
            g = loaded.geometry[gname]
            if isinstance(g, trimesh.Trimesh):
                g = g.copy()
                g.apply_transform(transform)
                geoms.append((str(gname), g))
    elif isinstance(loaded, trimesh.Trimesh):
        geoms = [(p.stem, loaded)]
    else:
        geoms = []
    out = []
    for gname, g in geoms:
        uv = getattr(g.visual, "uv", None)
        uv = None if uv is None or len(uv) != len(g.vertices) else np.asarray(uv, dtype=np.float64)
        if uv is not None:
            uv = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])  # OBJ/PLY: v up -> facecast/glTF: v down
        mat = getattr(g.visual, "material", None)
        material = None
        if mat is not None:
            img = _image_bytes(getattr(mat, "baseColorTexture", None) or getattr(mat, "image", None))
            color = getattr(mat, "main_color", None)
            color = np.asarray(color, dtype=np.float64) / 255.0 if color is not None else np.ones(4)
            material = Material(color=_srgb_to_linear(color), image=img, name=str(getattr(mat, "name", "")))
        colors = None
        vc = getattr(g.visual, "vertex_colors", None)
        if getattr(g.visual, "kind", None) == "vertex" and vc is not None and len(vc) == len(g.vertices):
            colors = np.asarray(vc, dtype=np.float64)[:, :3] / 255.0
        out.append(_Piece(np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces, dtype=np.int64), uv,
                          colors, material, {}, gname))
    return out


@dataclass
class _Piece:
    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None
    colors: np.ndarray | None
    material: object
    targets: dict[str, np.ndarray]
    name: str


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64).copy()
    c[:3] = np.where(c[:3] <= 0.04045, c[:3] / 12.92, ((c[:3] + 0.055) / 1.055) ** 2.4)
    return c


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, dtype=np.float64), 0, 1)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def _merge(p: Path, pieces: list) -> HeadMesh:
    from PIL import Image

    n_total = sum(len(x.vertices) for x in pieces)
    textured = [x for x in pieces if x.material is not None and getattr(x.material, "image", None) and x.uvs is not None]
    images: list[bytes] = []
    for x in textured:
        if x.material.image not in images:
            images.append(x.material.image)
    verts, tris, uvs, cols, part = [], [], [], [], []
    off = 0
    for i, x in enumerate(pieces):
        verts.append(x.vertices)
        tris.append(x.triangles + off)
        off += len(x.vertices)
        part.append(np.full(len(x.vertices), i, dtype=np.int16))
        mat = x.material
        base = np.ones(3) if mat is None else np.asarray(mat.color[:3])
        if x.colors is not None:
            cols.append(np.clip(x.colors * base, 0, 1))
        else:
            cols.append(np.tile(_linear_to_srgb(base) if mat is not None else np.array([0.8, 0.62, 0.52]),
                                (len(x.vertices), 1)))
    texture = None
    uv_all = None
    if len(images) == 1 and len(textured) == len(pieces):
        texture = images[0]
        uv_all = np.concatenate([x.uvs for x in pieces])
    elif images:
        texture, uv_all = _atlas(pieces, images)
    elif all(x.uvs is not None for x in pieces):
        uv_all = np.concatenate([x.uvs for x in pieces])
        texture = _sibling_texture(p)
    colors = None
    if texture is None:
        c = np.concatenate(cols).astype(np.float32)
        if any(x.colors is not None or x.material is not None for x in pieces):
            colors = c
    names = sorted({k for x in pieces for k in x.targets})
    targets = None
    if names:
        targets = {}
        for k in names:
            d = np.zeros((n_total, 3))
            o = 0
            for x in pieces:
                if k in x.targets:
                    d[o : o + len(x.vertices)] = x.targets[k]
                o += len(x.vertices)
            targets[k] = d
    del Image
    return HeadMesh(
        vertices=np.concatenate(verts),
        triangles=np.concatenate(tris),
        uvs=uv_all,
        texture=texture,
        colors=colors,
        name=str(p),
        targets=targets,
        part=np.concatenate(part),
        part_names=tuple(x.name for x in pieces),
    )


ATLAS_MAX_TILE = 2048


def _atlas(pieces: list, images: list[bytes]) -> tuple[bytes, np.ndarray]:
    """One PNG with every material's image (or colour) as a square tile, and the UVs moved into the tiles."""
    from PIL import Image

    tiles: list[Image.Image] = []
    for b in images:
        tiles.append(Image.open(io.BytesIO(b)).convert("RGB"))
    colour_tiles: dict[tuple, int] = {}
    which = []
    for x in pieces:
        img = getattr(x.material, "image", None) if x.material is not None else None
        if img is not None and x.uvs is not None:
            which.append(images.index(img))
            continue
        base = np.ones(3) if x.material is None else np.asarray(x.material.color[:3])
        key = tuple(np.round(_linear_to_srgb(base) * 255).astype(int))
        if key not in colour_tiles:
            colour_tiles[key] = len(tiles)
            tiles.append(Image.new("RGB", (8, 8), key))
        which.append(colour_tiles[key])
    size = min(ATLAS_MAX_TILE, max(max(t.size) for t in tiles))
    n = len(tiles)
    cols = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    atlas = Image.new("RGB", (cols * size, rows * size))
    for i, t in enumerate(tiles):
        atlas.paste(t.resize((size, size), Image.Resampling.BILINEAR), ((i % cols) * size, (i // cols) * size))
    margin = 1.0 / size  # a texel inside the tile: bilinear filtering never reads the neighbour
    uv_parts = []
    for x, k in zip(pieces, which):
        if x.uvs is None:
            uv = np.full((len(x.vertices), 2), 0.5)
        else:
            uv = np.asarray(x.uvs, dtype=np.float64)
            inside = (uv >= 0) & (uv <= 1)
            uv = np.where(inside, uv, uv - np.floor(uv))  # repeat-wrapped UVs folded into [0, 1)
        c, r = k % cols, k // cols
        u = (c + margin + uv[:, 0] * (1 - 2 * margin)) / cols
        v = (r + margin + uv[:, 1] * (1 - 2 * margin)) / rows
        uv_parts.append(np.column_stack([u, v]))
    buf = io.BytesIO()
    atlas.save(buf, format="PNG")
    return buf.getvalue(), np.concatenate(uv_parts)
