"""Head meshes at the edge: read glb/gltf/obj/ply with trimesh into a plain :class:`HeadMesh`.

Scene geometries are merged with their node transforms applied; vertex order is kept as in the
file (``process=False``) so landmark vertex indices stay valid. Texture: the material's embedded
base-colour image, else a single colour-map image next to the file (``*col*``, ``*diffuse*``,
``*albedo*`` or the only image there), kept as encoded bytes.
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
    name: where it came from (a path or "builtin")."""

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None = None
    texture: bytes | None = None
    colors: np.ndarray | None = None
    name: str = ""


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


def load_mesh(path: str | Path) -> HeadMesh:
    """Read a head mesh (glb/gltf/obj/ply). Raises MeshError naming the file on any problem."""
    import trimesh

    p = Path(path)
    if not p.is_file():
        raise MeshError(f"{p}: mesh file not found")
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{p}: unsupported mesh format {p.suffix!r} (use {', '.join(MESH_SUFFIXES)})")
    try:
        loaded = trimesh.load(str(p), process=False)
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
                geoms.append(g)
    elif isinstance(loaded, trimesh.Trimesh):
        geoms = [loaded]
    else:
        geoms = []
    if not geoms:
        raise MeshError(f"{p}: file contains no triangle mesh (point cloud or empty scene)")
    verts, tris, uvs, texture = [], [], [], None
    have_uv = all(getattr(g.visual, "uv", None) is not None and len(g.visual.uv) == len(g.vertices) for g in geoms)
    off = 0
    for g in geoms:
        verts.append(np.asarray(g.vertices, dtype=np.float64))
        tris.append(np.asarray(g.faces, dtype=np.int64) + off)
        off += len(g.vertices)
        if have_uv:
            uvs.append(np.asarray(g.visual.uv, dtype=np.float64))
            mat = getattr(g.visual, "material", None)
            if texture is None and mat is not None:
                texture = _image_bytes(getattr(mat, "baseColorTexture", None) or getattr(mat, "image", None))
    mesh = HeadMesh(
        vertices=np.concatenate(verts),
        triangles=np.concatenate(tris) if tris else np.zeros((0, 3), np.int64),
        uvs=np.concatenate(uvs) if have_uv else None,
        texture=texture if texture is not None or not have_uv else _sibling_texture(p),
        name=str(p),
    )
    check_mesh(mesh)
    return mesh
