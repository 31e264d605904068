"""server: the asyncio streaming service of facecast (layer 3; imports ``assets``, ``wire``, ``realtime_core``).

Layers, inner to outer (the inner ones do no I/O, like python-websockets' protocol core):

    session    sans-I/O session core: audio bytes in, frames (params, deltas, blendshapes) out
               (resampling by realtime_core.features.resample; the wire format is the ``wire`` package)
    timing     per-stage timing rings and summaries
    config     ServerConfig (frozen, validated once; from TOML)
    errors     ServerError (root of this package) and its families
    sources    audio sources as async iterators: microphone, file (paced by assets.pacing, or fast)
    workers    optional compute worker processes for sessions' per-frame work
    app        the asyncio server: ingest and viewer WebSockets, HTTP health/metrics/head/viewer
    glb        the head mesh as a binary glTF for viewers
"""
