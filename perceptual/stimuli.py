"""``facecast perceptual build``: every stimulus of a test, rendered once, cached, listed in a manifest.

Sources. Sentences are GRID s1 *test-split* sentences (``assets.grid``; never tuned on): the
real talker's audio and video. Syllables are the 27 CV syllables of seed 000 synthesised by espeak-ng
in English and Spanish (spelled so that espeak says exactly consonant + vowel; the phonemes it
reports are checked). Clips for opinion scores may also be any MP4 the experimenter names.

Audio. White Gaussian noise at each SNR, ``SNR = 10 log10(P_speech / P_noise)`` with the speech
power measured over the speech itself (GRID: first to last word of the alignment; syllables: the
non-pause phonemes), seeded by (item, SNR, seed) so A, N and S of one cell carry the *same* noisy
signal. Every stimulus is then scaled so its RMS over the speech region is ``level_dbfs`` (constant
presentation level; peaks kept below full scale). All audio is AAC in MP4, so conditions differ only
in what is seen.

Video, 640x480 by default. ``N``: the GRID mp4 scaled into the frame (aspect kept, padded; its own
25 fps). ``S``/``Sn``: the shipped model drives the built-in head through the offline renderer
(``clients.render``), from the clean or the noisy speech, rendered silent once and muxed with each
SNR's audio. ``A``: audio only (the page shows an empty frame). Emotion clips add the built-in head's
ARKit targets (smile: mouthSmile + cheek/eye squint; sad: mouthFrown + browInnerUp) to the speech
animation.

Cache and manifest. Each output is named by the SHA-256 of everything that makes it (kit version,
source content, SNR, seed, render settings, model file, expression), so a rebuild with other
settings reuses what it can; ``cache/index.json`` records each cached file's content hash, and a
cached file whose content changed is made again. ``manifest.json`` lists blocks and stimuli with
their files' SHA-256; :func:`load_manifest` refuses a manifest of another kit version, a stimulus
whose file is missing or changed, a manifest edited by hand (its test id is a hash of its content)
and one whose GRID source files changed since the build.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from perceptual.design import (
    CONSONANTS,
    EXPRESSIONS,
    SYLLABLES,
    Block,
    truth_of,
)
from perceptual.errors import BuildError, ManifestError
from realtime_core.expressions import EXPRESSION_RECIPES
from realtime_core.expressions import EXPRESSIONS as CORE_EXPRESSIONS
from realtime_core.fitted_maps import EXPRESSION_PARAMS
from realtime_core.mapping.expression import express

FORMAT = "facecast-perceptual-stimuli"
KIT_VERSION = 2
"""Bump when the way stimuli are made changes: manifests and cache entries of other versions are stale. (2: the
smiling and sad faces are the product's expressions on the head `facecast render` draws; 1 had a stand-in recipe
of the kit's own on the retargeted head.)"""

GRID_CREDIT = "GRID audio-visual corpus: M. Cooke, J. Barker, S. Cunningham, X. Shao (2006), CC BY 4.0"

# espeak spellings that make it say exactly consonant + vowel (checked against its phoneme events).
_EN_SPELLING = {
    "a": {"p": "pah", "b": "bah", "m": "mah", "f": "fah", "t": "tah", "d": "dah", "s": "sah", "sh": "shah", "k": "kah"},
    "i": {"p": "pee", "b": "bee", "m": "mee", "f": "fee", "t": "tee", "d": "dee", "s": "see", "sh": "she", "k": "key"},
    "u": {"p": "poo", "b": "boo", "m": "moo", "f": "foo", "t": "too", "d": "doo", "s": "sue", "sh": "shoe", "k": "coo"},
}
_ESPEAK_CONSONANT = {"p": "p", "b": "b", "m": "m", "f": "f", "t": "t", "d": "d", "s": "s", "sh": "S", "k": "k"}
_ESPEAK_VOWEL = {"en": {"a": "A:", "i": "i:", "u": "u:"}, "es": {"a": "a", "i": "i", "u": "u"}}
_VOICES = {"en": "en-us", "es": "es"}
CV_PAD_S = 0.35
"""Silence before and after a synthesised syllable (the face is visible before the sound starts)."""


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _key(spec: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps({"kit": KIT_VERSION, **spec}, sort_keys=True).encode()).hexdigest()


# --------------------------------------------------------------------------- audio


def add_white_noise(clean: np.ndarray, active: np.ndarray, snr_db: float, seed: int) -> np.ndarray:
    """clean (n,) float + seeded white Gaussian noise so that P_speech / P_noise = snr_db, with
    P_speech the mean square over ``active`` (n,) bool samples. Returns (n,) float64."""
    x = np.asarray(clean, dtype=np.float64)
    p_speech = float(np.mean(x[active] ** 2)) if active.any() else 0.0
    if p_speech <= 0:
        raise BuildError("cannot add noise at an SNR to silent speech")
    noise = np.random.default_rng(seed).standard_normal(len(x)) * np.sqrt(p_speech / 10 ** (snr_db / 10))
    return x + noise


def set_level(x: np.ndarray, active: np.ndarray, rms_dbfs: float) -> np.ndarray:
    """x (n,) scaled so its RMS over ``active`` is ``rms_dbfs`` (peaks kept <= 0.99 full scale)."""
    rms = float(np.sqrt(np.mean(np.asarray(x, dtype=np.float64)[active] ** 2)))
    g = 10 ** (rms_dbfs / 20) / max(rms, 1e-12)
    peak = float(np.max(np.abs(x))) * g
    if peak > 0.99:
        g *= 0.99 / peak
    return np.asarray(x, dtype=np.float64) * g


def _noise_seed(seed: int, item: str, snr_db: float) -> int:
    return int.from_bytes(hashlib.sha256(f"{seed}|{item}|{snr_db:g}".encode()).digest()[:8], "little")


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True, kw_only=True)
class BuildConfig:
    """What ``facecast perceptual build`` makes.

    out_dir: stimulus folder (manifest.json, media/, cache/); grid_root: GRID s1 folder (None: beside
    the checkout); snrs_db / cv_snrs_db: noise levels (dB) of the sentence / syllable blocks;
    synthetic_audio: which speech drives the head, ``clean`` (condition S), ``noisy`` (Sn) or both;
    sentences_per_cell: sentences per condition x SNR cell per participant; practice: a short block
    first; cv_languages: espeak languages of the syllable block (``()`` for none); cv_design: "latin"
    (each syllable once per participant) or "factorial" (every syllable in every cell, seed 000's 243);
    cv_syllables: a subset of the 27 (e.g. for a quick pilot);
    emotion_sentences: neutral sentences shown neutral/smiling/sad; mos_sentences: sentences rated real
    vs synthetic; mos_clips: extra ``(system, path)`` clips to rate; width/height/fps: rendered video;
    level_dbfs: presentation level; expression_strength: 0..1, the intensity of the smiling and sad faces (as
    ``facecast render --expression smile:STRENGTH``).
    """

    out_dir: Path
    grid_root: Path | None = None
    snrs_db: tuple[float, ...] = (-5.0, -10.0, -15.0)
    cv_snrs_db: tuple[float, ...] = (-5.0, -10.0, -15.0)
    synthetic_audio: tuple[str, ...] = ("clean",)
    sentences_per_cell: int = 2
    practice: bool = True
    cv_languages: tuple[str, ...] = ("en", "es")
    cv_design: str = "latin"
    cv_syllables: tuple[str, ...] = SYLLABLES
    emotion_sentences: int = 1
    mos_sentences: int = 2
    mos_clips: tuple[tuple[str, Path], ...] = ()
    width: int = 640
    height: int = 480
    fps: float = 30.0
    crf: int = 18
    model: Path | None = None
    seed: int = 0
    level_dbfs: float = -20.0
    expression_strength: float = 1.0
    progress: bool = True

    def __post_init__(self) -> None:
        if not self.snrs_db and not self.cv_snrs_db:
            raise BuildError("at least one SNR is needed")
        bad = [a for a in self.synthetic_audio if a not in ("clean", "noisy")]
        if bad or not self.synthetic_audio:
            raise BuildError(f"synthetic_audio must be 'clean' and/or 'noisy', got {self.synthetic_audio}")
        if self.sentences_per_cell < 0 or self.emotion_sentences < 0 or self.mos_sentences < 0:
            raise BuildError("sentence counts must be >= 0")
        if any(lang not in _VOICES for lang in self.cv_languages):
            raise BuildError(f"cv_languages must be among {sorted(_VOICES)}, got {self.cv_languages}")
        if not self.cv_syllables or any(s not in SYLLABLES for s in self.cv_syllables):
            raise BuildError(f"cv_syllables must be among {SYLLABLES}, got {self.cv_syllables}")
        if self.cv_design not in ("latin", "factorial"):
            raise BuildError(f"cv_design must be 'latin' or 'factorial', got {self.cv_design!r}")
        if not (64 <= self.width <= 4096 and 64 <= self.height <= 4096) or self.width % 2 or self.height % 2:
            raise BuildError(f"video size must be even and 64..4096, got {self.width}x{self.height}")
        if not 0 <= self.expression_strength <= 1:
            raise BuildError(f"expression_strength must be in 0..1, got {self.expression_strength}")
        for system, path in self.mos_clips:
            if not system or "|" in system or "/" in system:
                raise BuildError(f"clip system label {system!r} must be non-empty without '|' or '/'")
            if not Path(path).is_file():
                raise BuildError(f"{path}: clip to rate not found")

    @property
    def synthetic_conditions(self) -> tuple[str, ...]:
        return tuple({"clean": "S", "noisy": "Sn"}[a] for a in self.synthetic_audio)

    def settings_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("progress")
        d["out_dir"] = str(self.out_dir)
        d["grid_root"] = None if self.grid_root is None else str(self.grid_root)
        d["model"] = None if self.model is None else str(self.model)
        d["mos_clips"] = [[s, str(p)] for s, p in self.mos_clips]
        return d


