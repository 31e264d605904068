"""Watching and recording a live session from Python (``facecast view`` and ``facecast record``).

stream   ViewerStreamConfig; connect as a viewer (waiting for the session to exist), collect frames
         and audio, download the served head, lay audio and frames on one media timeline
live     the live window (GLFW) with audio playout synchronised to the frames
video    render a recorded deltas stream offscreen (EGL) into an MP4 with the audio muxed in
"""
