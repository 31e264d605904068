"""Speech with phoneme timings from espeak-ng's C library (``libespeak-ng.so.1``) via ctypes.

How it works: the library is initialised once per process in ``AUDIO_OUTPUT_SYNCHRONOUS`` mode
with ``espeakINITIALIZE_PHONEME_EVENTS``. ``espeak_Synth`` then returns only when the whole text
has been synthesised; meanwhile espeak calls our synth callback with blocks of 16-bit samples
and a list of events terminated by ``espeakEVENT_LIST_TERMINATED``. Every
``espeakEVENT_PHONEME`` carries the phoneme's mnemonic (espeak's ASCII phoneme names, e.g.
``p``, ``aI``, ``@U``; ``id.string``, up to 8 bytes) and ``sample``, the absolute index of the
output sample where the phoneme starts (``audio_position`` is the same instant in ms). A
phoneme ends where the next one (or a word/sentence end) starts.

The ``espeak_EVENT`` layout (speak_lib.h, API revision 12) on LP64 Linux, verified by
:func:`_check_event_layout` and by the tests (events at increasing sample positions inside
the audio, bilabial closures at low energy)::

    offset  0  int   type
            4  uint  unique_identifier
            8  int   text_position
           12  int   length
           16  int   audio_position   (ms)
           20  int   sample           (sample index)
           24  void* user_data
           32  union {int number; const char* name; char string[8];} id
    size   40

espeak-ng keeps global state (one voice, one callback), so all calls go through one
process-wide lock; it is not re-entrant. The library is loaded lazily on first use.

Each synthesis runs in a child forked from this process, whose espeak-ng is only ever initialised;
the child also loads the voice (~4 ms: with voices loaded here instead, what a child said changed
after tests/assets/test_espeak.py had loaded its voices, and three alignment tests failed).
espeak-ng 1.51 carries state from one ``espeak_Synth`` to the next: it reads its phoneme list past
the current clause's end (``next2``/``next3`` in ``CalcLengths``), where the previous text's last
clause still lies. In one process "Sure!" gave 8900 samples, 10843 after "Dr." or "doctor hello
hello." (vowel 0.331 s, not 0.292 s), 9102 after "Hello there, how are you?", and kept that until
a text with another last clause; its wave generator also keeps its phase (8900, 8897, 8898
samples for "Sure!" thrice). ``espeak_Cancel``, a voice change or a primer text reset neither,
and ``espeak_Terminate`` deadlocks (``pthread_cond_wait``). A fork has the state of a freshly
loaded library, so the same text and voice give the same samples whatever was said before, as
``facecast say`` in a new process does.
"""

from __future__ import annotations

import ctypes
import os
import struct
import threading
from dataclasses import dataclass

import numpy as np

from assets.errors import SynthesisError
from realtime_core.errors import ConfigError
from realtime_core.phones import PhonemeSegment

LIBRARY = "libespeak-ng.so.1"

# speak_lib.h constants
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_PHONEME_EVENTS = 0x0001
_INITIALIZE_DONT_EXIT = 0x8000
_POS_CHARACTER = 1
_CHARS_UTF8 = 1
_EVENT_LIST_TERMINATED = 0
_EVENT_WORD = 1
_EVENT_SENTENCE = 2
_EVENT_END = 5
_EVENT_MSG_TERMINATED = 6
_EVENT_PHONEME = 7
_PARAM_RATE = 1
_PARAM_VOLUME = 2
_PARAM_PITCH = 3
_PARAM_RANGE = 4
_PARAM_WORDGAP = 7

RATE_RANGE_WPM = (80, 450)
"""espeak's accepted speaking rates, words per minute (espeakRATE_MINIMUM/MAXIMUM)."""


class _EventId(ctypes.Union):
    _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]


class _Event(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(_Event))


def _check_event_layout() -> None:
    """Fail loudly if ctypes lays out the struct differently from the header (see module doc)."""
    want = {"type": 0, "audio_position": 16, "sample": 20, "user_data": 24, "id": 32}
    got = {name: getattr(_Event, name).offset for name in want}
    if got != want or ctypes.sizeof(_Event) != 40:
        raise SynthesisError(f"espeak_EVENT layout mismatch: offsets {got}, size {ctypes.sizeof(_Event)}")


