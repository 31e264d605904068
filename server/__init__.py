"""server: the asyncio streaming service of facecast.

Layers, inner to outer (the inner ones do no I/O, like python-websockets' protocol core):

    resample   streaming polyphase resampler (same output for any chunking)
    protocol   the wire format: frame headers, payload encodings, close codes (shared with clients)
    session    sans-I/O session core: audio bytes in, frames (params, deltas, blendshapes) out
    config     ServerConfig (frozen, validated once; from TOML)
    sources    audio sources as async iterators: microphone, file (paced or fast)
    app        the asyncio server: ingest and viewer WebSockets, HTTP health/metrics/head
    glb        the head mesh as a binary glTF for viewers
    demo       the `facecast demo` runner: espeak-ng speech through a live session, MP4 out
"""
