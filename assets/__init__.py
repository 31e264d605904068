"""assets: the file and asset edge of facecast (layer 2, beside ``wire``; imports only ``realtime_core``).

Every reader and writer of a file format lives here, one per format, and every error names the file.

    errors     AssetsError and its families (FileProblem: NotAudio, SilentAudio, WrongSampleRate,
               TruncatedFile, CorpusFormat; MeshError, LandmarkError, RigFileError, AssetError)
    files      atomic writes (temporary file + os.replace)
    audio      audio reading (any format ffmpeg reads, WAV natively), the one WAV writer (int16 x 32768)
    modelfile  model .npz load/save and the shipped default model (data/)
    tracks     the one codec of parameter tracks: CSV (strict corpus mode, resampling render reader) and JSON
    pacing     paced_blocks: the one real-time pacing loop for recorded audio (absolute loop-clock schedule)
    heads      meshes, the built-in head, landmark files, rig files and the rigging pipeline (its own map)
"""