LANGUAGES: dict[str, tuple[str, ...]] = {
    # espeak voice (language) names per corpus language; accents vary the phone set slightly.
    "en": ("en-us", "en", "en-gb-scotland", "en-gb-x-rp", "en-029", "en-us-nyc"),
    "es": ("es", "es-419"),
}
"""Base espeak voices per language code used in the corpus."""

VARIANTS: tuple[str, ...] = (
    "m1",
    "m2",
    "m3",
    "m4",
    "m5",
    "m6",
    "m7",
    "f1",
    "f2",
    "f3",
    "f4",
    "f5",
)
"""espeak voice variants (``voices/!v``): male ``m1..m7`` and female ``f1..f5`` formant sets."""


@dataclass(frozen=True)
class Voice:
    """One espeak-ng speaking voice.

    language:     corpus language code, "en" or "es".
    base:         espeak language voice, one of ``LANGUAGES[language]`` (e.g. "en-us").
    variant:      a ``VARIANTS`` entry (e.g. "f3") or None for the base voice.
    rate_wpm:     speaking rate, words per minute (80..450; espeak's default is 175).
    pitch:        base pitch 0..100 (50 = the voice's normal).
    pitch_range:  intonation range 0..100 (0 = monotone, 50 = normal).
    """

    language: str
    base: str
    variant: str | None = None
    rate_wpm: int = 175
    pitch: int = 50
    pitch_range: int = 50

    def __post_init__(self) -> None:
        if self.language not in LANGUAGES:
            raise ConfigError(f"unknown language {self.language!r}; known: {', '.join(sorted(LANGUAGES))}")
        if self.base not in LANGUAGES[self.language]:
            raise ConfigError(
                f"voice {self.base!r} is not one of {', '.join(LANGUAGES[self.language])} for {self.language!r}"
            )
        if self.variant is not None and self.variant not in VARIANTS:
            raise ConfigError(f"unknown variant {self.variant!r}; known: {', '.join(VARIANTS)}")
        if not RATE_RANGE_WPM[0] <= self.rate_wpm <= RATE_RANGE_WPM[1]:
            raise ConfigError(f"rate_wpm must be in {RATE_RANGE_WPM}, got {self.rate_wpm}")
        for name in ("pitch", "pitch_range"):
            if not 0 <= getattr(self, name) <= 100:
                raise ConfigError(f"{name} must be in 0..100, got {getattr(self, name)}")

    @property
    def espeak_name(self) -> str:
        """The name given to ``espeak_SetVoiceByName``, e.g. "en-us+f3"."""
        return self.base if self.variant is None else f"{self.base}+{self.variant}"

    @property
    def label(self) -> str:
        """A stable human-readable id, e.g. "en-us+f3@r160p55" (used in manifests)."""
        return f"{self.espeak_name}@r{self.rate_wpm}p{self.pitch}"


@dataclass(frozen=True)
class Synthesis:
    """What :meth:`EspeakSynthesizer.synthesize` returns.

    samples:         (n,) int16 mono PCM as espeak produced it.
    sample_rate_hz:  espeak's output rate (22050 Hz for its built-in voices).
    phonemes:        the phoneme timeline in seconds from the first sample, sorted, gapless
                     between consecutive events; pauses appear as espeak's "_" phonemes.
    """

    samples: np.ndarray
    sample_rate_hz: int
    phonemes: tuple[PhonemeSegment, ...]

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz


