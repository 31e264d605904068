"""Commands that take --head say, in one line, when the head fails the rig checks (and use it anyway)."""

from __future__ import annotations

import pytest

from assets.heads.head import Head


def test_commands_say_when_a_head_fails_its_checks(shared_data, capsys):
    """One line on stderr naming the failed figures and the way forward; nothing for a passing head."""
    from dataclasses import replace

    from assets.heads.wfm import candide_head
    from facecast.commands.headopts import warn_failing_checks

    good = candide_head(shared_data / "candide3" / "candide3-3.1.6.wfm")
    warn_failing_checks(good, "candide.wfm")
    assert capsys.readouterr().err == ""
    # The same head with its jaw drop turned 40 times too far: the mouth folds over the chin.
    targets = good.rig.targets.copy()
    targets[2] *= 40.0
    bad = Head(replace(good.rig, targets=targets), good.mesh)
    warn_failing_checks(bad, "folded.wfm")
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "folded.wfm fails the rig checks" in err[0] and "flipped triangles" in err[0] and "--landmarks" in err[0]
    assert "may tear or fold" in err[0]


def test_a_head_failing_only_mildly_is_told_what_it_looks_like():
    """A failure that tears nothing (lips apart at closure, a small opening) says what a viewer sees instead of
    "the mouth may tear or fold"; with a fold among them, the fold's sentence."""
    from facecast.commands.headopts import _what_it_means

    assert _what_it_means(["lips 0.0111 IOD apart at closure"]) == "The lips may not meet at /p b m/"
    both = _what_it_means(["lips 0.0111 IOD apart at closure", "the lips part by 0.41 of the mouth opening asked"])
    assert both == "The lips may not meet at /p b m/; the mouth opens less than the speech asks"
    assert _what_it_means(["lips 0.0111 IOD apart at closure", "2 flipped triangles at pose (0, 0, 0.4, 0)"]) == (
        "The mouth may tear or fold"
    )


@pytest.mark.slow  # a real first rig of the MediaPipe face (~10 s)
def test_a_first_rig_is_checked_once_and_a_reload_not_again(shared_data, own_cache, tmp_path, monkeypatch, capsys):
    """`--head MESH` on a mesh not rigged yet measured the rig checks twice (rig_checked, then the warning on the
    fresh rig) and once more at every load of the cached rig. The report is kept in the rig's meta ("checks"):
    one measurement per rig, and the warning still comes from it."""
    from dataclasses import replace

    import realtime_core.face.checks as checks
    from facecast.cli import build_parser
    from facecast.commands.headopts import resolve_from_args, warn_failing_checks

    calls = []
    measure = checks.check_rig

    def counted(*args, **kwargs):
        calls.append(1)
        return measure(*args, **kwargs)

    monkeypatch.setattr(checks, "check_rig", counted)
    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    args = build_parser().parse_args(["say", "hello", "-o", str(tmp_path / "x.glb"), "--head", str(mp)])
    first = resolve_from_args(args)
    assert "rigging" in capsys.readouterr().err  # a mesh rigged now says so (its seconds to minutes)
    assert len(calls) == 1 and len(list((own_cache / "rigs").glob("*.npz"))) == 1
    kept = first.rig.meta["checks"]
    assert kept["passed"] is True and kept["failures"] == [] and kept["flipped_triangles"] == 0
    again = resolve_from_args(args)  # the cached rig
    assert len(calls) == 1 and again.rig.meta["checks"] == kept
    assert capsys.readouterr().err == ""
    failing = {**kept, "passed": False, "failures": ["flipped triangles 3 > 0"]}
    warn_failing_checks(Head(replace(again.rig, meta={**again.rig.meta, "checks": failing}), again.mesh), "mp.obj")
    err = capsys.readouterr().err.strip().splitlines()
    assert len(calls) == 1 and len(err) == 1 and "mp.obj fails the rig checks (flipped triangles 3 > 0)" in err[0]
