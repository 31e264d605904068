"""Wavefront OBJ with MTL for heads: several objects and materials, one texture per material.

Vertex order is the file's ``v`` order, so landmark indices written for the file stay valid; a
position that appears with several texture coordinates or materials (a UV seam, a material border)
gets extra copies appended after the file's vertices. UVs are returned in facecast's (glTF's)
convention, v down: ``v_facecast = 1 - v_obj``. Polygons are fan-triangulated.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.errors import MeshError
from assets.heads.gltf import Material


@dataclass
class ObjMesh:
    """vertices (n, 3), triangles (m, 3), uvs (n, 2) or None, material (n,) index into materials
    (-1 none), group (n,) index into group_names (the ``o``/``g`` names)."""

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None
    material: np.ndarray
    materials: list[Material]
    group: np.ndarray
    group_names: list[str]


def _map_file(folder: Path, rest: str) -> Path | None:
    """The image a ``map_*`` statement names: its options (-s, -o, -bm ...) come first, and a Windows exporter's file
    name may hold spaces ("skin colour.png") or backslashes, so the longest tail of words naming a file wins."""
    words = rest.replace("\\", "/").split()
    for i in range(len(words)):
        p = folder / " ".join(words[i:])
        if p.is_file():
            return p
    return None


def _read_mtl(path: Path) -> dict[str, Material]:
    out: dict[str, Material] = {}
    if not path.is_file():
        return out
    cur = None
    cur_d: set[str] = set()  # the materials with a "d" line
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.strip().split(maxsplit=1)
        if not parts:
            continue
        key, rest = parts[0], parts[1] if len(parts) > 1 else ""
        if key == "newmtl":
            cur = rest.strip()
            out[cur] = Material(color=np.ones(4), image=None, name=cur)
        elif cur is None:
            continue
        elif key == "Kd":
            rgb = [float(x) for x in rest.split()[:3]]
            out[cur].color = np.array([*rgb, out[cur].color[3]])  # a "d" line may come first
        elif key == "map_Kd":
            img = _map_file(path.parent, rest)
            if img is not None:
                out[cur].image = img.read_bytes()
        elif key in ("d", "Tr") and rest.split():
            # Dissolve (d: 1 opaque) or its complement (Tr): see-through as glTF's BLEND materials are. A "d" line
            # wins over "Tr" wherever it stands. "Tr 1" alone would make the material invisible, and MeshLab
            # writes exactly that for every opaque material (menpo3d's james.obj scan, a whole face drawn as
            # nothing): read as opacity then, as its writers meant it; any other Tr as the complement.
            a = float(rest.split()[-1])
            if key == "d":
                cur_d.add(cur)
            elif cur in cur_d:
                continue
            opacity = a if key == "d" or a >= 1.0 else 1.0 - a
            out[cur].color[3] = opacity
            if opacity < 1.0:
                out[cur].alpha_mode = "BLEND"
            elif out[cur].alpha_mode == "BLEND":  # an earlier Tr's, now overruled (a map_d's MASK stays)
                out[cur].alpha_mode = "OPAQUE"
        elif key == "map_d":
            img = _map_file(path.parent, rest)
            if img is not None:
                out[cur].coverage = img.read_bytes()
                out[cur].alpha_mode = "MASK"
    return out


@dataclass(frozen=True)
class ObjPolygons:
    """An OBJ file's statements as written: ``positions`` (n, 3) float64; ``texcoords`` (t, 2) float64 (OBJ's v up);
    per polygon its corners as (position, texture coordinate) indices, 0-based (texture -1: none), its material index
    into ``material_names`` (-1: none) and its group index into ``group_names`` (the ``o``/``g`` names, "default"
    before any); ``mtllibs``: each ``mtllib`` statement's words. The one OBJ parser: :func:`read_obj` builds head meshes
    from it, the built-in head's source is read with it."""

    positions: np.ndarray
    texcoords: np.ndarray
    polygons: list[list[tuple[int, int]]]
    polygon_material: list[int]
    polygon_group: list[int]
    material_names: list[str]
    group_names: list[str]
    mtllibs: list[list[str]]


