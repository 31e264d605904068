"""The layer contract (pyproject [tool.importlinter]): imports run one way,
core <- assets/wire <- server, clients, training <- benchmarks, perceptual <- facecast, and no package cycle.

The contract is run on the real tree, and on a small fake tree with a deliberate violation to show
that it can fail (a contract that cannot fail checks nothing)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from facecast import PACKAGES
from tests.prerequisites import require_tool

# Runs the lint-imports tool.
pytestmark = pytest.mark.system

REPO = Path(__file__).resolve().parents[2]


def _contract() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]


def _lint_imports(cwd: Path, config: Path) -> subprocess.CompletedProcess[str]:
    # Beside this interpreter (the project's venv) even when it is not activated, else on PATH.
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or require_tool(
        "lint-imports", "dev extra: pip install -e '.[dev]'"
    )
    # The fake tree must shadow the real (editable-installed) packages: put it first on the path.
    env = {"PYTHONPATH": str(cwd), "PATH": str(Path(sys.executable).parent), "HOME": str(cwd)}
    return subprocess.run(
        [exe, "--config", str(config), "--no-cache"], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def test_the_tree_keeps_the_layer_contract():
    r = _lint_imports(REPO, REPO / "pyproject.toml")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "1 kept, 0 broken" in r.stdout, r.stdout


def test_the_contract_names_every_top_level_package():
    contract = _contract()
    assert set(contract["root_packages"]) == set(PACKAGES)
    layered = {p.strip() for layer in contract["contracts"][0]["layers"] for p in layer.split("|")}
    assert layered == set(PACKAGES)
    on_disk = {p.parent.name for p in REPO.glob("*/__init__.py")} - {"tests", "scripts"}
    assert on_disk == set(PACKAGES), f"a top-level package outside the contract: {on_disk ^ set(PACKAGES)}"


@pytest.mark.parametrize(
    "importer,imported,broken",
    [
        ("realtime_core/core.py", "assets", True),  # the core importing the I/O edge
        ("wire/protocol.py", "server", True),  # a layer-2 package importing layer 3
        ("server/app.py", "clients", True),  # siblings in one layer (the old server <-> clients cycle)
        ("training/corpus.py", "facecast", True),  # a library importing the CLI
        ("facecast/cli.py", "server", False),  # the CLI importing a library: allowed
        ("clients/view.py", "wire", False),  # a client importing the wire format: allowed
    ],
)
def test_a_layer_violation_breaks_the_contract(tmp_path, importer, imported, broken):
    """The project's own contract, run on a fake tree of the same packages with one extra import."""
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    for name in (
        "realtime_core/core.py",
        "wire/protocol.py",
        "server/app.py",
        "training/corpus.py",
        "facecast/cli.py",
        "clients/view.py",
    ):
        (tmp_path / name).write_text("")
    (tmp_path / importer).write_text(f"import {imported}\n")
    contract = _contract()
    layers = ",\n".join(f'    "{layer}"' for layer in contract["contracts"][0]["layers"])
    config = tmp_path / "contract.toml"
    config.write_text(
        textwrap.dedent(f"""\
        [tool.importlinter]
        root_packages = {list(PACKAGES)!r}
        [[tool.importlinter.contracts]]
        name = "layers"
        type = "layers"
        layers = [
        """)
        + layers
        + "\n]\n"
    )
    r = _lint_imports(tmp_path, config)
    if broken:
        assert r.returncode != 0 and "BROKEN" in r.stdout, r.stdout + r.stderr
        assert f"{importer[:-3].replace('/', '.')} -> {imported}" in r.stdout, r.stdout
    else:
        assert r.returncode == 0, r.stdout + r.stderr
