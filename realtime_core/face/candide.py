"""Candide-3 ``.wfm`` parser (text in, :class:`FaceModel` out; reading the file is the caller's job).

Format (J. Ahlberg, LiTH-ISY-R-2326): sections introduced by ``# NAME:`` comment lines.
``VERTEX LIST`` and ``FACE LIST`` hold a count then that many rows; ``ANIMATION UNITS LIST`` and
``SHAPE UNITS LIST`` hold a count of units, each unit being one or more comment lines (the first
is its name), a count and rows ``vertex dx dy dz``. ``TEXTURE`` holds u v rows, with a leading
count in some files (the 3.1.6 file has count 0, the UV variant has no count line). Parameter and
global-motion sections are ignored. Column separators vary (tabs, runs of spaces).
"""

from __future__ import annotations

import re

import numpy as np

from realtime_core.errors import ModelFormatError
from realtime_core.face.model import FaceModel, MouthLandmarks

_SECTION = re.compile(r"^#\s*([A-Z][A-Z ]+):\s*$")


def _sections(text: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    cur: list[str] | None = None
    for raw in text.splitlines():
        line = raw.strip()
        m = _SECTION.match(line)
        if m:
            cur = out.setdefault(m.group(1).strip(), [])
            continue
        if cur is not None and line:
            cur.append(line)
    return out


def _rows(lines: list[str], section: str) -> tuple[int, list[list[str]]]:
    data = [ln.split() for ln in lines if not ln.startswith("#")]
    if not data or len(data[0]) != 1:
        raise ModelFormatError(f"wfm section {section}: expected a count line")
    n = int(data[0][0])
    if len(data) - 1 < n:
        raise ModelFormatError(f"wfm section {section}: count {n} but only {len(data) - 1} rows")
    return n, data[1 : n + 1]


def _units(lines: list[str], section: str, n_vertices: int) -> dict[str, np.ndarray]:
    if not lines:
        return {}
    try:
        count = int(lines[0].split()[0])
    except ValueError as exc:
        raise ModelFormatError(f"wfm section {section}: expected a unit count, got {lines[0]!r}") from exc
    units: dict[str, np.ndarray] = {}
    i = 1
    for u in range(count):
        name = None
        while i < len(lines) and lines[i].startswith("#"):
            if name is None:
                name = " ".join(lines[i].lstrip("#").split())
            i += 1
        if i >= len(lines):
            raise ModelFormatError(f"wfm section {section}: file ends inside unit {u}")
        name = name or f"unit{u}"
        k = int(lines[i].split()[0])
        d = np.zeros((n_vertices, 3))
        for row in lines[i + 1 : i + 1 + k]:
            parts = row.split()
            if len(parts) != 4 or row.startswith("#"):
                raise ModelFormatError(f"wfm unit {name!r}: bad row {row!r}")
            idx = int(parts[0])
            if not 0 <= idx < n_vertices:
                raise ModelFormatError(f"wfm unit {name!r}: vertex {idx} out of range")
            d[idx] = [float(x) for x in parts[1:]]
        i += 1 + k
        key, j = name, 2
        while key in units:  # keep duplicate names apart rather than silently overwrite
            key, j = f"{name} #{j}", j + 1
        units[key] = d
    return units


def parse_wfm(text: str, *, name: str = "candide3") -> FaceModel:
    """Parse Candide-3 ``.wfm`` text into a :class:`FaceModel` (model units as in the file).

    Raises ModelFormatError naming the section on malformed input.
    """
    sec = _sections(text)
    for required in ("VERTEX LIST", "FACE LIST"):
        if required not in sec:
            raise ModelFormatError(f"wfm: missing section '# {required}:'")
    try:
        n, vrows = _rows(sec["VERTEX LIST"], "VERTEX LIST")
        vertices = np.array([[float(x) for x in r[:3]] for r in vrows], dtype=np.float64)
        m, frows = _rows(sec["FACE LIST"], "FACE LIST")
        triangles = np.array([[int(x) for x in r[:3]] for r in frows], dtype=np.int64).reshape(m, 3)
        au = _units(sec.get("ANIMATION UNITS LIST", []), "ANIMATION UNITS LIST", n)
        su = _units(sec.get("SHAPE UNITS LIST", []), "SHAPE UNITS LIST", n)
        uvs = None
        tex = [ln.split() for ln in sec.get("TEXTURE", []) if not ln.startswith("#")]
        if tex and len(tex[0]) == 1:  # optional leading count
            tex = tex[1 : 1 + int(tex[0][0])]
        if tex:
            uvs = np.array([[float(x) for x in r[:2]] for r in tex], dtype=np.float64)
            if len(uvs) != n:
                raise ModelFormatError(f"wfm TEXTURE has {len(uvs)} coordinates for {n} vertices")
    except (ValueError, IndexError) as exc:
        raise ModelFormatError(f"wfm: malformed number: {exc}") from exc
    if vertices.shape != (n, 3):
        raise ModelFormatError(f"wfm VERTEX LIST: expected {n} rows of 3 numbers")
    return FaceModel(vertices=vertices, triangles=triangles, uvs=uvs, animation_units=au, shape_units=su, name=name)


CANDIDE3_LANDMARKS: dict[str, int] = {
    "upper_lip": 7,
    "lower_lip": 8,
    "upper_inner": 87,
    "lower_inner": 40,
    "corner_left": 31,
    "corner_right": 64,
    "eye_outer_left": 20,
    "eye_inner_left": 23,
    "eye_outer_right": 53,
    "eye_inner_right": 56,
    "nose_tip": 5,
    "chin": 10,
}
"""Named landmark vertices of Candide-3 (both shipped variants share the vertex list)."""

CANDIDE3_MOUTH_UNITS: tuple[str, ...] = ("upper lip raiser", "lip stretcher", "jaw drop", "lip corner depressor")
"""Substrings (case-insensitive) naming the units that produce the four mouth parameters, in order."""


def candide3_mouth_groups(model: FaceModel) -> tuple[tuple[str, ...], ...]:
    """The calibration groups for a Candide-3 model: one animation unit per mouth parameter.

    Matches :data:`CANDIDE3_MOUTH_UNITS` against the unit names ("AUV0 Upper lip raiser (AU10)" in
    3.1.6, "Upper lip raiser" in the UV variant); raises ModelFormatError if one is missing.
    """
    groups = []
    for key in CANDIDE3_MOUTH_UNITS:
        hits = [n for n in model.animation_units if key in n.lower()]
        if not hits:
            raise ModelFormatError(f"Candide-3 model has no animation unit named like {key!r}")
        groups.append((hits[0],))
    return tuple(groups)


def candide3_mouth_landmarks() -> MouthLandmarks:
    """The :class:`MouthLandmarks` of Candide-3 (from :data:`CANDIDE3_LANDMARKS`): 7/8 outer lip
    midpoints, 87/40 the coincident inner-lip midpoints (upper/lower), 31/64 the lip corners (face's
    left/right), 20/23 and 53/56 the outer/inner eye corners."""
    return MouthLandmarks(**{k: CANDIDE3_LANDMARKS[k] for k in MouthLandmarks.__dataclass_fields__})
