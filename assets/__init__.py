"""assets: the file and asset edge of facecast (layer 2, beside ``wire``; imports only ``realtime_core``).

Every reader and writer of a file format lives here, one per format, and every error names the file.

    errors     AssetsError and its families (FileProblem: NotAudio, SilentAudio, WrongSampleRate,
               TruncatedFile, CorpusFormat; MeshError, LandmarkError, RigFileError, AssetError)
    files      atomic writes (temporary file + os.replace)
    audio      audio reading (any format ffmpeg reads, WAV natively), the one WAV writer (int16 x 32768)
    modelfile  model .npz load/save and the shipped default model (data/)
    tracks     the one codec of parameter tracks: CSV (strict corpus mode, resampling render reader) and JSON
    pacing     paced_blocks: the one real-time pacing loop for recorded audio (absolute loop-clock schedule)
    espeak     espeak-ng speech with phoneme timings (its C library via ctypes)
    tts        text -> speech with phone timings for unit selection (espeak-ng)
    grid       the GRID s1 corpus: ids, the one train/val/test split, word alignments, sentence text
    unitcorpus unit-selection corpus files: atomic save, load naming the file
    heads      meshes, the built-in head, landmark files, rig files and the rigging pipeline (its own map)
"""
