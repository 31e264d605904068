"""Landmark JSON files: ``{"landmarks": {name: vertex_index | [x, y, z], ...}}`` (extra keys allowed).

Shipped files live in ``assets/heads/landmarks/``; :func:`shipped_landmarks` finds one by head
file name. Names: eye_outer/inner_left/right, nose_tip, corner_left/right, upper_lip, lower_lip,
upper_inner, lower_inner, chin ("left" is the face's own left).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from assets.errors import LandmarkError
from assets.files import not_a_file

CREDITS = {
    "leeperrysmith.glb": "Head: Lee Perry-Smith / Infinite Realities (CC BY 3.0)",
    "canonical_face_model.obj": "Face mesh: MediaPipe (Apache-2.0)",
}
"""Attribution to show with renders of known third-party heads (by file name, lower case)."""

SHIPPED = {
    "leeperrysmith.glb": "lee_perry_smith.json",
    "canonical_face_model.obj": "mediapipe_canonical.json",
}


@dataclass(frozen=True)
class FoundLandmarks(Mapping[str, object]):
    """Landmarks found automatically: the mapping name -> [x, y, z] of ``points`` (what any landmark spec is), and
    ``alternatives``, other plausible sets of the same points (the single views' of
    :func:`clients.render.landmarks.find_landmarks`), which :func:`assets.heads.head.rig_checked` rigs from in turn
    when every rig from ``points`` fails its checks (docs/animation.md, "Steadier automatic landmarks")."""

    points: Mapping[str, object]
    alternatives: tuple[Mapping[str, object], ...] = field(default=())

    def __getitem__(self, key: str) -> object:
        return self.points[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.points)

    def __len__(self) -> int:
        return len(self.points)


def read_landmarks(path: str | Path) -> dict[str, object]:
    """The ``landmarks`` mapping of a JSON file; LandmarkError naming the file on any problem."""
    p = Path(path)
    if not p.is_file():
        raise LandmarkError(f"{p}: landmarks file {not_a_file(p)}")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LandmarkError(f"{p}: not valid JSON: {exc}") from exc
    lm = doc.get("landmarks") if isinstance(doc, dict) else None
    if not isinstance(lm, dict):
        raise LandmarkError(f"{p}: expected an object with a 'landmarks' object of name -> vertex index or [x, y, z]")
    return lm


def write_landmarks(path: str | Path, spec: Mapping[str, object], **extra: object) -> Path:
    """Write ``spec`` (name -> vertex index or (3,) point) as the file :func:`read_landmarks` reads, atomically: vertex
    indices stay indices, points become [x, y, z] (floats written exactly: the file gives back the same points);
    ``extra``: other top-level keys (where the points came from)."""
    import numpy as np

    from assets.files import atomic_write_bytes

    points = {k: np.asarray(v).tolist() for k, v in spec.items()}  # an index (numpy's too) stays an int
    # one landmark a line, for a person correcting a point in an editor
    rows = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in points.items())
    rest = "".join(f",\n {json.dumps(k)}: {json.dumps(v)}" for k, v in extra.items())
    text = f'{{\n "landmarks": {{\n{rows}\n }}{rest}\n}}\n'
    return atomic_write_bytes(Path(path), text.encode())


def shipped_landmarks(mesh_path: str | Path) -> Path | None:
    """The shipped landmarks file for a known head file name, else None."""
    name = SHIPPED.get(Path(mesh_path).name.lower())
    if name is None:
        return None
    return Path(str(resources.files("assets.heads").joinpath("landmarks", name)))


def credit_for(mesh_name: str) -> str:
    """The attribution line for a known head file (``""`` for others)."""
    return CREDITS.get(Path(mesh_name).name.lower(), "")
