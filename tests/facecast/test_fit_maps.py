"""`facecast fit-maps` writes where it is told, and never into the installed packages unless asked: its
default was the installed realtime_core/fitted_maps.py, so a user running it silently rewrote library code."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import realtime_core
from facecast.cli import main
from realtime_core import fitted_maps

PACKAGE = Path(realtime_core.__file__).resolve().parent


def test_an_output_inside_the_installed_package_is_refused_with_one_line(capsys) -> None:
    """Refused before the fit, exit 2, one line naming the file and the flag; the module the core reads and a
    new file beside it (what the old default and `-o` into the package wrote) are left as they were."""
    module = Path(fitted_maps.__file__)
    before = module.read_bytes(), module.stat().st_mtime_ns
    probe = PACKAGE / "_fit_maps_probe.py"  # a name no one ships: removed below if a fault writes it
    try:
        for out in (probe, module):
            assert main(["fit-maps", "-o", str(out)]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1, err
            assert err.startswith(f"facecast fit-maps: error: {out}: inside the installed facecast package"), err
            assert "'realtime_core'" in err and "--into-package" in err
        assert not probe.exists()
        assert (module.read_bytes(), module.stat().st_mtime_ns) == before
    finally:
        probe.unlink(missing_ok=True)


def test_the_output_is_required(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["fit-maps"])
    assert exc.value.code == 2 and "-o/--output" in capsys.readouterr().err


def test_it_writes_the_fitted_maps_where_it_is_told(tmp_path, capsys) -> None:
    """Outside the packages no flag is needed; the module written holds the committed module's maps."""
    out = tmp_path / "maps" / "fitted.py"
    assert main(["fit-maps", "-o", str(out)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    spec = importlib.util.spec_from_file_location("fitted_probe", out)
    assert spec is not None and spec.loader is not None
    written = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(written)
    from training.fit_maps import ARRAY_NAMES

    for name in ARRAY_NAMES:
        np.testing.assert_allclose(getattr(written, name), getattr(fitted_maps, name), atol=2e-5, rtol=1e-5)