class EspeakSynthesizer:
    """A handle on the process-wide espeak-ng library (created lazily, shared, thread-safe).

    Use :func:`synthesizer` to get the shared instance; constructing it loads the library.
    """

    _lock = threading.Lock()

    def __init__(self) -> None:
        _check_event_layout()
        try:
            lib = ctypes.CDLL(LIBRARY)
        except OSError as exc:
            raise SynthesisError(f"cannot load {LIBRARY} ({exc}); install the Debian package libespeak-ng1") from exc
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_SetSynthCallback.argtypes = [_CALLBACK]
        lib.espeak_SetSynthCallback.restype = None
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetVoiceByName.restype = ctypes.c_int
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_SetParameter.restype = ctypes.c_int
        lib.espeak_Synth.argtypes = [
            ctypes.c_void_p,
            ctypes.c_size_t,
            ctypes.c_uint,
            ctypes.c_int,
            ctypes.c_uint,
            ctypes.c_uint,
            ctypes.POINTER(ctypes.c_uint),
            ctypes.c_void_p,
        ]
        lib.espeak_Synth.restype = ctypes.c_int
        lib.espeak_Synchronize.argtypes = []
        lib.espeak_Synchronize.restype = ctypes.c_int
        rate = lib.espeak_Initialize(
            _AUDIO_OUTPUT_SYNCHRONOUS, 0, None, _INITIALIZE_PHONEME_EVENTS | _INITIALIZE_DONT_EXIT
        )
        if rate <= 0:
            raise SynthesisError(f"espeak_Initialize failed (returned {rate}); is espeak-ng-data installed?")
        self._lib = lib
        self._libc = ctypes.CDLL(None)  # the process's C library: srand() for espeak's noise
        self._libc.srand.argtypes = [ctypes.c_uint]
        self.sample_rate_hz = int(rate)
        self._chunks: list[bytes] = []  # int16 samples as espeak wrote them (native byte order)
        self._events: list[tuple[int, str]] = []  # (sample index, phoneme or "" for a boundary)
        # Keep a reference: ctypes frees the trampoline if the Python object dies.
        self._callback = _CALLBACK(self._on_synth)
        lib.espeak_SetSynthCallback(self._callback)

    def _on_synth(self, wav, n_samples, events) -> int:
        if n_samples > 0 and wav:
            # plain bytes, no numpy: this runs in the forked child, which should import nothing (another thread of
            # the parent may have held the import lock when it forked)
            self._chunks.append(ctypes.string_at(wav, 2 * n_samples))
        i = 0
        while events[i].type != _EVENT_LIST_TERMINATED:
            ev = events[i]
            if ev.type == _EVENT_PHONEME:
                raw = bytes(ev.id.string).split(b"\0", 1)[0]
                self._events.append((int(ev.sample), raw.decode("utf-8", "replace")))
            elif ev.type in (_EVENT_END, _EVENT_MSG_TERMINATED):
                self._events.append((int(ev.sample), ""))
            i += 1
        return 0

    def synthesize(self, text: str, voice: Voice, *, noise_seed: int | None = None) -> Synthesis:
        """Speak ``text`` with ``voice``; returns int16 samples and the phoneme timeline.

        The same text, voice and ``noise_seed`` give the same samples whatever this process said
        before (the synthesis runs in a forked child: see the module doc).

        noise_seed: if given, seeds the C library's ``rand()``, which espeak's wave generator
            uses for frication/aspiration noise (unseeded, the noise is the same too: the child
            starts from this process's ``rand()`` state, which espeak never draws from here).
        Raises SynthesisError if espeak rejects the voice or produces no audio.
        """
        if not text.strip():
            raise ConfigError("cannot synthesise empty text")
        with self._lock:
            read_fd, write_fd = os.pipe()
            pid = os.fork()
            if pid == 0:  # the child: synthesise, write the result, and leave without Python's exit handlers
                status = 1
                try:
                    os.close(read_fd)
                    self._synthesize_into(write_fd, text, voice, noise_seed)
                    status = 0
                finally:
                    os._exit(status)
            os.close(write_fd)
            with os.fdopen(read_fd, "rb") as pipe:
                reply = pipe.read()
            _, wait_status = os.waitpid(pid, 0)
        if os.waitstatus_to_exitcode(wait_status) != 0 or len(reply) < _HEADER.size:
            raise SynthesisError(f"espeak-ng's synthesis process failed for {text[:40]!r} (status {wait_status})")
        error, n_samples, n_events = _HEADER.unpack_from(reply)
        if error == _NO_VOICE:
            raise SynthesisError(f"espeak-ng has no voice {voice.espeak_name!r}")
        if error != 0:
            raise SynthesisError(f"espeak_Synth failed with code {error} for {text[:40]!r}")
        if n_samples == 0:
            raise SynthesisError(f"espeak produced no audio for {text[:40]!r} with {voice.espeak_name}")
        offset = _HEADER.size + 2 * n_samples
        samples = np.frombuffer(reply, dtype=np.int16, count=n_samples, offset=_HEADER.size).copy()
        events = [
            (sample, raw.split(b"\0", 1)[0].decode("utf-8", "replace"))
            for sample, raw in _EVENT_RECORD.iter_unpack(reply[offset : offset + _EVENT_RECORD.size * n_events])
        ]
        return Synthesis(samples, self.sample_rate_hz, _timeline(events, n_samples, self.sample_rate_hz))

    def _synthesize_into(self, fd: int, text: str, voice: Voice, noise_seed: int | None) -> None:
        """In the forked child: synthesise and write header, int16 samples and event records to ``fd``."""
        lib = self._lib
        if noise_seed is not None:
            self._libc.srand(ctypes.c_uint(noise_seed & 0xFFFFFFFF))
        error = 0
        if lib.espeak_SetVoiceByName(voice.espeak_name.encode()) != 0:
            error = _NO_VOICE
        else:
            # SetVoiceByName resets rate/pitch to the voice's defaults, so set them after it.
            lib.espeak_SetParameter(_PARAM_RATE, voice.rate_wpm, 0)
            lib.espeak_SetParameter(_PARAM_PITCH, voice.pitch, 0)
            lib.espeak_SetParameter(_PARAM_RANGE, voice.pitch_range, 0)
            lib.espeak_SetParameter(_PARAM_VOLUME, 100, 0)
            data = text.encode("utf-8") + b"\0"
            error = lib.espeak_Synth(data, len(data), 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None)
            if error == 0:
                lib.espeak_Synchronize()
        samples = b"".join(self._chunks) if error == 0 else b""
        events = self._events if error == 0 else []
        reply = (
            _HEADER.pack(error, len(samples) // 2, len(events))
            + samples
            + b"".join(_EVENT_RECORD.pack(sample, name.encode("utf-8")[:8]) for sample, name in events)
        )
        view = memoryview(reply)
        while view:  # os.write may take part of it (a pipe holds 64 KiB)
            view = view[os.write(fd, view) :]


_HEADER = struct.Struct("=iii")
"""The child's reply header: error (0, ``_NO_VOICE`` or espeak_Synth's code), samples, events."""

_EVENT_RECORD = struct.Struct("=i8s")
"""One event in the child's reply: start sample and phoneme name (espeak's up to 8 bytes; empty = a boundary)."""

_NO_VOICE = -1


def _timeline(events: list[tuple[int, str]], n_samples: int, rate: int) -> tuple[PhonemeSegment, ...]:
    """Turn (start sample, phoneme) events into segments; "" events only close the previous one.

    Zero-length phonemes (espeak emits some markers at the same sample) are dropped: a phoneme followed
    at its own sample by another phoneme (boundary events between them aside) has no length.
    espeak-ng starts a sentence-initial /m/ with a pause marker at the same sample ("Hello there. My":
    ``_``, a clause end, ``m``); both were given the /m/'s span, and the unit selection, reading the
    pause first, dropped the /m/: the lips stayed open through it.
    """
    events = sorted(events, key=lambda e: e[0])  # stable: keeps espeak's order at equal samples
    segs: list[PhonemeSegment] = []
    for k, (start, name) in enumerate(events):
        if not name:
            continue
        end = n_samples
        for later, other in events[k + 1 :]:
            if later > start:
                end = later
                break
            if other:  # another phoneme at this very sample: this one has no length
                end = start
                break
        end = min(end, n_samples)
        if end > start:
            segs.append(PhonemeSegment(name, start / rate, end / rate))
    return tuple(segs)


_shared: EspeakSynthesizer | None = None
_shared_lock = threading.Lock()


def synthesizer() -> EspeakSynthesizer:
    """The process-wide synthesizer (espeak-ng has one global state); loads it on first call."""
    global _shared
    with _shared_lock:
        if _shared is None:
            _shared = EspeakSynthesizer()
        return _shared
