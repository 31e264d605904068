"""Head meshes at the edge: read glb/gltf/vrm (:mod:`assets.heads.gltf`) and obj/ply (trimesh) into a :class:`HeadMesh`.

All pieces (primitives, objects) are merged with their node transforms applied; vertex order is
kept as in the file so landmark vertex indices stay valid. glTF morph targets are kept by name
(they drive the head directly, :mod:`assets.heads.targets`), and a VRM avatar's vowel expressions are added as
targets of their own (:mod:`assets.heads.vrm`). Texture: one per material; a mesh
with several textured materials gets one atlas (the tiles side by side, each piece's UVs moved
into its tile), so renderer, browser and exports all handle a single texture. Untextured pieces
take their material colour as vertex colours. Without any material texture, a colour-map image next to the
file is used (named with a whole word col/color/diffuse/albedo/..., else like the mesh, else the only image there;
never a normal, roughness, ... map: :func:`_sibling_texture`).
UVs follow glTF's convention (v down, image row 0 at v = 0); OBJ/PLY UVs (v up) are flipped.
Compressed glTF (meshopt, Draco, KTX2) is decoded first (:mod:`assets.heads.decompress`).
"""

from __future__ import annotations

import io
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assets.errors import MeshError
from assets.files import not_a_file
from realtime_core.normals import triangle_normals

MESH_SUFFIXES = (".glb", ".gltf", ".vrm", ".obj", ".ply")
GLTF_SUFFIXES = (".glb", ".gltf", ".vrm")
"""Read by the glTF reader: a VRM avatar is a binary glTF (its expressions: :mod:`assets.heads.vrm`)."""
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
SKIN_COLOR = (0.80, 0.62, 0.52)
"""RGB in [0, 1] of a head without colours or texture (the renderer paints it so)."""

CUTOUT_ALPHA = 0.5
"""Coverage under which a texel of a head's texture is not drawn. A head's texture has an alpha channel only when a
material of its file is see-through (glTF's MASK and BLEND, an OBJ material's ``d`` or ``map_d``: eyelashes and hair
cards, a cornea or eye-occlusion shell over the eyes): the loader bakes each material's rule into that channel as 0 or
1 (MASK at its own cutoff, BLEND at half coverage: one mesh drawn in one pass has no order to blend in), so the
renderer, the browser viewer and the glb exports cut at this one value (:func:`texture_cutout`)."""


def texture_cutout(texture: bytes | None) -> bool:
    """True when a head's encoded ``texture`` carries coverage, an alpha channel (:data:`CUTOUT_ALPHA`)."""
    if texture is None:
        return False
    from PIL import Image

    try:
        with Image.open(io.BytesIO(texture)) as im:  # the header only
            return im.mode in ("RGBA", "LA", "PA") or "transparency" in im.info
    except OSError:  # not an image: the renderer names the file when it decodes it
        return False


def _png(img) -> bytes:
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def _opaque(texture: bytes) -> bytes:
    """``texture`` as PNG or JPEG (glTF's core formats, which every glb export and browser reads; a WebP or AVIF
    image becomes PNG) without an alpha channel (an opaque material's alpha may hold anything: smoothness, a mask)."""
    core = texture[:8] == b"\x89PNG\r\n\x1a\n" or texture[:3] == b"\xff\xd8\xff"
    if core and not texture_cutout(texture):
        return texture
    from PIL import Image

    return _png(Image.open(io.BytesIO(texture)).convert("RGB"))


