"""Exports of an animation: pure writers from a parameter track (:class:`realtime_core.track.Track`,
and a head) to bytes. CSV and JSON curves are the one track codec of :mod:`assets.tracks`.

    errors    ExportError (under clients.errors.ClientError)
    rhubarb   Rhubarb Lip Sync style mouth-shape cues (A-H, X) as TSV, for 2D tools
    gltf      a binary glTF (.glb) of the head with the animation as morph-target weights
    files     atomic file writing, WAV bytes, and ``export_track`` choosing the format by suffix

Every writer returns bytes (or writes to a binary stream); only :mod:`clients.export.files` touches
the file system. ``facecast animate`` and ``facecast record`` both end in :func:`files.export_track`.
"""
