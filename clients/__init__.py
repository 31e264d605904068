"""clients: everything that consumes a live session or a parameter track (layer 3, beside
``server`` and ``training``; imports ``assets``, ``wire`` and ``realtime_core`` only).

    client   the asyncio client library over the wire protocol: IngestClient, ViewerClient, stream_samples
    errors   ClientError (root of this package) and RenderError
    export   glTF (.glb) morph-target animation, Rhubarb-style TSV cues, export_track by suffix
             (CSV/JSON curves through assets.tracks)
    render   offline moderngl rendering (headless EGL) and video muxing with ffmpeg
    viewer   the Python viewer window and recorder (``facecast view``, ``facecast record``)
    web      the browser viewer's static files, served by ``facecast serve`` at /
"""