def _covered(image, material) -> object:
    """A material's base image (PIL) as drawn: RGB for an opaque material, else RGBA whose alpha is its coverage
    baked to 0 / 1 (:data:`CUTOUT_ALPHA`); an RGB image again when every texel is covered."""
    from PIL import Image

    if material is None or material.alpha_mode == "OPAQUE":
        return image.convert("RGB")
    rgba = np.array(image.convert("RGBA"))
    if material.coverage is not None:
        # An OBJ's map_d: its alpha channel when it has one (Blender writes the RGBA base image there), else its grey.
        given = Image.open(io.BytesIO(material.coverage))
        cover = given.getchannel("A") if given.mode in ("RGBA", "LA") else given.convert("L")
        a = np.asarray(cover.resize(image.size, Image.Resampling.BILINEAR), dtype=np.float64) / 255.0
    else:
        a = rgba[..., 3] / 255.0
    a = a * float(material.color[3])
    cut = material.alpha_cutoff if material.alpha_mode == "MASK" else CUTOUT_ALPHA
    rgba[..., 3] = np.where(a >= cut, 255, 0)
    return Image.fromarray(rgba, "RGBA") if (rgba[..., 3] == 0).any() else Image.fromarray(rgba[..., :3], "RGB")


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


def vertex_normals(
    v: np.ndarray,
    t: np.ndarray,
    part: np.ndarray | None = None,
    *,
    together: np.ndarray | None = None,
    seams: PartSeams | None = None,
) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32 of vertices (n, 3) and triangles (m, 3), the
    smooth shading the renderer and the glb exports share. A vertex no triangle with area touches gets
    +z: glTF requires every NORMAL to be unit length, and such a vertex draws nothing anyway.
    ``part`` (n,): each vertex's part; a vertex also takes the faces of the vertices of other parts at its position
    (the seam of a head exported as several meshes, a separate jaw: shaded from one side each, its two sides showed
    a jagged line of light and shade along the seam, issue 12). Copies within one part (a texture seam, a cut lip
    seam's two sides) keep their own normals, as without ``part``, unless ``together`` joins them.
    together (n,) int or None: vertices with the same value share one normal, the sum over all of them
    (texture-seam twins: split, each side's normal sees only its own triangles and the seam shows as a
    crease in the lighting).
    seams: :func:`part_seams` of ``part`` found once (a renderer drawing many frames of one head: the copies of a
    seam stay together, so the positions need not be welded again every frame); used instead of ``part``.

    Not trimesh's: ``Trimesh.vertex_normals`` weights by corner angle (median 1.5, at worst 63 degrees off
    these on the built-in head; 1.2 and 135 on Lee Perry-Smith: every render and export would change) and
    leaves unused vertices zero; ``trimesh.geometry.mean_vertex_normals`` of :func:`triangle_normals` is this
    rule (equal to 3e-16), but importing trimesh costs the viewers, which draw with these, 0.8 s more."""
    v = np.asarray(v)
    t = np.asarray(t)
    fn = triangle_normals(v, t).astype(np.float64)
    # bincount, not np.add.at: the renderer calls this every frame and np.add.at is ~10x slower.
    n = np.stack(
        [np.bincount(t.reshape(-1), weights=np.repeat(fn[:, c], 3), minlength=len(v)) for c in range(3)], axis=1
    )
    if seams is None and part is not None:
        seams = part_seams(v, part)
    if seams is not None:
        n = seams.with_other_parts(n)
    if together is not None:
        owner = np.asarray(together)
        n = np.stack([np.bincount(owner, weights=n[:, c]) for c in range(3)], axis=1)[owner]
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), [0.0, 0.0, 1.0])
    return out.astype(np.float32)


def target_normal_deltas(
    v: np.ndarray, t: np.ndarray, targets: np.ndarray, part: np.ndarray | None = None
) -> np.ndarray:
    """(T, n, 3) float32 per-target normal deltas of a head driven by its own morph targets: the
    :func:`vertex_normals` of ``v + targets[j]`` (the target at weight 1) minus those of ``v`` (n, 3), with the same
    ``part`` seams (found once, at rest). glTF morph targets carry them as NORMAL (three.js blends them, morphNormals):
    without them a viewer lights every pose with the rest normals (a lower lip turned down keeps its rest shading).
    A weighted sum of these deltas added to the rest normals and renormalised approximates the normals of the
    blended shape (docs/animation.md measures how closely at /a/, /u/ and a smile); exactly 0 on the vertices no
    target's triangles touch, so a sparse store keeps only the moved vertices and their neighbours."""
    v = np.asarray(v, dtype=np.float64)
    d = np.asarray(targets, dtype=np.float64)
    seams = None if part is None else part_seams(v, part)
    rest = vertex_normals(v, t, seams=seams)
    out = np.empty(d.shape, dtype=np.float32)
    for j in range(len(d)):
        out[j] = vertex_normals(v + d[j], t, seams=seams) - rest
    return out