# --------------------------------------------------------------------------- the manifest


@dataclass(frozen=True, kw_only=True)
class Manifest:
    """A loaded, verified manifest: ``root`` folder, ``test_id``, blocks, stimuli (id -> entry)."""

    root: Path
    test_id: str
    blocks: tuple[Block, ...]
    stimuli: dict[str, dict[str, Any]]
    data: dict[str, Any] = field(repr=False)

    def block(self, name: str) -> Block:
        for b in self.blocks:
            if b.name == name:
                return b
        raise ManifestError(f"{self.root}: no block {name!r}")

    def media_path(self, stimulus: str) -> Path:
        return self.root / self.stimuli[stimulus]["file"]


def _test_id(blocks: list[dict], stimuli: dict[str, dict]) -> str:
    content = {"blocks": blocks, "stimuli": {k: [v["file"], v["sha256"]] for k, v in sorted(stimuli.items())}}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]


def load_manifest(root: str | Path, *, verify: bool = True, check_sources: bool = True) -> Manifest:
    """Read ``root/manifest.json`` (or a manifest path) and, with ``verify``, check every file's hash.

    Raises ManifestError naming the manifest and what is wrong: missing, other kit version (stale),
    edited content, a stimulus file missing or changed (tampered), a GRID source changed (stale)."""
    path = Path(root)
    if path.is_dir():
        path = path / "manifest.json"
    if not path.is_file():
        raise ManifestError(f"{path}: no stimulus manifest here; run `facecast perceptual build -o {path.parent}`")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ManifestError(f"{path}: unreadable manifest: {exc}") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ManifestError(f"{path}: not a {FORMAT} manifest")
    if data.get("kit_version") != KIT_VERSION:
        raise ManifestError(
            f"{path}: stale manifest: built by perceptual kit version {data.get('kit_version')}, this facecast "
            f"makes version {KIT_VERSION}; run `facecast perceptual build` again"
        )
    try:
        blocks = tuple(Block.from_json(b) for b in data["blocks"])
        stimuli = data["stimuli"]
        test_id = data["test_id"]
    except (KeyError, TypeError) as exc:
        raise ManifestError(f"{path}: malformed manifest: missing {exc}") from exc
    if _test_id(data["blocks"], stimuli) != test_id:
        raise ManifestError(
            f"{path}: the manifest was edited after it was built (its content does not match "
            f"test id {test_id}); run `facecast perceptual build` again"
        )
    for b in blocks:
        missing = [s for s in b.stimulus_ids() if s not in stimuli]
        if missing:
            raise ManifestError(f"{path}: block {b.name!r} needs stimuli the manifest lacks: {missing[:3]}")
    if verify:
        problems = []
        for sid, st in stimuli.items():
            f = path.parent / st["file"]
            if not f.is_file():
                problems.append(f"{st['file']} is missing")
            elif f.stat().st_size != st["bytes"] or sha256_file(f) != st["sha256"]:
                problems.append(f"{st['file']} ({sid}) differs from the manifest")
        if problems:
            raise ManifestError(
                f"{path}: stimulus files were tampered with or are stale: {'; '.join(problems[:5])}"
                f"{' ...' if len(problems) > 5 else ''} ({len(problems)} in all); run "
                f"`facecast perceptual build` again"
            )
    if check_sources:
        for src, digest in data.get("sources", {}).items():
            p = Path(src)
            if p.is_file() and sha256_file(p) != digest:
                raise ManifestError(
                    f"{path}: stale stimuli: source {p} changed since the build; run `facecast perceptual build` again"
                )
    return Manifest(root=path.parent, test_id=test_id, blocks=blocks, stimuli=stimuli, data=data)


