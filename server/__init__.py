"""server: the asyncio streaming service of facecast.

Layers, inner to outer (the inner ones do no I/O, like python-websockets' protocol core):

    controls   the control registry (gain, smoothing_ms, ...) and the per-frame state they set
    session    sans-I/O session core: audio bytes in, frames (params, deltas, blendshapes) out, around
               realtime_core.pipeline.SpeechToParams
    protocol   sans-I/O service protocol: the ingest state machine (events in; replies, work and close
               codes out), session kinds, view-query parsing, bounded JSON
    describe   JSON descriptions of sessions (started reply, viewer description, list rows)
    http       the plain-HTTP router (health, metrics, sessions, head downloads, static files)
    guard      hardening decisions without I/O: ingest pacing, Origin/Host checks, per-client limits,
               incidents logged once with a count
    config     ServerConfig (frozen, validated once; from TOML)
    live       live sessions (local or worker, one async interface) and viewer fan-out
    workers    compute processes running sessions off the event loop
    cluster    scale-out over Redis: registry with heartbeats, per-session pub/sub frame channels
    sources    audio sources as async iterators: microphone, file (paced or fast)
    app        the asyncio shell: WebSocket connections, lifecycle, admission, metrics
    text_session  text sessions for chatbots: text in, espeak-ng speech and unit-selection motion out
    timing     per-stage timing rings
    errors     ServerError and its family
"""