@dataclass(frozen=True)
class PartSeams:
    """Where the meshes of a head made of several meet: ``canon`` (n,) each vertex's welded position (as the rig
    welds) and ``group`` (n,) its (position, part) pair."""

    canon: np.ndarray
    group: np.ndarray

    def with_other_parts(self, n: np.ndarray) -> np.ndarray:
        """``n`` (n, 3) summed face normals -> each vertex's plus those of the vertices of other parts at its
        position: its position's whole sum minus its own part's other copies."""
        per_position = np.stack([np.bincount(self.canon, weights=n[:, c]) for c in range(3)], axis=1)
        per_group = np.stack([np.bincount(self.group, weights=n[:, c]) for c in range(3)], axis=1)
        return n + per_position[self.canon] - per_group[self.group]


def part_seams(v: np.ndarray, part: np.ndarray) -> PartSeams | None:
    """:class:`PartSeams` of vertices ``v`` (n, 3) in parts ``part`` (n,); None for a head of one part."""
    from realtime_core.face.welding import weld

    p = np.asarray(part, dtype=np.int64)
    if len(np.unique(p)) < 2:
        return None
    canon, _ = weld(np.asarray(v, dtype=np.float64))
    _, group = np.unique(canon * (int(p.max()) + 1) + p, return_inverse=True)
    return PartSeams(canon=canon, group=group.reshape(-1))


# Whole words of an image's name (split at non-letters and camelCase: "Head_BaseColor" -> head, base, color) that
# name a colour map, and those that name another kind of map (never a colour map, whatever else the name says).
COLOUR_MAP_WORDS = frozenset({"col", "color", "colour", "basecolor", "diffuse", "albedo", "diff"})
OTHER_MAP_WORDS = frozenset(
    {
        "normal", "nrm", "norm", "rough", "roughness", "gloss", "glossiness", "spec", "specular", "ao",
        "occlusion", "ambientocclusion", "bump", "height", "disp", "displacement", "metal", "metallic",
        "metalness", "opacity", "alpha", "emissive", "emission", "orm",
        "tangent",  # a tangent-space normal map (three.js's Lee Perry-Smith: Infinite-Level_02_Tangent_SmoothUV.jpg)
    }
)  # fmt: skip