# --------------------------------------------------------------------------- building


class _Builder:
    def __init__(self, config: BuildConfig) -> None:
        self.c = config
        self.root = Path(config.out_dir)
        self.cache = self.root / "cache"
        self.media = self.root / "media"
        self.index_path = self.cache / "index.json"
        self.index: dict[str, str] = {}
        if self.index_path.is_file():
            try:
                self.index = json.loads(self.index_path.read_text())
            except (OSError, json.JSONDecodeError):
                self.index = {}
        ffmpeg = shutil.which("ffmpeg")
        if ffmpeg is None:
            raise BuildError("ffmpeg is not installed (apt-get install ffmpeg); it encodes every stimulus")
        self.ffmpeg: str = ffmpeg
        self.sources: dict[str, str] = {}
        self._renderer: tuple[Any, Any] | None = None  # (the head's rig, its renderer)
        self.made = 0
        self.reused = 0

    # -- cache ------------------------------------------------------------------------------
    def cached(self, folder: Path, key: str, suffix: str, make: Callable[[Path], object]) -> Path:
        """The file ``folder/key[:24]suffix``, made by ``make(tmp_path)`` unless cached intact."""
        out = folder / f"{key[:24]}{suffix}"
        rel = str(out.relative_to(self.root))
        if out.is_file() and self.index.get(rel) == sha256_file(out):
            self.reused += 1
            return out
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=suffix, dir=folder)
        os.close(fd)
        try:
            make(Path(tmp))
            os.chmod(tmp, 0o644)
            os.replace(tmp, out)
        finally:
            Path(tmp).unlink(missing_ok=True)
        self.index[rel] = sha256_file(out)
        from assets.files import atomic_write_bytes

        atomic_write_bytes(self.index_path, json.dumps(self.index, indent=0, sort_keys=True).encode())
        self.made += 1
        return out

    def run_ffmpeg(self, args: list[str], what: str) -> None:
        proc = subprocess.run(
            [self.ffmpeg, "-y", "-nostdin", "-loglevel", "error", *args], capture_output=True, text=True, check=False
        )
        if proc.returncode != 0:
            raise BuildError(f"{what}: ffmpeg failed: {proc.stderr.strip()[-400:]}")

    # -- audio ------------------------------------------------------------------------------
    def wav(self, key: str, samples: np.ndarray, rate: int) -> Path:
        from assets.audio import write_wav

        return self.cached(self.cache / "audio", key, ".wav", lambda p: write_wav(p, samples, rate))

    def grid_audio(self, sentence) -> tuple[np.ndarray, np.ndarray, int, str]:
        """Clean GRID speech (n,), its speech mask (n,), rate, and the source video's hash."""
        from assets.audio import read_audio
        from assets.grid import SILENCE_WORDS, read_words

        digest = self.sources.get(str(sentence.video)) or sha256_file(sentence.video)
        self.sources[str(sentence.video)] = digest
        x, rate = read_audio(sentence.video)
        words = [(s, e) for s, e, w in read_words(sentence.align) if w not in SILENCE_WORDS]
        if not words:
            raise BuildError(f"{sentence.align}: no words in the alignment")
        t = np.arange(len(x)) / rate
        active = (t >= words[0][0]) & (t < words[-1][1])
        return x, active, rate, digest

    def syllable_audio(self, lang: str, syl: str) -> tuple[np.ndarray, np.ndarray, int, str]:
        """espeak-ng speech of one CV syllable, padded; cached as WAV (espeak is not bit-reproducible
        across processes, the cached file is what every condition uses)."""
        from assets.audio import read_wav
        from assets.espeak import Voice, synthesizer

        cons = next(c for c in sorted(CONSONANTS, key=len, reverse=True) if syl.startswith(c))
        vow = syl[len(cons) :]
        text = _EN_SPELLING[vow][cons] if lang == "en" else syl
        voice = Voice(language=lang, base=_VOICES[lang])
        key = _key({"what": "syllable", "lang": lang, "syl": syl, "text": text, "voice": voice.label})

        def make(p: Path) -> None:
            from assets.audio import write_wav

            s = synthesizer().synthesize(text, voice, noise_seed=self.c.seed)
            got = [ph.phoneme for ph in s.phonemes if not ph.phoneme.startswith("_")]
            want = [_ESPEAK_CONSONANT[cons], _ESPEAK_VOWEL[lang][vow]]
            if got != want:
                raise BuildError(f"espeak-ng ({voice.espeak_name}) said {got} for {text!r}, expected {want}")
            pad = np.zeros(int(CV_PAD_S * s.sample_rate_hz), dtype=np.int16)
            write_wav(p, np.concatenate([pad, s.samples, pad]), s.sample_rate_hz)

        path = self.cached(self.cache / "syllables", key, ".wav", make)
        x, rate = read_wav(path)
        # Speech region: where the padded signal is above -40 dB of its peak (espeak leaves no noise).
        env = np.abs(x) > 0.01 * np.max(np.abs(x))
        idx = np.flatnonzero(env)
        active = np.zeros(len(x), dtype=bool)
        active[idx[0] : idx[-1] + 1] = True
        return x, active, rate, sha256_file(path)

    def mixes(
        self, item: str, x: np.ndarray, active: np.ndarray, rate: int, src: str, snrs: tuple[float | None, ...]
    ) -> dict[float | None, Path]:
        """WAV per SNR (None: clean), each at the presentation level."""
        out = {}
        for snr in snrs:
            spec = {
                "what": "mix",
                "src": src,
                "item": item,
                "snr": snr,
                "seed": self.c.seed,
                "level": self.c.level_dbfs,
            }

            def samples(snr=snr) -> np.ndarray:
                y = x if snr is None else add_white_noise(x, active, snr, _noise_seed(self.c.seed, item, snr))
                return set_level(y, active, self.c.level_dbfs)

            out[snr] = self.wav(_key(spec), samples(), rate)
        return out

    # -- video ------------------------------------------------------------------------------
    def renderer(self):
        if self._renderer is None:
            from assets.heads.head import resolve_head
            from clients.render.renderer import RenderConfig, renderer_for_rig

            # The head `facecast render` draws by default: the built-in head through its own ARKit targets, whose face
            # shapes (cheeks, eyes, brows) show an expression beside the mouth (MorphRig.face_recipe).
            head = resolve_head("builtin")
            r = renderer_for_rig(head.rig, head.mesh, RenderConfig(width=self.c.width, height=self.c.height))
            self._renderer = (head.rig, r)
        return self._renderer

    def model_digest(self) -> str:
        from assets.modelfile import resolve_model

        return sha256_file(resolve_model(self.c.model))

    def head_video(self, speech: Path, expression: str) -> Path:
        """Silent MP4 of the built-in head animated from ``speech`` with ``expression``."""
        spec = {
            "what": "head",
            "speech": sha256_file(speech),
            "expression": expression,
            "strength": self.c.expression_strength,
            "head": "builtin, own targets",
            "recipe": dict(EXPRESSION_RECIPES.get(expression, {})),
            "expression_params": EXPRESSION_PARAMS.tolist(),
            "size": [self.c.width, self.c.height],
            "fps": self.c.fps,
            "crf": self.c.crf,
            "model": self.model_digest(),
        }

        def make(p: Path) -> None:
            from clients.render.video import VideoConfig, params_for_audio, write_video
            from realtime_core.track import frames_from_samples

            track = params_for_audio(speech, self.c.model)
            if track.fps != self.c.fps:
                track = frames_from_samples(track.times(), track.values, self.c.fps)
            frames = track.values
            rig, r = self.renderer()
            alpha = np.zeros((len(frames), len(CORE_EXPRESSIONS)))
            if expression != "neutral":
                # The product's expression (`facecast render --expression`): the mouth through the four parameters
                # (paper 002 eq. 2), the rest of the face through the head's own face shapes.
                alpha[:, CORE_EXPRESSIONS.index(expression)] = self.c.expression_strength
                frames = express(frames, alpha)
            write_video(
                np.arange(len(frames)),
                lambda k: r.render(rig.deformed(frames[k], alpha[k])),
                p,
                size=(self.c.width, self.c.height),
                config=VideoConfig(fps=self.c.fps, crf=self.c.crf),
            )

        return self.cached(self.cache / "render", _key(spec), ".mp4", make)

    def encode(self, spec: dict[str, Any], args: Callable[[Path], list[str]], what: str) -> Path:
        return self.cached(self.media, _key(spec), ".mp4", lambda p: self.run_ffmpeg(args(p), what))

    def audio_only(self, wav: Path) -> Path:
        spec = {"what": "A", "audio": sha256_file(wav)}
        return self.encode(
            spec,
            lambda p: ["-i", str(wav), "-c:a", "aac", "-b:a", "128k", "-movflags", "+faststart", "-f", "mp4", str(p)],
            f"{wav} -> audio-only stimulus",
        )

    def with_audio(self, video: Path, wav: Path, what: str, *, reencode: bool) -> Path:
        """``video``'s picture (scaled and padded into the frame when ``reencode``) with ``wav``'s sound."""
        spec = {
            "what": "AV",
            "video": sha256_file(video),
            "audio": sha256_file(wav),
            "reencode": reencode,
            "size": [self.c.width, self.c.height],
            "crf": self.c.crf,
        }
        w, h = self.c.width, self.c.height
        vf = f"scale={w}:{h}:force_original_aspect_ratio=decrease,pad={w}:{h}:(ow-iw)/2:(oh-ih)/2,setsar=1"
        vcodec = (
            ["-vf", vf, "-c:v", "libx264", "-crf", str(self.c.crf), "-pix_fmt", "yuv420p"]
            if reencode
            else ["-c:v", "copy"]
        )

        def args(p: Path) -> list[str]:
            return [
                "-i",
                str(video),
                "-i",
                str(wav),
                "-map",
                "0:v:0",
                "-map",
                "1:a:0",
                *vcodec,
                "-c:a",
                "aac",
                "-b:a",
                "128k",
                "-movflags",
                "+faststart",
                "-f",
                "mp4",
                str(p),
            ]

        return self.encode(spec, args, what)


