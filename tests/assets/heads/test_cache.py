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
