"""The rule for missing prerequisites: skip with the reason outside CI, fail under CI=true."""

from __future__ import annotations

import pytest

from tests.prerequisites import missing, require_data, require_module, require_tool


@pytest.mark.parametrize("ci,outcome", [("true", pytest.fail.Exception), ("", pytest.skip.Exception)])
def test_a_missing_tool_module_or_data_set_fails_in_ci_and_skips_elsewhere(monkeypatch, tmp_path, ci, outcome):
    monkeypatch.setenv("CI", ci)
    with pytest.raises(outcome, match="no-such-tool-xyz is not installed"):
        require_tool("no-such-tool-xyz")
    with pytest.raises(outcome, match="no_such_module_xyz unavailable"):
        require_module("no_such_module_xyz")
    with pytest.raises(outcome, match="test data not found"):
        require_data(tmp_path / "absent")
    with pytest.raises(outcome, match="why"):
        missing("why")


def test_present_prerequisites_pass_through(monkeypatch, tmp_path):
    monkeypatch.setenv("CI", "true")
    assert require_tool("sh").endswith("sh")
    assert require_module("json").__name__ == "json"
    assert require_data(tmp_path) == tmp_path
