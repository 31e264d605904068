"""``facecast perceptual serve``: the experiment's web server (aiohttp on asyncio).

aiohttp rather than the websockets HTTP hook ``server/app.py`` uses: answers arrive as POST bodies
(that hook serves GET only), and ``<video>`` needs HTTP range requests, which aiohttp's file
responses answer.

Routes (participants: the page and its JSON API; the experimenter: ``/results?key=K``)::

    GET  /                     the participant page (consent, instructions, practice, trials)
    GET  /static/<file>        its script and style sheet
    GET  /media/<file>         stimulus MP4s listed in the manifest (nothing else)
    GET  /api/test             blocks, instructions and response sets (no answers, no item names)
    POST /api/participants     {"id"?: str} -> {"participant", "token"}; 409 if the id is taken
    GET  /api/session          ?participant=&token= -> the plan (media URLs only) and answered trials
    POST /api/answers          {"participant", "token", "trial", "media", "response", timings}
                               -> {"status": "stored" | "duplicate" | "conflict"}
    POST /api/events           {"participant", "token", "trial", "kind": play|pause|resume|reload}
    GET  /results, /api/results  ?key=K: progress, scores so far, events (the experimenter's page)

The manifest is verified (every file's hash) before the server starts; a bad request gets a 4xx
with a message and never stops the server.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import json
import secrets
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import web

from perceptual.design import (
    DIGITS,
    EMOTIONS,
    LETTERS,
    MOS_LABELS,
    MOS_SCALES,
    SYLLABLES,
    n_correct,
    plan,
    validate_response,
)
from perceptual.errors import AnswerError, PerceptualError, StoreError
from perceptual.stimuli import Manifest, load_manifest
from perceptual.store import Store


@dataclass(frozen=True, kw_only=True)
class ServeConfig:
    """stimuli: the built stimulus folder; db: the response database (created if missing); host/port
    (0 = any free port); results_key: the experimenter page's key (None: a random one, printed)."""

    stimuli: Path
    db: Path
    host: str = "127.0.0.1"
    port: int = 8090
    results_key: str | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise PerceptualError(f"port must be 0..65535, got {self.port}")


def _web_file(name: str) -> bytes:
    return resources.files("perceptual").joinpath("web", name).read_bytes()