def _select_sentences(config: BuildConfig, n: int) -> list:
    from assets.grid import default_root, sentences

    root = Path(config.grid_root) if config.grid_root is not None else default_root()
    if not (root / "video").is_dir():
        raise BuildError(f"{root}: GRID s1 corpus not found (expected video/ and align/ folders); pass --grid")
    test = sentences(root, split="test")
    if len(test) < n:
        raise BuildError(f"{root}: the test split has {len(test)} sentences, the test design needs {n}")
    order = np.random.default_rng(config.seed).permutation(len(test))
    return [test[i] for i in order[:n]]


def build(config: BuildConfig) -> Manifest:
    """Make (or reuse) every stimulus and write ``manifest.json``; returns the verified manifest."""
    from assets.progress import Progress

    c = config
    b = _Builder(c)
    grid_conds = ("A", "N", *c.synthetic_conditions)
    blocks: list[Block] = []
    n_grid = len(grid_conds) * len(c.snrs_db) * c.sentences_per_cell if c.snrs_db else 0
    n_practice = len(grid_conds) if c.practice and n_grid else 0
    counts = [n_practice, n_grid, c.emotion_sentences, c.mos_sentences]
    picked = _select_sentences(c, sum(counts)) if sum(counts) else []
    by_id = {s.sentence_id: s for s in picked}
    parts, k = [], 0
    for n in counts:
        parts.append([s.sentence_id for s in picked[k : k + n]])
        k += n
    practice_ids, grid_ids, emotion_ids, mos_ids = parts
    if practice_ids:
        blocks.append(
            Block(
                name="practice",
                kind="keywords",
                design="latin",
                conditions=grid_conds,
                snrs_db=(max(c.snrs_db),),
                items=tuple(practice_ids),
                per_cell=1,
                practice=True,
                title="Practice",
                instructions=_INSTRUCTIONS["practice"],
            )
        )
    if grid_ids:
        blocks.append(
            Block(
                name="grid",
                kind="keywords",
                design="latin",
                conditions=grid_conds,
                snrs_db=c.snrs_db,
                items=tuple(grid_ids),
                per_cell=c.sentences_per_cell,
                title="Sentences in noise",
                instructions=_INSTRUCTIONS["keywords"],
            )
        )
    if c.cv_languages and c.cv_snrs_db:
        items = tuple(f"{lang}:{s}" for lang in c.cv_languages for s in c.cv_syllables)
        conds = ("A", *c.synthetic_conditions)
        n_cells = len(conds) * len(c.cv_snrs_db)
        per_cell = max(1, len(items) // n_cells)
        if c.cv_design == "latin" and len(items) < n_cells:
            raise BuildError(f"{len(items)} syllables cannot fill {n_cells} cells; use cv_design 'factorial'")
        blocks.append(
            Block(
                name="cv",
                kind="syllable",
                design=c.cv_design,
                conditions=conds,
                snrs_db=c.cv_snrs_db,
                items=items,
                per_cell=per_cell,
                title="Syllables in noise",
                instructions=_INSTRUCTIONS["syllable"],
            )
        )
    if emotion_ids:
        blocks.append(
            Block(
                name="emotion",
                kind="emotion",
                design="factorial",
                conditions=EXPRESSIONS,
                snrs_db=(None,),
                items=tuple(emotion_ids),
                title="Emotion",
                instructions=_INSTRUCTIONS["emotion"],
            )
        )
    if mos_ids:
        blocks.append(
            Block(
                name="mos",
                kind="mos",
                design="factorial",
                conditions=("N", "S"),
                snrs_db=(None,),
                items=tuple(mos_ids),
                title="Opinion scores",
                instructions=_INSTRUCTIONS["mos"],
            )
        )
    if c.mos_clips:
        names = tuple(f"{system}/{Path(p).stem}" for system, p in c.mos_clips)
        if len(set(names)) != len(names):
            raise BuildError(f"two rated clips share a system and file name: {names}")
        blocks.append(
            Block(
                name="clips",
                kind="mos",
                design="factorial",
                conditions=("clip",),
                snrs_db=(None,),
                items=names,
                title="Opinion scores of clips",
                instructions=_INSTRUCTIONS["mos"],
            )
        )
    if not blocks:
        raise BuildError("the configuration asks for no stimuli at all")

    jobs = [(blk, sid) for blk in blocks for sid in blk.stimulus_ids()]
    stimuli: dict[str, dict[str, Any]] = {}
    audio_cache: dict[str, tuple] = {}
    bar = Progress(jobs, desc="perceptual stimuli", unit="stim", disable=not c.progress)
    try:
        for blk, sid in bar:
            _, item, cond, _snr = sid.split("|")
            snr = None if _snr == "clean" else float(_snr)
            bar.set_postfix_str(sid, refresh=False)
            if blk.name == "clips":
                path = dict(zip(names, (p for _, p in c.mos_clips)))[item]
                x, rate = _clip_audio(Path(path))
                wav = b.wav(_key({"what": "clip-audio", "src": sha256_file(path)}), x, rate)
                out = b.with_audio(Path(path), wav, f"{path}", reencode=True)
                fps, src_video = _probe_fps(Path(path)), str(path)
            else:
                if item not in audio_cache:
                    audio_cache[item] = (
                        b.syllable_audio(*item.split(":")) if blk.kind == "syllable" else b.grid_audio(by_id[item])
                    )
                x, active, rate, src = audio_cache[item]
                wavs = b.mixes(item, x, active, rate, src, (None, snr) if snr is not None else (None,))
                heard = wavs[snr]
                src_video = None
                if cond == "A":
                    out, fps = b.audio_only(heard), None
                elif cond == "N":
                    src_video = str(by_id[item].video)
                    out, fps = b.with_audio(by_id[item].video, heard, f"{item} natural talker", reencode=True), 25.0
                else:
                    expression = cond if cond in EXPRESSIONS else "neutral"
                    drive = heard if cond == "Sn" else wavs[None]
                    video = b.head_video(drive, expression)
                    out, fps = b.with_audio(video, heard, f"{item} synthetic head", reencode=False), c.fps
            stimuli[sid] = {
                "block": blk.name,
                "kind": blk.kind,
                "item": item,
                "condition": cond,
                "snr_db": snr,
                "truth": truth_of(blk.kind, item, cond) if blk.name != "clips" else {},
                "file": str(out.relative_to(b.root)),
                "sha256": sha256_file(out),
                "bytes": out.stat().st_size,
                "has_video": cond != "A",
                "fps": fps,
                "source_video": src_video,
            }
    finally:
        bar.close()
        if b._renderer is not None:
            b._renderer[1].close()
    block_json = [blk.to_json() for blk in blocks]
    data = {
        "format": FORMAT,
        "kit_version": KIT_VERSION,
        "test_id": _test_id(block_json, stimuli),
        "settings": c.settings_json(),
        "credits": [GRID_CREDIT, "Speech synthesis of syllables: espeak-ng"],
        "blocks": block_json,
        "stimuli": stimuli,
        "sources": b.sources,
        "stats": {"made": b.made, "reused": b.reused},
    }
    from assets.files import atomic_write_bytes

    atomic_write_bytes(b.root / "manifest.json", (json.dumps(data, indent=1) + "\n").encode("utf-8"))
    _remove_unlisted(b.root, stimuli)
    return load_manifest(b.root)


def _remove_unlisted(root: Path, stimuli: dict[str, dict]) -> None:
    """Media files no stimulus lists any more (an older build's) are removed so the folder is the test."""
    keep = {st["file"] for st in stimuli.values()}
    for f in (root / "media").glob("*.mp4"):
        if str(f.relative_to(root)) not in keep:
            f.unlink()


def _clip_audio(path: Path) -> tuple[np.ndarray, int]:
    from assets.audio import read_audio

    return read_audio(path)


def _probe_fps(path: Path) -> float | None:
    exe = shutil.which("ffprobe")
    if exe is None:
        return None
    proc = subprocess.run(
        [
            exe,
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=r_frame_rate",
            "-of",
            "default=nw=1:nk=1",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    try:
        num, den = proc.stdout.strip().split("/")
        return float(num) / float(den)
    except ValueError:
        return None


_INSTRUCTIONS = {
    "practice": "A few practice trials to get used to the page. They are not scored.",
    "keywords": (
        'Each trial plays a short sentence in noise, like "bin blue at F two now". Some trials show '
        "the speaker's face, some an animated face, some nothing. Report the letter and the digit you "
        "heard. Guess if you are not sure."
    ),
    "syllable": "Each trial plays one syllable in noise. Choose the syllable you heard. Guess if you are not sure.",
    "emotion": "Each trial shows an animated face saying a sentence. Which emotion does the speaker show?",
    "mos": (
        "Rate each clip on two five-point scales: how accurately the lips match the speech, and how natural "
        "the face looks (1 bad, 2 poor, 3 fair, 4 good, 5 excellent)."
    ),
}
