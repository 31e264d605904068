"""Session descriptions: what a peer is told about a session, as JSON-ready dicts (no I/O).

``started`` answers an ingest's start message, ``view_description`` is a viewer's first message
(docs/protocol.md lists every field), ``summary`` is one row of ``/sessions`` and ``/metrics``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.blendshapes import blendshape_names, blendshape_weights
from realtime_core.expressions import EXPRESSIONS, NEUTRAL
from realtime_core.face.keyframes import MorphRig
from wire import protocol as P

if TYPE_CHECKING:
    from assets.heads.head import Head
    from server.cluster import RemoteFeed
    from server.live import LiveSession
    from server.protocol import ViewRequest


def started(live: LiveSession) -> dict:
    """The ``started`` reply's fields (the protocol adds ``type``)."""
    s = live.session
    out = {
        "session": live.name,
        "model_rate_hz": s.rate_hz,
        "fps": s.fps,
        "algorithmic_delay_s": s.algorithmic_delay_s,
        "view_path": f"/view?session={live.name}",
    }
    cfg = getattr(s, "config", None)
    if cfg is not None and getattr(cfg, "enrol", None) is not None:
        out["enrolled_s"] = round(cfg.enrol_seconds(), 2)  # the session's model copy is adapted to this voice
    if cfg is not None and getattr(cfg, "auto_gain", None):
        out["auto_gain"] = True  # its input is brought to the model's speech level
    return out


def view_description(live: LiveSession | RemoteFeed, req: ViewRequest, head: Head | None) -> dict:
    """A viewer's first message: the session, the subscription, the value layout and the head."""
    s = live.session
    d: dict = {
        "type": "description",
        "protocol": P.PROTOCOL_VERSION,
        "session": live.name,
        "fps": s.fps,
        "kind": req.kind,
        "encoding": req.encoding,
        "header_kind": req.header_kind,
        "header_encoding": req.header_encoding,
        "header_bytes": P.HEADER_BYTES,
        "params": {"names": list(VISUAL_PARAMS), "units": "inter-ocular distances (IOD)"},
        # What a viewer's expression control may name: every session takes them (a text session applies them as its
        # frames are released); none for a viewer of another node's session, whose node takes no viewer messages.
        "expressions": [NEUTRAL, *EXPRESSIONS] if live.takes_viewer_controls else [],
        "algorithmic_delay_s": s.algorithmic_delay_s,
        "audio": {"rate_hz": s.rate_hz, "channels": 1, "encoding": "int16", "scale": 1 / 32768} if req.audio else None,
        "values_per_frame": len(VISUAL_PARAMS),
        "head": None,
    }
    if head is not None:
        d["head"] = head_description(head)
    if req.kind == "deltas" and head is not None:
        d["values_per_frame"] = 3 * int(len(head.rig.moving))
        d["layout"] = "x, y, z of each moving vertex in moving_vertices order, added to the neutral mesh"
    elif req.kind == "morph" and head is not None and isinstance(head.rig, MorphRig):
        d["names"] = list(head.rig.names)
        d["values_per_frame"] = len(d["names"])
        d["layout"] = "one weight per morph target in names order (three.js morphTargetInfluences)"
    elif req.kind == "blendshapes":
        d["names"] = list(blendshape_names(req.encoding))
        d["values_per_frame"] = len(d["names"])
    d["rest_values"] = rest_values(req, head)
    return d


def head_description(head: Head) -> dict:
    """The served head as a viewer's description names it: where to download it and which vertices move."""
    rig, mesh = head.rig, head.mesh
    return {
        "mesh_url": "/head/mesh",
        "mesh_json_url": "/head/mesh.json",
        "texture_url": "/head/texture" if mesh.texture is not None else None,
        "vertex_count": int(len(mesh.vertices)),
        "moving_vertices": rig.moving.astype(int).tolist(),
        "units": "mesh units",
        # A head driven by its own targets: their names in the order of the morph kind's weights
        # (mesh.json carries the targets themselves); null for a retargeted head.
        "morph": {"names": list(rig.names)} if isinstance(rig, MorphRig) else None,
    }


def head_at_rest(head: Head) -> dict:
    """``/head/description.json``: the head's description and its rest values for each frame kind it serves
    (``{"morph": [...] or null, "deltas": [...] or null}``; null: all 0). A page waiting for a session (an
    embedded chatbot avatar before its first answer) shows the head at rest instead of an empty canvas."""
    kinds = ("morph", "deltas") if isinstance(head.rig, MorphRig) else ("deltas",)
    return {
        "head": head_description(head),
        "rest_values": {kind: rest_values_of(kind, "float32", head) for kind in kinds},
    }


def rest_values(req: ViewRequest, head: Head | None) -> list[float] | None:
    """:func:`rest_values_of` for a viewer's subscription."""
    return rest_values_of(req.kind, req.encoding, head)


def rest_values_of(kind: str, encoding: str, head: Head | None) -> list[float] | None:
    """The values (``values_per_frame``, the kind's layout) of a frame at the rest pose (mouth parameters 0:
    lips touching, neutral expression), or None when they are all 0 (every head but one resting through its own
    targets). A viewer shows them before a session's first frame and eases to them after its last.

    Why: a head modelled with its lips apart rests through its targets (:attr:`MorphRig.rest`, its jaw below 0), so
    zero weights or zero deltas are the head as modelled, lips apart: easing to zero at a session's end opened the
    mouth the session's silences had shown closed."""
    rig = head.rig if head is not None else None
    zero = np.zeros(len(VISUAL_PARAMS))
    if kind == "deltas" and rig is not None:
        values = np.asarray(rig.displacements(zero), dtype=np.float32).reshape(-1)
    elif kind == "morph" and isinstance(rig, MorphRig):
        values = np.asarray(rig.weights(zero), dtype=np.float32)
    elif kind == "blendshapes":
        values = np.asarray(blendshape_weights(zero, encoding), dtype=np.float32)
    else:  # params: the rest is 0 by definition
        return None
    return [float(v) for v in values] if np.any(values) else None


def view_description_text(live: LiveSession | RemoteFeed, req: ViewRequest, head: Head | None) -> str:
    """:func:`view_description` as JSON text, made once per session and subscription (``req``) and
    kept in ``live.descriptions``: its facts never change while the session lives, and the head's
    vertex list makes it ~15 KB of JSON (~0.2 ms to encode) for every viewer that connects."""
    text = live.descriptions.get(req)
    if text is None:
        text = live.descriptions[req] = P.dumps(view_description(live, req, head))
    return text


def summary(live: LiveSession) -> dict:
    """One session's row. ``source`` is the source's kind only (ingest, file, microphone): a file
    session's path stays in the server's log, never in a reply."""
    s = live.session
    row = {
        "name": live.name,
        "source": live.source.split(" ", 1)[0],
        "viewers": len(live.viewers),
        "frames": s.frames_out,
        "audio_s": round(s.samples_out / s.rate_hz, 3),
        "dropped": live.dropped,
        "input_rate_hz": s.config.sample_rate_hz,
        "channels": s.config.channels,
        "controls": s.control_state(),
    }
    return row
