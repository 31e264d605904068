"""Text-driven visible speech by unit selection over recorded motion (seed 001, Ma et al. 2006).

Modules (sans-I/O, numpy in, numpy out):
    empca        EM-PCA of motion frames (Sec. 3.6), components chosen by explained variance
    visemes      the viseme category table (ARPAbet, espeak-ng English and Spanish phones)
    corpus       the phone-labelled motion corpus as flat arrays (Sec. 3.2-3.3)
    search       the phonetic transition graph and the Viterbi unit search (Sec. 3.7)
    concat       time warping of units to target durations and junction smoothing (Sec. 3.8)
    synthesizer  phones with timings -> 30 fps motion, the three above in one call
    recording    text + recording: the audio-driven model's motion mixed in (pauses most)
    text         text cleaning, checks and sentence chunks
"""
