"""A mesh head driven by its own targets is made once (the fit, its mouth's inside, its checks) and read from the
cache after (``<cache>/morph_heads/<key>.npz``, :func:`assets.heads.head.morph_head`): issue 12, "Heads with ARKit
targets animate through them with no rig step beyond loading"."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from assets.heads.cache import atomic_savez
from assets.heads.head import morph_head, morph_head_generation, morph_head_path
from assets.heads.mesh import HeadMesh
from realtime_core.archive import npz_arrays
from realtime_core.face.checks import EXTREME_POSES

# The built-in head (downloaded on first use).
pytestmark = pytest.mark.system

POSES = np.array([*EXTREME_POSES[::3], (0.0, 0.0, 0.0, 0.0), (0.01, -0.02, 0.13, 0.005)])


@pytest.fixture(scope="module")
def builtin():
    from assets.heads.builtin import load_builtin_head

    return load_builtin_head()


@pytest.fixture
def cache(tmp_path, builtin):
    """An empty cache but for the built-in head's file (linked from the user's: downloaded once)."""
    from assets.heads.builtin import HEAD_FILE
    from assets.heads.cache import cache_dir

    (tmp_path / HEAD_FILE).symlink_to(cache_dir() / HEAD_FILE)
    return tmp_path


def _file_head(b) -> HeadMesh:
    """The built-in head as a file with ARKit targets gives it (the test set's ARKit glb): its teeth and tongue as
    parts of one flat colour each (their inside not yet shaded: the cached mesh's colours differ from the file's)."""
    from assets.heads.builtin import PART_COLORS

    part = np.asarray(b.part)
    return HeadMesh(
        vertices=np.asarray(b.mesh.vertices, dtype=np.float64),
        triangles=np.asarray(b.mesh.triangles, dtype=np.int64),
        colors=PART_COLORS[part].astype(np.float32),
        name="arkit.glb",
        targets={"blendShape1." + k: np.asarray(d, dtype=np.float64) for k, d in b.targets.items()},
        part=part.astype(np.int16),
        part_names=("skin", "eyes", "upper teeth", "lower teeth", "tongue"),
    )


def _builtin_points(mesh: HeadMesh) -> dict[str, list[float]]:
    """A landmark finder (name -> point), as the automatic one answers, on a mesh laid out as the built-in head."""
    from assets.heads.builtin import load_builtin_head

    return {k: mesh.vertices[i].tolist() for k, i in load_builtin_head().landmarks.items()}


def _load(mesh: HeadMesh, cache):
    return morph_head(mesh, cache=cache, landmark_finder=_builtin_points)


def _kept(cache) -> list:
    return sorted((cache / "morph_heads").glob("*.npz"))


def _aged(path, data: bytes | None = None):
    """``path`` (written now with ``data`` when given) last written two days ago."""
    import os
    import time

    from assets.heads.cache import STALE_AFTER_S

    if data is not None:
        path.write_bytes(data)
    t = time.time() - 2 * STALE_AFTER_S
    os.utime(path, (t, t))
    return path


def _same_head(a, b) -> None:
    """Every array, name and figure of two heads is equal, and they pose alike."""
    for f in ("neutral", "triangles", "targets", "moving"):
        np.testing.assert_array_equal(getattr(a.rig, f), getattr(b.rig, f))
    for f in ("gram", "cross", "contact_rest", "contact_rows", "contact_source"):
        np.testing.assert_array_equal(getattr(a.rig.keymap, f), getattr(b.rig.keymap, f))
    assert a.rig.names == b.rig.names and a.rig.meta == b.rig.meta
    for f in ("vertices", "triangles", "colors", "part"):
        np.testing.assert_array_equal(getattr(a.mesh, f), getattr(b.mesh, f))
    assert a.mesh.part_names == b.mesh.part_names and a.mesh.name == b.mesh.name
    np.testing.assert_array_equal(a.rig.weights(POSES), b.rig.weights(POSES))


def test_a_morph_head_loaded_twice_is_the_same_head_the_second_time_read_from_its_cache_file(cache, builtin):
    mesh = _file_head(builtin)
    first = _load(mesh, cache)
    assert first is not None and first.kind == "morph"
    (path,) = _kept(cache)
    checks = first.rig.meta["checks"]
    assert checks["passed"] and first.rig.meta["landmarks"] == _builtin_points(mesh)
    # The inside of its mouth was shaded (its deep teeth darker than the file's flat colours) and kept so.
    assert (first.mesh.colors < mesh.colors - 1e-3).any(axis=1).sum() > 300
    written = path.read_bytes()

    second = _load(mesh, cache)
    assert second is not None and second.rig is not first.rig
    _same_head(first, second)
    assert _kept(cache) == [path] and path.read_bytes() == written  # read, not written again

    # A figure changed in the file comes back as the file has it: the checks were read, not measured again.
    arrays = npz_arrays(written, "morph head")
    meta = json.loads(str(arrays["meta"]))
    meta["checks"]["max_edge_stretch"] = 123.0
    atomic_savez(path, **{**arrays, "meta": np.array(json.dumps(meta))})
    third = _load(mesh, cache)
    assert third is not None and third.rig.meta["checks"]["max_edge_stretch"] == 123.0
    np.testing.assert_array_equal(third.rig.weights(POSES), first.rig.weights(POSES))

    # The same content under another path shares the entry and is named as given now.
    moved = _load(replace(mesh, name="elsewhere/arkit.glb"), cache)
    assert moved is not None and _kept(cache) == [path]
    assert moved.mesh.name == "elsewhere/arkit.glb" and moved.rig.meta["head"] == "elsewhere/arkit.glb"


def test_a_mesh_with_one_vertex_moved_is_a_new_entry(cache, builtin):
    mesh = _file_head(builtin)
    first = _load(mesh, cache)
    (path,) = _kept(cache)
    # Written a day ago and more: another head's entry of this generation (kept, as the rig cache keeps a current
    # rig), one of an older generation (removed when the next entry is written), and a file of another name.
    arrays = npz_arrays(path.read_bytes(), "morph head")
    info = json.loads(str(arrays["head_meta"]))
    other = _aged(path.with_name("a" * 32 + ".npz"), path.read_bytes())
    older = np.array(json.dumps({**info, "generation": "0" * 32}))
    atomic_savez(path.with_name("b" * 32 + ".npz"), **{**arrays, "head_meta": older})
    stale = _aged(path.with_name("b" * 32 + ".npz"))
    notes = _aged(path.with_name("notes.npz"), b"not a cache entry")
    v = mesh.vertices.copy()
    far = int(np.argmax(np.linalg.norm(v - v.mean(axis=0), axis=1)))  # away from the mouth: the same rig else
    v[far] += 0.01 * np.ptp(v, axis=0).max()
    changed = _load(replace(mesh, vertices=v), cache)
    assert first is not None and changed is not None
    assert not stale.exists() and other.exists() and notes.exists()
    kept = [p for p in _kept(cache) if p not in (other, notes)]
    assert len(kept) == 2 and path in kept
    np.testing.assert_array_equal(changed.mesh.vertices[far], v[far])
    np.testing.assert_array_equal(changed.rig.neutral[far], v[far].astype(np.float32))
    assert not np.array_equal(changed.rig.neutral, first.rig.neutral)


def test_a_corrupt_or_foreign_cache_file_is_made_again_and_rewritten(cache, builtin):
    mesh = _file_head(builtin)
    path = morph_head_path(mesh, None, _builtin_points, morph_head_generation(builtin), cache=cache)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"PK\x03\x04 not a zip at all")
    made = _load(mesh, cache)
    assert made is not None and made.rig.meta["checks"]["passed"]
    assert _kept(cache) == [path]
    _same_head(made, _load(mesh, cache))  # rewritten readable: read back as made
    # A file of another generation (written by an older facecast under the same name) is made again too.
    arrays = npz_arrays(path.read_bytes(), "morph head")
    info = json.loads(str(arrays["head_meta"]))
    meta = json.loads(str(arrays["meta"]))
    meta["checks"]["max_edge_stretch"] = 123.0
    arrays |= {"head_meta": np.array(json.dumps({**info, "generation": "0" * 32})), "meta": np.array(json.dumps(meta))}
    atomic_savez(path, **arrays)
    again = _load(mesh, cache)
    assert again is not None and again.rig.meta["checks"]["max_edge_stretch"] != 123.0
    _same_head(made, again)
    assert json.loads(str(npz_arrays(path.read_bytes(), "morph head")["head_meta"]))["generation"] == info["generation"]
