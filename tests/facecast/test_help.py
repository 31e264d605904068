"""Every command's ``--help``: it renders, shows real defaults once, and no empty ones."""

from __future__ import annotations

import re

import pytest

from facecast.cli import COMMANDS, main


@pytest.mark.parametrize("command", list(COMMANDS))
def test_help_states_each_default_once_and_no_empty_ones(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines anywhere: compare unwrapped
    # a description is not %-formatted by argparse (only option helps are): "%%" there prints as is
    assert "%%" not in text
    assert "(default: None)" not in text and "(default: False)" not in text and "(default: [])" not in text
    # one option's help (up to the next option) never states its default twice
    for option in re.split(r"\s(?=-{1,2}[a-z][\w-]* )", text):
        assert option.count("(default") <= 1, option


def test_help_keeps_informative_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["animate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "streaming (live) or batch HMMI (default: stream)" in text
    assert "(default: builtin)" in text


def test_an_off_switch_shows_no_default(capsys):
    """`train --no-energy` (store_false) has the default True, which read as "c0 left out by default"."""
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    option = re.search(r"--no-energy leave c0.*?(?= --level-norm )", text)
    assert option is not None and "(default" not in option.group(0), option


def test_version_names_the_installed_release(capsys):
    """`facecast --version` was "unrecognized arguments"; it prints pyproject's version, exit 0."""
    import tomllib
    from pathlib import Path

    want = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())["project"]["version"]
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"facecast {want}"