def parse_obj_text(text: str, source: str) -> ObjPolygons:
    """Parse OBJ ``text``; MeshError naming ``source`` and the line on a malformed statement."""
    pos: list[list[float]] = []
    tex: list[list[float]] = []
    polygons: list[list[tuple[int, int]]] = []
    poly_mat: list[int] = []
    poly_grp: list[int] = []
    mat_names: list[str] = []
    groups = ["default"]
    mtllibs: list[list[str]] = []
    mat, grp = -1, 0
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            key = parts[0]
            if key == "v":
                pos.append([float(x) for x in parts[1:4]])
            elif key == "vt":
                tex.append([float(x) for x in parts[1:3]] + [0.0] * (2 - len(parts[1:3])))
            elif key in ("o", "g"):
                name = " ".join(parts[1:]) or "default"
                if name not in groups:
                    groups.append(name)
                grp = groups.index(name)
            elif key == "mtllib":
                mtllibs.append(parts[1:])
            elif key == "usemtl":
                name = " ".join(parts[1:])
                if name not in mat_names:
                    mat_names.append(name)
                mat = mat_names.index(name)
            elif key == "f":
                refs = []
                for ref in parts[1:]:
                    f = ref.split("/")
                    vi = int(f[0])
                    ti = int(f[1]) if len(f) > 1 and f[1] else 0
                    refs.append(
                        (vi - 1 if vi > 0 else len(pos) + vi, (ti - 1 if ti > 0 else len(tex) + ti) if ti else -1)
                    )
                polygons.append(refs)
                poly_mat.append(mat)
                poly_grp.append(grp)
        except (ValueError, IndexError) as exc:
            raise MeshError(f"{source}: line {lineno}: cannot parse {line.strip()[:60]!r}") from exc
    return ObjPolygons(
        positions=np.asarray(pos, dtype=np.float64).reshape(-1, 3),
        texcoords=np.asarray(tex, dtype=np.float64).reshape(-1, 2),
        polygons=polygons,
        polygon_material=poly_mat,
        polygon_group=poly_grp,
        material_names=mat_names,
        group_names=groups,
        mtllibs=mtllibs,
    )


def read_obj(path: Path) -> ObjMesh:
    """Parse ``path`` (and its ``mtllib``); MeshError naming the file on a malformed line."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise MeshError(f"{path}: cannot read: {exc}") from exc
    parsed = parse_obj_text(text, str(path))
    materials: dict[str, Material] = {}
    for words in parsed.mtllibs:
        # Several files, or one whose name holds spaces ("my head.mtl", as Windows exporters write it).
        whole = path.parent / " ".join(words)
        for lib in [whole] if whole.is_file() else [path.parent / x for x in words]:
            materials.update(_read_mtl(lib))
    mat_names, groups = parsed.material_names, parsed.group_names
    # (v, vt, material, group) per triangle corner, the polygons fan-triangulated.
    corners = [
        (vi, ti, mat, grp)
        for refs, mat, grp in zip(parsed.polygons, parsed.polygon_material, parsed.polygon_group, strict=True)
        for k in range(1, len(refs) - 1)
        for vi, ti in (refs[0], refs[k], refs[k + 1])
    ]
    v = parsed.positions
    uv_src = parsed.texcoords
    if not corners:
        return ObjMesh(v, np.zeros((0, 3), np.int64), None, np.full(len(v), -1), [], np.zeros(len(v), np.int64), groups)
    c = np.asarray(corners, dtype=np.int64)
    if c[:, 0].min() < 0 or c[:, 0].max() >= len(v) or (c[:, 1].max() >= len(uv_src)):
        raise MeshError(f"{path}: a face refers to a vertex or texture coordinate that does not exist")
    has_uv = bool(len(uv_src)) and bool((c[:, 1] >= 0).all())
    # One output vertex per distinct (position, uv, material); the first use of a position keeps its index.
    corner_key = np.stack([c[:, 0], c[:, 1] if has_uv else np.zeros(len(c), np.int64), c[:, 2]], axis=1)
    uniq, first_use, inv = np.unique(corner_key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    first_of_pos = np.full(len(v), -1, dtype=np.int64)
    out_index = np.empty(len(uniq), dtype=np.int64)
    extra: list[int] = []
    order = np.argsort(first_use)  # file order of first use
    for u in order:
        p = uniq[u, 0]
        if first_of_pos[p] < 0:
            first_of_pos[p] = u
            out_index[u] = p
        else:
            out_index[u] = len(v) + len(extra)
            extra.append(u)
    n_out = len(v) + len(extra)
    src_pos = np.concatenate([np.arange(len(v)), uniq[extra, 0]]) if extra else np.arange(len(v))
    verts = v[src_pos]
    tris = out_index[inv].reshape(-1, 3)
    uvs = None
    row_of = np.full(n_out, -1, dtype=np.int64)
    row_of[out_index] = np.arange(len(uniq))
    if has_uv:
        uvs = np.zeros((n_out, 2))
        ok = row_of >= 0
        uvs[ok] = uv_src[uniq[row_of[ok], 1]]
        uvs[:, 1] = 1.0 - uvs[:, 1]  # OBJ: v up -> facecast/glTF: v down
    material = np.full(n_out, -1, dtype=np.int64)
    material[out_index] = uniq[:, 2]
    group = np.zeros(n_out, dtype=np.int64)
    group[out_index[inv]] = np.repeat(c[:, 3], 1)
    mats = [materials.get(n, Material(color=np.ones(4), image=None, name=n)) for n in mat_names]
    return ObjMesh(verts, tris, uvs, material, mats, group, groups)
