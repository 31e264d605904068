"""clients: the I/O edge of facecast (files, caches, downloads, rendering).

    heads    mesh loading, the built-in head, landmarks, rig files and the rigging pipeline
    render   offline moderngl rendering and video muxing
    export   glTF (.glb) morph-target animation, CSV/JSON curves, Rhubarb-style TSV cues
    viewer   the Python viewer window and recorder (`facecast view`, `facecast record`)
    web      the browser viewer served by `facecast serve` at /
    client   the asyncio client library (ingest, view) over the wire protocol
"""