def name_words(stem: str) -> list[str]:
    """The lower-case words of a file name's stem: split at anything not a letter or digit and at camelCase
    boundaries ("Map-COL" -> map, col; "headNormal_col" -> head, normal, col; "collar" -> collar)."""
    return [w.lower() for w in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|[0-9]+", stem)]


def _painted(colors: np.ndarray | None) -> bool:
    """Whether a mesh's vertex colours (n, 3) in [0, 1] paint it: they vary over it by more than 1/255 in a channel.
    Such a mesh has said its colour, and an image beside it is none of its: facecast's own glb exports carry UVs and
    COLOR_0, and ``render --head take.glb`` drew the built-in head's export in a frame grab lying beside it
    (``take_0.3.png``, "named like the mesh"; its automatic landmarks, found on that render, then failed the rig
    checks). One colour everywhere (a default white) says nothing: such a mesh still takes the colour map beside it."""
    return colors is not None and len(colors) > 0 and float(np.ptp(colors, axis=0).max()) > 1 / 255


def _sibling_texture(path: Path) -> bytes | None:
    """The colour map beside a mesh whose materials name no image (the fallback: a material's image decides
    first, :func:`_assemble`): among the images there that are not another kind of map (``OTHER_MAP_WORDS``:
    normal, roughness, ...), those named a colour map (``COLOUR_MAP_WORDS``, whole words: not "collar"), else
    those named like the mesh, else the only image; of several, the one sharing most words with the mesh's name
    (then the first by name), with a warning naming it and how to choose another. None when nothing fits."""
    images = sorted(p for p in path.parent.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES and p.is_file())
    words = {p: set(name_words(p.stem)) for p in images}
    candidates = [p for p in images if not words[p] & OTHER_MAP_WORDS]
    mesh_words = set(name_words(path.stem))
    hits = [p for p in candidates if words[p] & COLOUR_MAP_WORDS] or [
        p for p in candidates if mesh_words and mesh_words <= words[p]
    ]
    if not hits and len(candidates) == 1:
        hits = candidates
    if not hits:
        return None
    chosen = min(hits, key=lambda p: (-len(words[p] & mesh_words), p.name))
    if len(hits) > 1:
        others = ", ".join(p.name for p in hits if p != chosen)
        print(
            f"facecast: warning: {path}: its materials name no texture and {len(hits)} images beside it could be its "
            f"colour map; using {chosen.name} (not {others}). To use another, name it in the material (map_Kd in the "
            ".mtl, baseColorTexture in glTF) or keep one colour map beside the mesh",
            file=sys.stderr,
        )
    return chosen.read_bytes()


def check_mesh(mesh: HeadMesh) -> None:
    """Raise MeshError (naming ``mesh.name``) if the mesh cannot be rigged."""
    v, t = mesh.vertices, mesh.triangles
    if len(t) == 0:
        raise MeshError(f"{mesh.name}: mesh has no faces")
    if len(v) < 4 or not np.all(np.isfinite(v)):
        raise MeshError(f"{mesh.name}: mesh has too few vertices or non-finite coordinates")
    area = 0.5 * np.linalg.norm(triangle_normals(v, t), axis=1)
    extent = float(np.ptp(v, axis=0).max())
    if not extent > 0 or area.sum() <= 1e-12 * extent**2:
        raise MeshError(f"{mesh.name}: mesh is degenerate (zero extent or zero total area)")
    sv = np.linalg.svd(v - v.mean(0), compute_uv=False)
    if sv[2] < 1e-6 * sv[0]:
        raise MeshError(f"{mesh.name}: mesh is flat (all vertices in one plane); a head must be 3D")


def load_mesh(path: str | Path, *, cache: Path | None = None, parts: tuple[str | Path, ...] = ()) -> HeadMesh:
    """Read a head mesh (glb/gltf/vrm/obj/ply), with ``parts``: further files of the same head (eyes,
    teeth, tongue delivered separately) appended after it in the given order, so the head file's
    vertex indices stay valid; each file's pieces are parts named ``STEM:OBJECT`` (see
    :mod:`assets.heads.parts`). Raises MeshError naming the file on any problem."""
    p = Path(path)
    pieces = [_file_parts(p, cache)]
    for q in parts:
        got = _file_parts(Path(q), cache)
        got.part_names = tuple(f"{Path(q).stem}:{n}" for n in got.part_names)
        pieces.append(got)
    mesh = _assemble(p, _concat(pieces) if len(pieces) > 1 else pieces[0], cache)
    check_mesh(mesh)
    return mesh


def _concat(pieces: list[_Parts]) -> _Parts:
    """One _Parts of several files: vertices, materials and part names appended in order."""
    nv = np.cumsum([0] + [len(x.vertices) for x in pieces])
    nm = np.cumsum([0] + [len(x.materials) for x in pieces])
    npart = np.cumsum([0] + [len(x.part_names) for x in pieces])
    uvs = None
    if any(x.uvs is not None for x in pieces):  # a piece without UVs samples a corner of its (colour) tile
        uvs = np.concatenate([x.uvs if x.uvs is not None else np.zeros((len(x.vertices), 2)) for x in pieces])
    colors = None
    if any(x.colors is not None for x in pieces):
        colors = np.concatenate([x.colors if x.colors is not None else np.ones((len(x.vertices), 3)) for x in pieces])
    targets = {}
    # In the files' order (a VRM's expressions first, as read, so they stay the vowels' first spelling); a part
    # without the target does not move with it.
    for k in dict.fromkeys(k for x in pieces for k in x.targets):
        targets[k] = np.concatenate([x.targets.get(k, np.zeros((len(x.vertices), 3))) for x in pieces])
    return _Parts(
        vertices=np.concatenate([x.vertices for x in pieces]),
        triangles=np.concatenate([x.triangles + nv[i] for i, x in enumerate(pieces)]),
        uvs=uvs,
        colors=colors,
        material=np.concatenate([np.where(x.material >= 0, x.material + nm[i], -1) for i, x in enumerate(pieces)]),
        materials=[m for x in pieces for m in x.materials],
        part=np.concatenate([x.part.astype(np.int16) + npart[i] for i, x in enumerate(pieces)]).astype(np.int16),
        part_names=tuple(n for x in pieces for n in x.part_names),
        targets=targets,
    )


def _file_parts(p: Path, cache: Path | None) -> _Parts:
    """One mesh file's pieces (MeshError naming it when it is missing, unsupported or has no triangles)."""
    if not p.is_file():
        raise MeshError(f"{p}: mesh file {not_a_file(p)} (give a .glb, .gltf, .vrm, .obj or .ply head, or 'builtin')")
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{p}: unsupported mesh format {p.suffix!r}; convert it to one of {', '.join(MESH_SUFFIXES)}")
    suffix = p.suffix.lower()
    if suffix in GLTF_SUFFIXES:
        parts = _gltf_parts(p, cache)
    elif suffix == ".obj":
        from assets.heads.obj import read_obj

        o = read_obj(p)
        parts = _Parts(o.vertices, o.triangles, o.uvs, None, o.material, o.materials, o.group, tuple(o.group_names), {})
    else:
        parts = _ply_parts(p)
    if len(parts.triangles) == 0:
        raise MeshError(
            f"{p}: file contains no triangle mesh (point cloud or empty scene); export the head as triangles"
        )
    return parts


@dataclass
class _Parts:
    """A mesh before textures are resolved: per-vertex material index (-1 none) into ``materials``."""

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None
    colors: np.ndarray | None
    material: np.ndarray
    materials: list
    part: np.ndarray
    part_names: tuple[str, ...]
    targets: dict[str, np.ndarray]


def _gltf_parts(p: Path, cache: Path | None) -> _Parts:
    from assets.heads.decompress import decompressed
    from assets.heads.gltf import NEEDS_DECODER, UNREADABLE_HINT, read_gltf, read_gltf_document
    from assets.heads.vrm import VRM0_TURN, expression_targets, is_vrm0, vrm_expressions

    try:
        doc, _ = read_gltf_document(p)
    except Exception as exc:  # a bad file raises many unrelated types (struct, json, unicode)
        raise MeshError(f"{p}: not a readable glTF file ({exc}); {UNREADABLE_HINT}") from exc
    used = set(doc.get("extensionsRequired", [])) | set(doc.get("extensionsUsed", []))
    src = decompressed(p, cache) if used & set(NEEDS_DECODER) else p
    prims, materials = read_gltf(src)
    if not prims:
        return _Parts(
            np.zeros((0, 3)),
            np.zeros((0, 3), np.int64),
            None,
            None,
            np.zeros(0, np.int64),
            [],
            np.zeros(0, np.int16),
            (),
            {},
        )
    n = [len(x.vertices) for x in prims]
    offs = np.concatenate([[0], np.cumsum(n)])
    have_uv = all(x.uvs is not None for x in prims)
    colors = None
    if any(x.colors is not None for x in prims):
        colors = np.concatenate([x.colors if x.colors is not None else np.ones((len(x.vertices), 3)) for x in prims])
    names = sorted({k for x in prims for k in x.targets})
    # A VRM's vowel expressions first: where the file's own targets spell the same vowel (VRoid's Fcl_MTH_A, which
    # its "aa" binds), match_targets keeps the first spelling, the expression as the file defines the vowel.
    targets = expression_targets(p, prims, vrm_expressions(p, doc), set(names))
    for k in names:
        d = np.zeros((int(offs[-1]), 3))
        for i, x in enumerate(prims):
            if k in x.targets:
                d[offs[i] : offs[i + 1]] = x.targets[k]
        targets[k] = d
    vertices = np.concatenate([x.vertices for x in prims])
    if is_vrm0(doc):  # a VRM 0.x avatar faces -z: turned to face +z as glTF's and VRM 1.0's do
        vertices = vertices * VRM0_TURN
        targets = {k: d * VRM0_TURN for k, d in targets.items()}
    return _Parts(
        vertices=vertices,
        triangles=np.concatenate([x.triangles + offs[i] for i, x in enumerate(prims)]),
        uvs=np.concatenate([x.uvs for x in prims]) if have_uv else None,
        colors=colors,
        material=np.concatenate([np.full(len(x.vertices), x.material) for x in prims]),
        materials=materials,
        part=np.concatenate([np.full(len(x.vertices), i, dtype=np.int16) for i, x in enumerate(prims)]),
        part_names=tuple(x.node for x in prims),
        targets=targets,
    )


def _ply_parts(p: Path) -> _Parts:
    import trimesh

    try:
        g = trimesh.load(str(p), process=False, maintain_order=True, force="mesh")
    except Exception as exc:  # trimesh raises many unrelated types for a bad file
        why = f"{type(exc).__name__}: {exc}"
        raise MeshError(f"{p}: malformed PLY ({why}); re-export the head as .glb or .obj") from exc
    v = np.asarray(getattr(g, "vertices", np.zeros((0, 3))), dtype=np.float64)
    t = np.asarray(getattr(g, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    uv = getattr(getattr(g, "visual", None), "uv", None)
    uv = None if uv is None or len(uv) != len(v) else np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])  # v up -> down
    colors = None
    vc = getattr(getattr(g, "visual", None), "vertex_colors", None)
    if getattr(getattr(g, "visual", None), "kind", None) == "vertex" and vc is not None and len(vc) == len(v):
        colors = np.asarray(vc, dtype=np.float64)[:, :3] / 255.0
    return _Parts(v, t, uv, colors, np.full(len(v), -1), [], np.zeros(len(v), np.int16), (p.stem,), {})


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, dtype=np.float64), 0, 1)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB colours in [0, 1] (facecast's, as HeadMesh holds them) -> linear light (glTF's COLOR_0),
    IEC 61966-2-1; the inverse of how a glTF file's colours are read here."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0, 1)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _assemble(p: Path, parts: _Parts, cache: Path | None = None) -> HeadMesh:
    """Resolve textures: one material image -> that texture; several -> an atlas; none -> material
    colours as vertex colours (or a sibling colour map)."""
    from PIL import Image

    mats = parts.materials
    used = sorted({int(m) for m in np.unique(parts.material) if m >= 0})
    images: list[bytes] = []
    for m in used:
        img = getattr(mats[m], "image", None)
        if img is not None and img not in images:
            images.append(img)
    texture, uvs = None, parts.uvs
    see_through = [m for m in used if getattr(mats[m], "alpha_mode", "OPAQUE") != "OPAQUE"]
    if images and parts.uvs is not None:
        single = (
            len(images) == 1
            and all(getattr(mats[m], "image", None) is not None for m in used)
            and (parts.material >= 0).all()
            and (not see_through or len(used) == 1)
        )
        if single and see_through:
            texture = _png(_covered(Image.open(io.BytesIO(images[0])), mats[used[0]]))
        elif single:
            texture = _opaque(images[0])
        else:
            texture, uvs = _atlas(parts, images, cache)
    elif parts.uvs is not None and any(float(mats[m].color[3]) < CUTOUT_ALPHA for m in see_through):
        # No image, but a see-through material (a cornea over the eyes): colour tiles carry its coverage.
        texture, uvs = _atlas(parts, images, cache)
    elif parts.uvs is not None and not _painted(parts.colors):
        texture = _sibling_texture(p)
        texture = None if texture is None else _opaque(texture)
        if texture is not None and p.suffix.lower() in GLTF_SUFFIXES:
            # An image beside a glTF that does not reference it was made for three.js's
            # TextureLoader (flipY = true, e.g. the Lee Perry-Smith example): flip it into glTF's convention.
            buf = io.BytesIO()
            Image.open(io.BytesIO(texture)).convert("RGB").transpose(Image.Transpose.FLIP_TOP_BOTTOM).save(buf, "PNG")
            texture = buf.getvalue()
    colors = None
    if texture is None and (used or parts.colors is not None):
        base = np.ones((len(parts.vertices), 3))
        for m in used:
            base[parts.material == m] = np.asarray(mats[m].color[:3])
        lin = base * (parts.colors if parts.colors is not None else 1.0)
        colors = _linear_to_srgb(lin).astype(np.float32)
        if parts.colors is None and not used:
            colors = None
    return HeadMesh(
        vertices=parts.vertices,
        triangles=parts.triangles,
        uvs=uvs,
        texture=texture,
        colors=colors,
        name=str(p),
        targets=parts.targets or None,
        part=parts.part,
        part_names=parts.part_names,
    )


