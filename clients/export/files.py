"""Writing exports to disk: atomic files, the audio beside a .glb, the format chosen by suffix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from assets.audio import wav_bytes
from assets.files import atomic_write_bytes, check_writable
from assets.heads.mesh import HeadMesh
from assets.tracks import encode_csv, encode_json
from clients.export.errors import ExportError
from clients.export.gltf import arkit_glb, head_glb, morph_glb
from clients.export.rhubarb import tsv_bytes
from realtime_core.track import Track

FORMATS = (".glb", ".csv", ".json", ".tsv")
MORPHS = ("units", "arkit52")
AUDIO_BESIDE = (".glb", ".json")  # the formats that name a .wav written beside them


def audio_beside(path: str | Path) -> Path | None:
    """The ``.wav`` :func:`export_track` writes beside ``path`` when given audio (.glb, .json), else None."""
    p = Path(path)
    return p.with_suffix(".wav") if p.suffix.lower() in AUDIO_BESIDE else None


def check_outputs(paths: list[Path], *, source: str | Path | None = None) -> frozenset[Path]:
    """Refuse, before anything is written, exports of unknown format, a ``.wav`` beside a .glb/.json
    that would overwrite ``source`` (the speech the audio was read from: ``take.wav --glb take.glb``
    would replace the user's recording by its mono copy) or another of ``paths``, and paths that cannot be written
    (:func:`assets.files.check_writable`: a folder, a read-only place). Raises ExportError / CannotWriteError.
    Returns the paths checked (resolved), for :func:`export_track`'s ``checked``."""
    for p in paths:
        if p.suffix.lower() not in FORMATS:
            raise ExportError(f"{p}: unknown export format {p.suffix.lower()!r} (use {', '.join(FORMATS)})")
    taken = {Path(p).resolve(): "an output" for p in paths}
    if source is not None:
        taken[Path(source).resolve()] = "the input speech"
    for p in paths:
        wav = audio_beside(p)
        if wav is not None and wav.resolve() in taken:
            raise ExportError(
                f"{p}: the audio written beside it, {wav}, would overwrite {taken[wav.resolve()]}; "
                "give the export another name"
            )
    for p in paths:  # last: the probes make the outputs' folders
        check_writable(p)
        wav = audio_beside(p)
        if wav is not None and wav.is_dir():
            raise ExportError(f"{p}: the audio written beside it, {wav}, is a folder; give the export another name")
    return frozenset(Path(p).resolve() for p in paths)


def export_track(
    path: str | Path,
    track: Track,
    *,
    head: tuple | HeadMesh | None = None,
    audio: tuple[np.ndarray, int] | None = None,
    morphs: str = "units",
    arkit_targets: dict[str, np.ndarray] | None = None,
    arkit_track: Track | None = None,
    expression: np.ndarray | None = None,
    checked: frozenset[Path] = frozenset(),
    units: str = "IOD",
    cue_fps: float | None = None,
) -> list[Path]:
    """Write ``track`` to ``path`` in the format of its suffix (.glb, .csv, .json, .tsv); returns the
    files written. head: an :class:`assets.heads.head.Head` (or (rig, HeadMesh)), required for .glb; or a HeadMesh
    whose own morph targets the track's curves weight (``track.names``: a served head, :func:`morph_glb`);
    audio: (samples (n,) float or int16, rate_hz) starting at the track's first frame, written as
    ``<stem>.wav`` beside a .glb or .json
    (and named inside it). morphs (.glb): "units" = the rig's 4 mouth units (exact deformation) or
    "arkit52" = ARKit's 52 blendshapes from ``arkit_targets`` (name -> (n, 3)) with mapped weights;
    with ``expression`` ``(n, len(EXPRESSIONS))`` intensities, the ARKit weights are those of
    ``arkit_track`` (the speech parameters before the expression; default ``track``) plus the expressions'
    ARKit recipes, as a live session's ARKit output; a head driven by its own targets ("units") shows them on its own
    face shapes (:attr:`realtime_core.face.keyframes.MorphRig.face_recipe`) beside ``track``'s expressed mouth.
    ``path`` is checked (:func:`check_outputs`: a probe file made and removed) before anything is written unless it
    is in ``checked``, what a command's own check_outputs returned before its work. units: what the track's curves
    measure, recorded in a .json (the mouth parameters' IOD, or blendshape weights: ``animate --curves``).
    cue_fps (.tsv): the rate the cues are written at, ``track`` being the model's own frames (``animate --fps``: cues
    of curves interpolated onto 24 fps lost one-frame closures; :func:`clients.export.rhubarb.cues`)."""
    if morphs not in MORPHS:
        raise ExportError(f"morphs must be one of {MORPHS}, got {morphs!r}")
    p = Path(path)
    suffix = p.suffix.lower()
    # Everything that can be refused is refused before the first byte is written (no .wav left behind).
    if suffix == ".glb" and head is None:
        raise ExportError(f"{p}: a .glb export needs the head (its rig and mesh)")
    if suffix == ".glb" and isinstance(head, HeadMesh):
        if morphs != "units":
            raise ExportError(f"{p}: a head given by its own targets is exported with them (morphs 'units')")
        lacking = [n for n in track.names if n not in (head.targets or {})]
        if lacking:
            raise ExportError(f"{p}: {head.name} has no morph targets {lacking[:5]} for the track's curves")
    if suffix == ".glb" and morphs == "arkit52" and arkit_targets is None:
        raise ExportError(f"{p}: ARKit-52 morph targets need a head that has them (the built-in head)")
    if p.resolve() not in checked:
        check_outputs([p])
    written: list[Path] = []
    wav_name = None
    wav = audio_beside(p)
    if audio is not None and wav is not None:
        written.append(atomic_write_bytes(wav, wav_bytes(audio[0], audio[1])))
        wav_name = wav.name
    if suffix == ".glb":
        assert head is not None  # refused above otherwise
        if isinstance(head, HeadMesh):
            data = morph_glb(head, track, audio=wav_name)
        elif morphs == "units":
            rig, mesh = head
            data = head_glb(rig, mesh, track, audio=wav_name, expression=expression)
        else:
            assert arkit_targets is not None  # refused above otherwise
            data = arkit_glb(
                tuple(head)[1],
                arkit_targets,
                track if arkit_track is None else arkit_track,
                audio=wav_name,
                expression=expression,
            )
    elif suffix == ".csv":
        data = encode_csv(track)
    elif suffix == ".json":
        data = encode_json(track, audio=wav_name, units=units)
    else:
        data = tsv_bytes(track, fps=cue_fps)
    written.insert(0, atomic_write_bytes(p, data))
    return written