class ExperimentServer:
    """Serves one verified stimulus set and writes answers to one database."""

    def __init__(self, config: ServeConfig) -> None:
        self.config = config
        self.manifest: Manifest = load_manifest(config.stimuli)
        self.store = Store.open(config.db, test_id=self.manifest.test_id, manifest=self.manifest.data)
        self.results_key = config.results_key or secrets.token_urlsafe(9)
        self.media = {Path(st["file"]).name: sid for sid, st in self.manifest.stimuli.items()}
        self.blocks = {b.name: b for b in self.manifest.blocks}
        self.runner: web.AppRunner | None = None
        self.port: int | None = None
        app = web.Application(middlewares=[self._errors], client_max_size=64 * 1024)
        app.add_routes(
            [
                web.get("/", self._index),
                web.get("/static/{name}", self._static),
                web.get("/media/{name}", self._media),
                web.get("/api/test", self._test),
                web.post("/api/participants", self._new_participant),
                web.get("/api/session", self._session),
                web.post("/api/answers", self._answer),
                web.post("/api/events", self._event),
                web.get("/results", self._results_page),
                web.get("/api/results", self._results_json),
            ]
        )
        self.app = app

    # -- lifecycle --------------------------------------------------------------------------
    async def start(self) -> None:
        self.runner = web.AppRunner(self.app, access_log=None)
        await self.runner.setup()
        site = web.TCPSite(self.runner, self.config.host, self.config.port)
        await site.start()
        self.port = self.runner.addresses[0][1]  # the bound port when 0 was asked

    async def stop(self) -> None:
        if self.runner is not None:
            await self.runner.cleanup()
        self.store.close()

    @property
    def url(self) -> str:
        return f"http://{self.config.host}:{self.port}"

    async def serve_forever(self) -> None:
        await self.start()
        print(
            f"perceptual test {self.manifest.test_id}: {len(self.manifest.stimuli)} stimuli, database {self.config.db}"
        )
        print(f"participants: {self.url}/   (an id of your choice: {self.url}/?p=ID)")
        print(f"experimenter: {self.url}/results?key={self.results_key}", flush=True)
        try:
            await asyncio.Event().wait()
        finally:
            await self.stop()

    # -- helpers ----------------------------------------------------------------------------
    @web.middleware
    async def _errors(self, request: web.Request, handler):
        try:
            return await handler(request)
        except web.HTTPException:
            raise
        except StoreError as exc:
            return web.json_response({"error": str(exc)}, status=409)
        except (PerceptualError, ValueError, KeyError, TypeError) as exc:
            return web.json_response({"error": str(exc)}, status=400)

    def _plan_for(self, ordinal: int, pid: str) -> list[dict[str, Any]]:
        trials = plan(list(self.manifest.blocks), ordinal, f"{self.manifest.test_id}|{pid}")
        return [{"index": t.index, "block": t.block, "stimulus": t.stimulus} for t in trials]

    async def _body(self, request: web.Request) -> dict[str, Any]:
        try:
            body = await request.json()
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise AnswerError(f"request body is not JSON: {exc}") from exc
        if not isinstance(body, dict):
            raise AnswerError("request body must be a JSON object")
        return body

    def _check_key(self, request: web.Request) -> None:
        if not secrets.compare_digest(request.query.get("key", ""), self.results_key):
            raise web.HTTPForbidden(text="the results page needs ?key= as printed by `facecast perceptual serve`")

    # -- participant side -------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.Response:
        return web.Response(
            body=_web_file("index.html"), content_type="text/html", headers={"Cache-Control": "no-store"}
        )

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        types = {"experiment.js": "text/javascript", "style.css": "text/css"}
        if name not in types:
            raise web.HTTPNotFound()
        return web.Response(body=_web_file(name), content_type=types[name], headers={"Cache-Control": "no-store"})

    async def _media(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if name not in self.media:
            raise web.HTTPNotFound()
        return web.FileResponse(
            self.manifest.media_path(self.media[name]), headers={"Cache-Control": "private, max-age=3600"}
        )

    async def _test(self, request: web.Request) -> web.Response:
        return web.json_response(
            {
                "test_id": self.manifest.test_id,
                "blocks": [
                    {
                        "name": b.name,
                        "kind": b.kind,
                        "title": b.title,
                        "instructions": b.instructions,
                        "practice": b.practice,
                    }
                    for b in self.manifest.blocks
                ],
                "responses": {
                    "letters": LETTERS,
                    "digits": DIGITS,
                    "syllables": SYLLABLES,
                    "emotions": EMOTIONS,
                    "mos_labels": MOS_LABELS,
                    "mos_scales": MOS_SCALES,
                },
                "credits": self.manifest.data.get("credits", []),
            }
        )

    async def _new_participant(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        requested = body.get("id") or None
        if requested is not None and not isinstance(requested, str):
            raise AnswerError("participant id must be a string")
        p, token = self.store.create_participant(requested, self._plan_for)
        return web.json_response({"participant": p.id, "token": token, "trials": len(p.plan)}, status=201)

    async def _session(self, request: web.Request) -> web.Response:
        p = self.store.participant(request.query.get("participant", ""), request.query.get("token", ""))
        trials = []
        for t in p.plan:
            st = self.manifest.stimuli[t["stimulus"]]
            b = self.blocks[t["block"]]
            trials.append(
                {
                    "index": t["index"],
                    "block": b.name,
                    "kind": b.kind,
                    "practice": b.practice,
                    "media": f"/media/{Path(st['file']).name}",
                    "has_video": st["has_video"],
                    "fps": st["fps"],
                }
            )
        return web.json_response(
            {
                "participant": p.id,
                "trials": trials,
                "answered": self.store.answered(p.id),
                "complete": p.completed_utc is not None,
            }
        )

    async def _answer(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        p = self.store.participant(str(body.get("participant", "")), str(body.get("token", "")))
        trial = body.get("trial")
        if isinstance(trial, bool) or not isinstance(trial, int) or not 0 <= trial < len(p.plan):
            raise AnswerError(f"participant {p.id}: trial {trial!r} is not in their plan of {len(p.plan)} trials")
        sid = p.plan[trial]["stimulus"]
        st = self.manifest.stimuli[sid]
        if body.get("media") != f"/media/{Path(st['file']).name}":
            raise AnswerError(
                f"participant {p.id}: trial {trial} played {body.get('media')!r}, which is not its "
                f"stimulus (the page is out of date: reload it)"
            )
        block = self.blocks[st["block"]]
        response = validate_response(block.kind, body.get("response"))
        correct, scored = n_correct(block.kind, st["truth"], response)

        def num(key: str) -> float | None:
            v = body.get(key)
            return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

        status = self.store.record_answer(
            p.id,
            trial,
            {
                "block": block.name,
                "kind": block.kind,
                "practice": int(block.practice),
                "stimulus": sid,
                "item": st["item"],
                "condition": st["condition"],
                "snr_db": st["snr_db"],
                "truth": json.dumps(st["truth"], sort_keys=True),
                "response": json.dumps(response, sort_keys=True),
                "correct": correct,
                "scored": scored,
                "rt_ms": num("rt_ms"),
                "latency_ms": num("latency_ms"),
                "av_offset_ms": num("av_offset_ms"),
                "plays": int(num("plays") or 0),
            },
        )
        return web.json_response({"status": status, "trial": trial})

    async def _event(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        p = self.store.participant(str(body.get("participant", "")), str(body.get("token", "")))
        kind = body.get("kind")
        if kind not in ("play", "pause", "resume", "reload"):
            raise AnswerError(f"unknown event kind {kind!r}")
        trial = body.get("trial") if isinstance(body.get("trial"), int) else None
        self.store.log_event(p.id, trial, kind, str(body.get("detail", ""))[:200])
        return web.Response(status=204)

    # -- experimenter side ------------------------------------------------------------------
    def results(self) -> dict[str, Any]:
        answers = self.store.answers()
        people = []
        for p in self.store.participants():
            mine = [a for a in answers if a["participant"] == p.id]
            scored = [a for a in mine if a["scored"] and not a["practice"]]
            lat = [a["latency_ms"] for a in mine if a["latency_ms"] is not None]
            people.append(
                {
                    "participant": p.id,
                    "ordinal": p.ordinal,
                    "answered": len(mine),
                    "trials": len(p.plan),
                    "started_utc": p.created_utc,
                    "completed_utc": p.completed_utc,
                    "score": (sum(a["correct"] for a in scored) / sum(a["scored"] for a in scored)) if scored else None,
                    "median_latency_ms": sorted(lat)[len(lat) // 2] if lat else None,
                }
            )
        return {
            "test_id": self.manifest.test_id,
            "database": str(self.config.db),
            "participants": people,
            "answers": len(answers),
            "events": self.store.events(),
        }

    async def _results_json(self, request: web.Request) -> web.Response:
        self._check_key(request)
        return web.json_response(self.results())

    async def _results_page(self, request: web.Request) -> web.Response:
        self._check_key(request)
        r = self.results()
        esc = html.escape
        rows = []
        for p in r["participants"]:
            score = "" if p["score"] is None else f"{p['score']:.1%}"
            lat = "" if p["median_latency_ms"] is None else f"{p['median_latency_ms']:.0f} ms"
            rows.append(
                f"<tr><td>{esc(p['participant'])}</td><td>{p['ordinal']}</td>"
                f"<td>{p['answered']} / {p['trials']}</td>"
                f"<td>{'done' if p['completed_utc'] else 'in progress'}</td><td>{score}</td><td>{lat}</td>"
                f"<td>{esc(p['started_utc'])}</td></tr>"
            )
        rows_html = "".join(rows)
        notable = [e for e in r["events"] if e["kind"] in ("id_reused", "duplicate", "conflict", "reload")]
        events = "".join(
            f"<tr><td>{esc(e['at_utc'])}</td><td>{esc(str(e['participant']))}</td>"
            f"<td>{'' if e['trial'] is None else e['trial']}</td><td>{esc(e['kind'])}</td>"
            f"<td>{esc(e['detail'])}</td></tr>"
            for e in notable[-200:]
        )
        page = f"""<!doctype html><html><head><meta charset="utf-8"><title>facecast perceptual results</title>
<meta http-equiv="refresh" content="10"><link rel="stylesheet" href="/static/style.css"></head>
<body class="results"><h1>Perceptual test {esc(r["test_id"])}</h1>
<p>Database <code>{esc(r["database"])}</code>: {r["answers"]} answers. Report:
<code>facecast perceptual report {esc(r["database"])}</code>. This page refreshes every 10 s.</p>
<table id="participants"><tr><th>participant</th><th>#</th><th>answered</th><th>state</th><th>correct so far</th>
<th>median click-to-start</th><th>started (UTC)</th></tr>{rows_html}</table>
<h2>Events to know about</h2><p>Reused ids, repeated or conflicting submissions, pages reloaded mid-test.</p>
<table id="events"><tr><th>UTC</th><th>participant</th><th>trial</th><th>kind</th><th>detail</th></tr>{events}</table>
</body></html>"""
        return web.Response(text=page, content_type="text/html")


def serve(config: ServeConfig) -> None:
    """Run the server until Ctrl-C."""
    server = ExperimentServer(config)
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(server.serve_forever())
