"""Offline rendering: a moderngl head renderer (headless EGL) and video writing with ffmpeg.

renderer   HeadRenderer: textured/vertex-coloured, lit, MSAA, front or three-quarter view
video      the frame loop and ffmpeg muxing (write_video), captions, params_for_audio (speech ->
           the model's parameter track); parameter CSVs are read by assets.tracks
landmarks  automatic landmarks: render the head, MediaPipe face mesh, cast the points back onto it
"""
