"""clients: the I/O edge of facecast (files, caches, downloads, rendering).

    heads    mesh loading, the built-in head, landmarks, rig files and the rigging pipeline
    render   offline moderngl rendering and video muxing
"""
