"""The perceptual experiment's test harness: a tiny real stimulus set's configuration, the experiment
server in a subprocess, and the simulated participant's answer policy (mirrored in session_check.mjs)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

from perceptual.design import CONSONANTS, LETTERS
from tests.prerequisites import SHARED_DATA

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "artifacts" / "perceptual"


def grid_root() -> Path | None:
    for base in (SHARED_DATA, REPO.parent / "shared" / "data", REPO.parent.parent / "shared" / "data"):
        p = base / "video" / "grid_s1"
        if (p / "video").is_dir():
            return p
    return None


def tiny_config(out_dir: Path, root: Path):
    """Two SNRs, one sentence per cell, four Spanish syllables, one emotion and one MOS sentence: every
    block and condition, about 20 renders at the real 640x480."""
    from perceptual.stimuli import BuildConfig

    return BuildConfig(
        out_dir=out_dir,
        grid_root=root,
        snrs_db=(-5.0, -10.0),
        cv_snrs_db=(-5.0, -10.0),
        sentences_per_cell=1,
        cv_languages=("es",),
        cv_syllables=("pa", "ba", "ma", "ta"),
        emotion_sentences=1,
        mos_sentences=1,
        progress=False,
    )


def policy(kind: str, condition: str, truth: dict) -> dict:
    """The simulated participant's answer (the same rules as session_check.mjs)."""
    if kind == "keywords":
        wrong_letter = LETTERS[(LETTERS.index(truth["letter"]) + 1) % len(LETTERS)]
        wrong_digit = str((int(truth["digit"]) + 1) % 10)
        if condition == "N":
            return dict(truth)
        if condition.startswith("S"):
            return {"letter": truth["letter"], "digit": wrong_digit}
        return {"letter": wrong_letter, "digit": truth["digit"] if int(truth["digit"]) % 2 == 0 else wrong_digit}
    if kind == "syllable":
        syl = truth["syllable"]
        if condition.startswith("S") or syl.endswith("a"):
            return {"syllable": syl}
        return {"syllable": CONSONANTS[(CONSONANTS.index(syl[:-1]) + 1) % len(CONSONANTS)] + syl[-1]}
    if kind == "emotion":
        return {"emotion": {"neutral": "neutral", "smile": "happy", "sad": "not sure"}[condition]}
    return {"N": {"accuracy": 5, "naturalness": 4}, "S": {"accuracy": 3, "naturalness": 2}}.get(
        condition, {"accuracy": 3, "naturalness": 3}
    )


def http(method: str, url: str, body: dict | None = None) -> tuple[int, dict]:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            raw = r.read()
            return r.status, (json.loads(raw) if raw else {})
    except urllib.error.HTTPError as e:
        raw = e.read()
        try:
            return e.code, json.loads(raw or b"{}")
        except json.JSONDecodeError:
            return e.code, {"text": raw.decode(errors="replace")}


class ServerProcess:
    """``facecast perceptual serve`` in a real subprocess on a free port."""

    def __init__(self, stimuli: Path, db: Path, key: str = "k") -> None:
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "facecast",
                "perceptual",
                "serve",
                str(stimuli),
                "--db",
                str(db),
                "--port",
                "0",
                "--results-key",
                key,
            ],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.url = None
        deadline = time.monotonic() + 60
        lines = []
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            m = re.search(r"participants: (http://[0-9.]+:\d+)/", line)
            if m:
                self.url = m.group(1)
                break
        if self.url is None:
            self.proc.kill()
            raise RuntimeError(f"server did not start: {''.join(lines)} {self.proc.stderr.read()}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def media_index(manifest) -> dict[str, dict]:
    """'/media/<file>' -> manifest stimulus entry."""
    return {f"/media/{Path(st['file']).name}": st for st in manifest.stimuli.values()}


def answer_all(url: str, participant: str, token: str, index: dict[str, dict], *, start: int = 0) -> list[dict]:
    """Answer every remaining trial over HTTP with the policy; returns the session's trials."""
    status, s = http("GET", f"{url}/api/session?participant={participant}&token={token}")
    assert status == 200, s
    for t in s["trials"][start:]:
        st = index[t["media"]]
        body = {
            "participant": participant,
            "token": token,
            "trial": t["index"],
            "media": t["media"],
            "response": policy(st["kind"], st["condition"], st["truth"]),
        }
        status, r = http("POST", f"{url}/api/answers", body)
        assert status == 200 and r["status"] in ("stored", "duplicate"), r
    return s["trials"]
