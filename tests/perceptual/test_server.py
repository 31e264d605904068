"""The server and its database against bad input, and against being killed (SIGKILL) mid-session."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import threading
import time

import pytest

from perceptual.errors import StoreError
from perceptual.store import Store
from tests.perceptual.harness import ServerProcess, http, media_index, policy

# The experiment server in subprocesses.
pytestmark = pytest.mark.system


@pytest.fixture()
def server(stimuli, tmp_path):
    srv = ServerProcess(stimuli.root, tmp_path / "answers.sqlite")
    yield srv
    srv.stop()


def test_a_database_of_another_test_or_schema_is_refused(stimuli, tmp_path):
    db = tmp_path / "x.sqlite"
    Store.open(db, test_id="0123456789abcdef", manifest={}).close()
    with pytest.raises(StoreError, match=r"another test version.*new database"):
        Store.open(db, test_id=stimuli.test_id, manifest=stimuli.data)
    conn = sqlite3.connect(db)
    conn.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="schema version 99"):
        Store.open_existing(db)
    bad = tmp_path / "not.sqlite"
    bad.write_bytes(b"not a database at all" * 100)
    with pytest.raises(StoreError, match="not"):
        Store.open_existing(bad)


def test_bad_requests_get_clear_errors_and_never_stop_the_server(server, stimuli):
    url = server.url
    status, p = http("POST", f"{url}/api/participants", {"id": "P01"})
    assert status == 201
    status, r = http("POST", f"{url}/api/participants", {"id": "P01"})
    assert status == 409 and "P01 is already used" in r["error"]
    status, r = http("POST", f"{url}/api/participants", {"id": "no spaces please"})
    assert status == 400 and "letters, digits" in r["error"]
    index = media_index(stimuli)
    status, s = http("GET", f"{url}/api/session?participant=P01&token={p['token']}")
    t0 = s["trials"][0]
    st = index[t0["media"]]
    good = {
        "participant": "P01",
        "token": p["token"],
        "trial": 0,
        "media": t0["media"],
        "response": policy(st["kind"], st["condition"], st["truth"]),
    }
    for change, code, words in [
        ({"token": "wrong"}, 400, "wrong session token"),
        ({"participant": "nobody"}, 400, "unknown participant"),
        ({"trial": 10_000}, 400, "not in their plan"),
        ({"media": s["trials"][1]["media"]}, 400, "not its stimulus"),
        ({"response": {"letter": "w", "digit": "1"}}, 400, "is not one of"),
    ]:
        status, r = http("POST", f"{url}/api/answers", {**good, **change})
        assert status == code and words in r["error"], (change, r)
    status, r = http("POST", f"{url}/api/answers", good)
    assert (status, r["status"]) == (200, "stored")
    status, r = http("POST", f"{url}/api/answers", good)  # a double submission
    assert (status, r["status"]) == (200, "duplicate")
    other = dict(good, response={"letter": "a", "digit": "0"} if st["kind"] == "keywords" else good["response"])
    status, r = http("POST", f"{url}/api/answers", other)
    assert status == 200 and r["status"] in ("conflict", "duplicate")
    status, res = http("GET", f"{url}/api/results?key=k")
    assert res["answers"] == 1  # one row, whatever was sent again
    kinds = [e["kind"] for e in res["events"]]
    assert "id_reused" in kinds and "duplicate" in kinds
    assert http("GET", f"{url}/api/results?key=wrong")[0] == 403
    assert http("GET", f"{url}/media/../manifest.json")[0] == 404
    assert server.proc.poll() is None


def test_answers_survive_sigkill_mid_session_without_loss_or_duplicates(stimuli, tmp_path):
    db = tmp_path / "kill.sqlite"
    index = media_index(stimuli)
    srv = ServerProcess(stimuli.root, db)
    try:
        status, p = http("POST", f"{srv.url}/api/participants", {})
        pid, token = p["participant"], p["token"]
        _, s = http("GET", f"{srv.url}/api/session?participant={pid}&token={token}")
        trials = s["trials"]
        bodies = []
        for t in trials:
            st = index[t["media"]]
            bodies.append(
                {
                    "participant": pid,
                    "token": token,
                    "trial": t["index"],
                    "media": t["media"],
                    "response": policy(st["kind"], st["condition"], st["truth"]),
                }
            )
        confirmed: list[int] = []
        half = len(trials) // 2

        def client(url: str) -> None:
            # Answers sent back to back; the server is killed while one is in flight.
            for b in bodies:
                try:
                    status, _r = http("POST", f"{url}/api/answers", b)
                except OSError:
                    return
                if status == 200:
                    confirmed.append(b["trial"])

        th = threading.Thread(target=client, args=(srv.url,))
        th.start()
        deadline = time.monotonic() + 120
        while len(confirmed) < half and th.is_alive() and time.monotonic() < deadline:
            time.sleep(0.002)
        os.kill(srv.proc.pid, signal.SIGKILL)
        th.join(30)
        srv.proc.wait()
        n_confirmed = len(confirmed)
        assert half <= n_confirmed < len(trials)
        with sqlite3.connect(db) as conn:  # the killed server's database, as it was left
            rows = conn.execute("SELECT trial, response FROM answers WHERE participant = ?", (pid,)).fetchall()
        stored = {t: json.loads(r) for t, r in rows}
        assert set(confirmed) <= set(stored)  # every confirmed answer is there
        assert len(rows) == len(stored) <= n_confirmed + 1  # at most the in-flight one more, none twice
        # The page resends every answer it has no confirmation for (and the last confirmed one again).
        srv = ServerProcess(stimuli.root, db)
        for b in bodies[n_confirmed - 1 :]:
            status, r = http("POST", f"{srv.url}/api/answers", b)
            assert status == 200 and r["status"] in ("stored", "duplicate"), r
        _, s2 = http("GET", f"{srv.url}/api/session?participant={pid}&token={token}")
        assert s2["answered"] == list(range(len(trials)))
    finally:
        srv.stop()
    with sqlite3.connect(db) as conn:
        rows = conn.execute(
            "SELECT trial, response FROM answers WHERE participant = ? ORDER BY trial", (pid,)
        ).fetchall()
        done = conn.execute("SELECT completed_utc FROM participants WHERE id = ?", (pid,)).fetchone()[0]
    assert [t for t, _ in rows] == list(range(len(trials)))
    assert [json.loads(r) for _, r in rows] == [b["response"] for b in bodies]
    assert done is not None