ATLAS_MAX_TILE = 2048
ATLAS_VERSION = 1
"""Bump when :func:`_atlas_png` draws other pixels from the same tiles: a head's atlas is kept in
``<cache>/atlas/v<ATLAS_VERSION>_<key>.png`` (:func:`_kept_atlas`)."""
ATLAS_CACHE_FAMILY = re.compile(r"v[0-9]+_[0-9a-f]{32}\.png")


def _atlas(parts: _Parts, images: list[bytes], cache: Path | None = None) -> tuple[bytes, np.ndarray]:
    """One PNG with every material's image (or colour) as a square tile, and the UVs moved into the tiles. The PNG
    is read from the cache when its tiles were drawn before (:func:`_kept_atlas`)."""
    from PIL import Image

    tiles: list[tuple[str, Any, Any]] = []  # (kind "image" | "colour", its bytes | (r, g, b), its material)
    tile_of_material: dict[int, int] = {}
    tile_keys: dict[tuple, int] = {}  # (image or colour, the material's coverage rule) -> tile
    for m in sorted({int(x) for x in np.unique(parts.material)}):
        mat = parts.materials[m] if m >= 0 else None
        img = getattr(mat, "image", None)
        rule = (
            None
            if mat is None or mat.alpha_mode == "OPAQUE"
            else (mat.alpha_mode, mat.alpha_cutoff, float(mat.color[3]), mat.coverage)
        )
        if img is not None:
            key: tuple = ("image", images.index(img), rule)
            if key not in tile_keys:
                tile_keys[key] = len(tiles)
                tiles.append(("image", img, mat))
            tile_of_material[m] = tile_keys[key]
            continue
        base = np.ones(3) if mat is None else np.asarray(mat.color[:3])
        rgb = tuple(int(x) for x in np.round(_linear_to_srgb(base) * 255))
        key = ("colour", rgb, rule)
        if key not in tile_keys:
            tile_keys[key] = len(tiles)
            tiles.append(("colour", rgb, mat))
        tile_of_material[m] = tile_keys[key]
    # A tile's size is its image's (the header's: _covered keeps it), an 8 x 8 block for a colour.
    sizes = [Image.open(io.BytesIO(src)).size if kind == "image" else (8, 8) for kind, src, _ in tiles]
    size = min(ATLAS_MAX_TILE, max(max(wh) for wh in sizes))
    n = len(tiles)
    cols = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    png = _kept_atlas(tiles, size, cols, rows, cache)
    margin = 1.0 / size  # a texel inside the tile: bilinear filtering never reads the neighbour
    uv = np.asarray(parts.uvs, dtype=np.float64)
    uv = np.where((uv >= 0) & (uv <= 1), uv, uv - np.floor(uv))  # repeat-wrapped UVs folded into [0, 1)
    k = np.array([tile_of_material[int(m)] for m in parts.material], dtype=np.int64)
    c, r = k % cols, k // cols
    u = (c + margin + uv[:, 0] * (1 - 2 * margin)) / cols
    v = (r + margin + uv[:, 1] * (1 - 2 * margin)) / rows
    return png, np.column_stack([u, v])


