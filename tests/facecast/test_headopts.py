"""Commands that take --head say, in one line, when the head fails the rig checks (and use it anyway)."""

from __future__ import annotations

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
