"""Offline rendering: a moderngl head renderer (headless EGL) and video writing with ffmpeg.

    renderer   HeadRenderer: textured/vertex-coloured, lit, MSAA, front or three-quarter view
    video      params CSV reading, frame loop, ffmpeg muxing, the speech->params hook
"""