def _atlas_png(tiles: list[tuple[str, Any, Any]], size: int, cols: int, rows: int) -> bytes:
    """The atlas of :func:`_atlas`: each tile (kind, image bytes or colour, material) as the material draws it
    (:func:`_covered`), resized to ``size`` square, in ``cols`` x ``rows``, as PNG."""
    from PIL import Image

    drawn: list[Any] = [
        _covered(Image.open(io.BytesIO(src)) if kind == "image" else Image.new("RGBA", (8, 8), (*src, 255)), mat)
        for kind, src, mat in tiles
    ]
    mode = "RGBA" if any(t.mode == "RGBA" for t in drawn) else "RGB"
    atlas = Image.new(mode, (cols * size, rows * size), (0, 0, 0, 255) if mode == "RGBA" else (0, 0, 0))
    for i, t in enumerate(drawn):
        tile = t.convert(mode).resize((size, size), Image.Resampling.BILINEAR)
        atlas.paste(tile, ((i % cols) * size, (i // cols) * size))
    return _png(atlas)


def _kept_atlas(tiles: list[tuple[str, Any, Any]], size: int, cols: int, rows: int, cache: Path | None) -> bytes:
    """:func:`_atlas_png`, kept in ``<cache>/atlas/v<ATLAS_VERSION>_<key>.png`` (written atomically; files of another
    version written over a day ago removed) under a digest of what it is drawn from: each tile's image bytes or
    colour and its material's coverage rule, the layout and :data:`ATLAS_VERSION`. A multi-material head (a Character
    Creator 4 export: 4 images, 11 materials) decoded, packed and encoded its atlas on every load (0.44 s of a 0.48 s
    warm load of a head driven by its own targets, docs/heads.md). A kept file that is not a whole PNG is drawn
    again; a cache that cannot be written costs time, not the atlas."""
    import hashlib

    from PIL import Image

    from assets.errors import AssetError, CannotWriteError
    from assets.files import atomic_write_bytes
    from assets.heads.cache import cache_dir, remove_stale_siblings

    h = hashlib.sha256(f"atlas {ATLAS_VERSION} {size} {cols} {rows}".encode())
    for kind, src, mat in tiles:
        h.update(f" {kind} ".encode())
        h.update(hashlib.sha256(src).digest() if kind == "image" else repr(src).encode())
        if mat is not None and mat.alpha_mode != "OPAQUE":  # what _covered reads of it
            cover = b"-" if mat.coverage is None else hashlib.sha256(mat.coverage).digest()
            h.update(f" {mat.alpha_mode} {mat.alpha_cutoff!r} {float(mat.color[3])!r} ".encode() + cover)
    try:
        path = (cache or cache_dir()) / "atlas" / f"v{ATLAS_VERSION}_{h.hexdigest()[:32]}.png"
    except AssetError:  # no cache folder can be made: drawn each time
        return _atlas_png(tiles, size, cols, rows)
    try:
        data = path.read_bytes()
        Image.open(io.BytesIO(data)).verify()  # every chunk's CRC up to the end: a file cut short or damaged fails
        return data
    except (OSError, SyntaxError, ValueError):  # none yet, or not a whole PNG (PIL raises SyntaxError on a bad CRC)
        pass
    png = _atlas_png(tiles, size, cols, rows)
    try:
        atomic_write_bytes(path, png)
    except CannotWriteError:
        return png
    remove_stale_siblings(path, ATLAS_CACHE_FAMILY, stale=lambda p: not p.name.startswith(f"v{ATLAS_VERSION}_"))
    return png
