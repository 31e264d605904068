// facecast browser viewer: pick a live session, watch and hear it, reconnect on its own.
//
// Page options (query string): session=NAME (watch this one; default: the first live session),
// token=T (the server's shared token), buffer_ms=N (jitter buffer, default 80), kind=morph|deltas|params
// (what to ask for first; default morph: a head driven by its own morph targets gets its weights, and
// the page falls back to vertex deltas, then to the mouth parameters, when the server has no such head).
// Automation hook: window.facecast exposes the state shown in the panel, freeze(on) to hold the
// displayed frame (screenshots), mouthBox() (where the mouth is on the canvas), morph() (the
// shown frame's streamed weights and the morphTargetInfluences three.js draws with), morphNormals() (how
// the normals drawn at the shown influences turn and follow the shape: HeadView.morphNormals), applied(from)
// (the record of every frame applied: {n, index, peak, late, gap}, n counting from 0, late: s its time had
// passed when the refresh that showed it came, gap: s since the refresh before), and freezeWhen({above}
// or {below}) + caught(): the page itself freezes on the first frame applied after the call whose
// peak passes the bound, so a check never depends on polling a value that changes 30 times a second.

import { decodeMessage, KIND, CLOSE } from "./protocol.js";
import { PlayoutClock, AudioOut, DisplayRate, nowS, takeDue } from "./playout.js";
import { HeadView } from "./head.js";
import { pageOptions } from "./options.js";

const opts = new URLSearchParams(location.search);
const token = opts.get("token");
const bufferS = Math.max(0, Number(opts.get("buffer_ms") ?? 80)) / 1000;
const POLL_S = 1.0; // session list refresh (and reconnect attempts)
// While waiting for a session on a reachable server the list is polled this often: a session's first
// frame leaves the server ~0.2 s after its audio starts and a later viewer gets no replay, so a page
// polling only every POLL_S joined up to a second late and never showed the start of the speech.
const WAIT_POLL_S = 0.1;
let waitTimer = null;

const $ = (id) => document.getElementById(id);
const page = pageOptions(opts);
for (const w of page.warnings) console.warn(`facecast viewer: ${w}`);
document.body.classList.toggle("embed", page.embed);
document.documentElement.classList.toggle("transparent", page.background === null);
const view = new HeadView($("view"), { background: page.background });
const audio = new AudioOut();

const state = {
  status: "starting",
  session: null, // the session being watched
  wanted: opts.get("session"), // the session the user asked for (null: the first live one)
  sessions: [],
  connections: 0, // descriptions received (one per successful connection)
  frames: 0, // frames shown
  received: 0, // frames received on this connection
  firstIndex: null, // index of the first frame received on this connection (0: watched from the start)
  lost: 0, // frames the server dropped or never sent (gaps in the frame index)
  skipped: 0, // frames due together with a newer one in one display refresh (display too slow): not shown
  resyncs: 0, // timeline moves later after a late frame
  catchups: 0, // timeline moves earlier once frames come early again (never before where the first frame put it)
  deliveryMs: null, // server send -> browser receipt (median of the last 30 frames)
  behindAudioMs: null, // frame arrival - arrival of the audio of the same media time
  waitMs: null, // frame arrival -> shown (jitter buffer)
  drawMs: null, // time the page's script spends applying a frame and submitting the draw (median of the last 30;
  // a software renderer draws after that: displayHz tells how often the browser manages a picture)
  headLoadMs: null, // description -> head downloaded and built (or reused)
  ticks: 0, // animation frames the page has run
  displayHz: null, // display refreshes per second over the last second of play (below 30: frames are skipped)
  lastPeak: 0, // largest vertex delta of the shown frame (mesh units)
  kind: null,
  closeCode: null,
  closeReason: "",
  restSteps: 0, // animation frames drawn between a session's last frame and the rest pose (the easing)
  ended: null, // how the last session ended (shown while the page waits for the next), null while watching
  errors: 0,
};

let ws = null;
let clock = new PlayoutClock({ bufferS });
let queue = []; // received frames {msg, due, arrival} waiting for their due time
let desc = null;
let lastIndex = -1;
let frozen = false;
const display = new DisplayRate();
let audioArrivals = []; // [{start, end, arrival}] of recent audio blocks (media s, performance s)
const windows = { delivery: [], behind: [], wait: [], draw: [] };

function median(list, x) {
  list.push(x);
  if (list.length > 30) list.shift();
  const s = [...list].sort((a, b) => a - b);
  return s[s.length >> 1];
}

function setStatus(text) {
  state.status = text;
  $("status").textContent = text;
}

function withToken(q) {
  if (token) q.set("token", token);
  return q;
}

async function pollSessions() {
  try {
    // /sessions is cluster-wide and, like every private route, needs the token when the server has one.
    const url = token ? `/sessions?token=${encodeURIComponent(token)}` : "/sessions";
    const res = await fetch(url, { cache: "no-store" });
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    const m = await res.json();
    if (!ws && Array.isArray(m.view_kinds)) {
      // The best kind this server offers, from the one asked for on: no attempt it would refuse (a head without
      // targets of its own refused "morph" with 4400 at every connection, and logged it).
      const offered = KINDS.slice(firstKind).find((k) => m.view_kinds.includes(k));
      if (offered) kindLevel = KINDS.indexOf(offered);
    }
    state.sessions = (m.sessions || []).map((s) => s.name);
    renderSessionList(m.sessions || []);
    if (!ws) {
      const target = state.wanted ?? state.sessions[0];
      if (target && state.sessions.includes(target)) connect(target);
      else {
        // The last session's end stays said while the page waits (the poll 0.2 s after a close used to
        // replace "session ended" by a bare "waiting").
        const waiting = state.wanted ? `waiting for session "${state.wanted}"` : "waiting for a live session";
        setStatus(state.ended ? `${state.ended}; ${waiting}` : waiting);
        showHeadAtRest();
        clearTimeout(waitTimer); // one pending fast poll at most (the POLL_S interval also calls this)
        waitTimer = setTimeout(pollSessions, WAIT_POLL_S * 1000);
      }
    }
  } catch (err) {
    state.sessions = [];
    kindLevel = firstKind; // the server that comes back may have another head
    renderSessionList([]);
    if (!ws) setStatus("server unreachable, retrying");
  }
}

let restAsked = false; // the served head was asked for to show at rest while no session plays
/** While the page waits for a session and has shown none, the server's head at rest (an embedded chatbot avatar
 *  is there before its first answer, not an empty canvas). Once; again after a failure (the server was away). */
async function showHeadAtRest() {
  if (restAsked || ws || shown) return;
  restAsked = true;
  try {
    const url = token ? `/head/description.json?token=${encodeURIComponent(token)}` : "/head/description.json";
    const res = await fetch(url, { cache: "no-store" });
    if (res.status === 404) return; // a server without a head: nothing to show before the parameters come
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    const d = await res.json();
    const kind = KINDS.slice(kindLevel).find((k) => k in d.rest_values);
    if (!kind || ws || shown) return;
    await view.load({ ...d.head, morph: kind === "morph" ? d.head.morph : null });
    if (ws || shown) return; // a session began meanwhile: its description and frames take over
    const rest = d.rest_values[kind];
    if (rest && kind === "morph") view.applyWeights(Float32Array.from(rest));
    else if (rest) view.applyDeltas(Float32Array.from(rest));
  } catch (err) {
    console.warn("head at rest:", err);
    restAsked = false;
  }
}

function renderSessionList(list) {
  const ul = $("sessions");
  ul.replaceChildren();
  if (!list.length) {
    const li = document.createElement("li");
    li.textContent = "none";
    li.className = "none";
    ul.append(li);
  }
  for (const s of list) {
    const li = document.createElement("li");
    const a = document.createElement("a");
    a.href = `?${withToken(new URLSearchParams({ session: s.name }))}`;
    a.textContent = s.name;
    a.addEventListener("click", (ev) => {
      ev.preventDefault();
      history.replaceState(null, "", a.href);
      state.wanted = s.name;
      if (ws) ws.close(1000, "switching session");
      else connect(s.name);
    });
    if (s.name === state.session) li.className = "current";
    li.append(a, ` ${s.source}, ${s.viewers} viewer${s.viewers === 1 ? "" : "s"}`);
    ul.append(li);
  }
}

// What to ask for, best first; a refusal ("no morph targets", "no head") moves to the next one.
const KINDS = ["morph", "deltas", "params"];
const firstKind = Math.max(0, KINDS.indexOf(opts.get("kind") ?? "morph"));
let kindLevel = firstKind;
let shown = null; // the last frame shown {index, values} (automation)
const appliedLog = []; // the last APPLIED_KEEP frames applied {n, index, peak, late} (automation)
const APPLIED_KEEP = 2000;
let appliedCount = 0;
let lastTickAt = null; // s: the refresh before this one (a shown frame's lateness is bounded by the gap since)
let armed = null; // freezeWhen's bound {above} or {below}, until a frame passes it
let caught = null; // the frame that froze the page {n, index, peak}
// A session that ends mid-word (an audio or microphone session closed while the mouth is open) would
// leave its last frame on screen until another session starts: once the frames queued at the close have
// been shown, the face eases to rest over REST_EASE_S: the description's rest_values (a head resting through its
// own targets, lips modelled apart: its jaw below 0), else zero weights, deltas or parameters.
const REST_EASE_S = 0.2;
let toRest = null; // null, or {start: null} from the close until the queue drains, then {start, from}

function connect(name) {
  if (ws) return;
  // A new connection is a new timeline: what the last one left queued (and its easing to rest) is dropped when it
  // is described, not before: a poll just after a session's end can still list it, and the attempt, refused with
  // 4004, used to drop the session's last frames and stop its easing half way (see onclose).
  let described = false;
  const before = { ended: state.ended, status: state.status }; // what a refused attempt leaves as it was
  const kind = KINDS[kindLevel];
  const q = withToken(new URLSearchParams({ session: name, kind, audio: "1" }));
  if (kind === "deltas") q.set("encoding", "int16");
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const sock = new WebSocket(`${proto}//${location.host}/view?${q}`);
  sock.binaryType = "arraybuffer";
  ws = sock;
  state.session = name;
  state.kind = kind;
  state.ended = null;
  setStatus(`connecting to "${name}"`);
  sock.onmessage = (ev) => {
    if (typeof ev.data === "string") {
      const text = JSON.parse(ev.data);
      if (text.type === "ack" || text.type === "rejected") {
        onControlReply(text);
        return;
      }
      if (!described) {
        described = true;
        resetStream();
      }
      desc = text;
      showExpressionPicker(desc.expressions ?? []);
      // Frames that arrive while the head downloads are timed and queued; they move the mesh once it exists.
      const head = kind === "params" || !desc.head ? null : { ...desc.head, morph: kind === "morph" ? desc.head.morph : null };
      const loadStart = performance.now();
      const ready = view.load(head).then(() => {
        state.headLoadMs = performance.now() - loadStart;
        // Before a first frame the head shows its rest, not the head as modelled (lips apart on a resting head).
        if (!shown && !queue.length && desc.rest_values) applyValues(Float32Array.from(desc.rest_values));
        state.connections += 1;
        setStatus(kind !== "params" ? `watching "${name}"` : `watching "${name}": mouth parameters only (the server has no head)`);
        $("bars").hidden = kind !== "params";
      });
      ready.catch((err) => {
        console.warn("head download failed", err);
        sock.close(1000, "head download failed");
      });
      return;
    }
    const arrival = nowS();
    let msg;
    try {
      msg = decodeMessage(ev.data);
    } catch (err) {
      console.warn("undecodable message", err);
      return;
    }
    if (msg.kind === KIND.AUDIO) onAudio(msg, arrival);
    else onFrame(msg, arrival);
  };
  sock.onclose = (ev) => {
    if (ws !== sock) return;
    ws = null;
    if (ev.code === CLOSE.BAD_REQUEST && /no head|no morph targets/.test(ev.reason) && kindLevel < KINDS.length - 1) {
      // This kind is unavailable (no head driven by its own targets, or no head): ask for the next, at once.
      kindLevel = /no head/.test(ev.reason) ? KINDS.length - 1 : kindLevel + 1;
      connect(name);
      return;
    }
    if (!described && ev.code === CLOSE.NOT_FOUND && before.ended) {
      // An attempt on a session that has just ended (still listed by the poll): the page stays as the end left
      // it (its last frames, its easing, "session ended") and waits for the session to start again.
      state.ended = before.ended;
      setStatus(before.status);
      setTimeout(pollSessions, POLL_S * 1000);
      return;
    }
    state.closeCode = ev.code;
    state.closeReason = ev.reason;
    if (shown && described) toRest = toRest ?? { start: null };
    // 1001 is also a cluster node's word that the session's own node stopped: the session is over.
    const lost = ev.code === CLOSE.GOING_AWAY && ev.reason.startsWith("session lost");
    const why = lost ? `session ended (${ev.reason})` : {
      [CLOSE.NORMAL]: "session ended", [CLOSE.GOING_AWAY]: "server restarting",
      [CLOSE.NOT_FOUND]: "no such session", [CLOSE.TOO_SLOW]: "too slow, reconnecting",
      [CLOSE.UNAUTHORIZED]: "wrong or missing token (add ?token=...)",
    }[ev.code] ?? `connection closed (${ev.code})`;
    state.ended = why;
    setStatus(`${why}; waiting for "${state.wanted ?? "any session"}" to (re)start`);
    // The queue is kept: a session's last frames (its lookahead, flushed at the end) arrive just before
    // the close and wait for their due time while their audio, already scheduled, still plays; tick()
    // shows them, so the face ends where the speech ends instead of freezing on the frame shown at the close.
    setTimeout(pollSessions, 200);
  };
}

// Expression picker: the buttons send {"type": "control", "expression": {...}} on the viewer's socket;
// the server eases the session's face to it from the next frame (every viewer of the session sees it).
let activeExpression = "neutral";

function showExpressionPicker(names) {
  const box = $("expressions");
  box.replaceChildren();
  box.classList.toggle("none", names.length === 0);
  if (names.length === 0) {
    box.textContent = "none (this session takes no expressions)";
    return;
  }
  for (const name of names) {
    const b = document.createElement("button");
    b.textContent = name;
    b.dataset.name = name;
    b.classList.toggle("active", name === activeExpression);
    b.onclick = () => sendExpression(name);
    box.appendChild(b);
  }
}

function sendExpression(name) {
  if (!ws || ws.readyState !== WebSocket.OPEN) return;
  const intensity = Number($("intensity").value);
  ws.send(JSON.stringify({ type: "control", expression: { name, intensity } }));
  activeExpression = name;
  for (const b of $("expressions").children) b.classList.toggle("active", b.dataset.name === name);
  $("expression-status").textContent = `asked for ${name} at ${intensity.toFixed(2)}`;
}

function onControlReply(msg) {
  $("expression-status").textContent = msg.type === "ack"
    ? `${activeExpression}: applied` : `rejected: ${msg.reason}`;
}

$("intensity").oninput = () => {
  $("intensity-value").textContent = Number($("intensity").value).toFixed(2);
};
$("intensity").onchange = () => {
  if (activeExpression !== "neutral") sendExpression(activeExpression);
};

function resetStream() {
  clock = new PlayoutClock({ bufferS });
  queue = [];
  lastIndex = -1;
  audioArrivals = [];
  audio.reset();
  state.received = 0;
  state.firstIndex = null;
  toRest = null;
}

function onFrame(msg, arrival) {
  if (lastIndex >= 0 && msg.index > lastIndex + 1) state.lost += msg.index - lastIndex - 1;
  if (msg.index <= lastIndex) return; // stale (never expected: the server sends in order)
  if (state.firstIndex === null) state.firstIndex = msg.index;
  lastIndex = msg.index;
  state.received += 1;
  state.deliveryMs = median(windows.delivery, 1000 * (Date.now() / 1000 - msg.sendTime));
  const a = audioArrivals.find((b) => b.start <= msg.mediaTime && msg.mediaTime < b.end);
  if (a) state.behindAudioMs = median(windows.behind, 1000 * (arrival - a.arrival));
  const [resyncs, catchups] = [clock.resyncs, clock.catchups];
  const due = clock.arrive(msg.mediaTime, arrival);
  state.resyncs += clock.resyncs - resyncs;
  state.catchups += clock.catchups - catchups;
  state.waitMs = median(windows.wait, 1000 * (due - arrival));
  queue.push({ msg, due });
  // Audio that arrived before the first frame fixed the timeline is scheduled now.
  for (const p of pendingAudio.splice(0)) onAudio(p.msg, p.arrival);
}

const pendingAudio = [];

function onAudio(msg, arrival) {
  const rate = desc?.audio?.rate_hz ?? 16000;
  if (!audioArrivals.some((b) => b.start === msg.mediaTime)) {
    audioArrivals.push({ start: msg.mediaTime, end: msg.mediaTime + msg.count / rate, arrival });
    if (audioArrivals.length > 200) audioArrivals.shift();
  }
  const due = clock.due(msg.mediaTime);
  if (due === null) {
    pendingAudio.push({ msg, arrival });
    if (pendingAudio.length > 500) pendingAudio.shift();
    return;
  }
  audio.schedule(msg.values, rate, due);
}

function showParams(values) {
  const names = desc?.params?.names ?? [];
  const bars = $("bars");
  if (bars.children.length !== names.length) {
    bars.replaceChildren(...names.map((n) => {
      const row = document.createElement("div");
      row.innerHTML = `<span>${n}</span><meter min="-0.5" max="0.5" value="0"></meter>`;
      return row;
    }));
  }
  names.forEach((_, i) => { bars.children[i].querySelector("meter").value = values[i]; });
}

function applyValues(values) {
  if (state.kind === "morph") {
    view.applyWeights(values);
    state.lastPeak = view.lastPeak;
  } else if (state.kind === "deltas") {
    view.applyDeltas(values);
    state.lastPeak = view.lastPeak;
  } else {
    showParams(values);
  }
}

function restValues(n) {
  const r = desc?.rest_values;
  return r && r.length === n ? Float32Array.from(r) : new Float32Array(n);
}

function easeToRest(now) {
  if (toRest.start === null) {
    const from = Float32Array.from(shown.values);
    toRest = { start: now, from, to: restValues(from.length) };
  }
  const f = Math.min(1, (now - toRest.start) / REST_EASE_S);
  const k = 1 - f * f * (3 - 2 * f); // smoothstep: no jump at either end
  applyValues(toRest.from.map((v, i) => toRest.to[i] + (v - toRest.to[i]) * k));
  if (f > 0 && f < 1) state.restSteps += 1;
  if (f >= 1) toRest = null;
}

function tick() {
  state.ticks += 1;
  const now = nowS();
  // The rate while frames play (the queue holds some): kept after a session ends, when an idle page
  // refreshes at the screen's rate again (it draws nothing), so the panel still says why frames were skipped.
  if (queue.length) {
    display.tick(now);
    state.displayHz = display.hz;
  }
  const due = takeDue(queue, now);
  // While frozen, due frames are consumed unseen (neither shown nor skipped: the page holds one on purpose).
  const show = frozen ? null : due.show;
  if (!frozen) state.skipped += due.skipped.length;
  const drawStart = performance.now();
  if (!show && toRest && !queue.length && !frozen) easeToRest(now);
  if (show) {
    applyValues(show.msg.values);
    state.frames += 1;
    shown = { index: show.msg.index, values: show.msg.values };
    const gap = lastTickAt === null ? null : now - lastTickAt;
    const rec = { n: appliedCount++, index: show.msg.index, peak: state.lastPeak, late: now - show.due, gap };
    appliedLog.push(rec);
    if (appliedLog.length > APPLIED_KEEP) appliedLog.shift();
    if (armed && (armed.above !== undefined ? rec.peak >= armed.above : rec.peak <= armed.below)) {
      frozen = true; // this frame stays on screen: drawn just below, never replaced while frozen
      caught = rec;
      armed = null;
    }
  }
  view.render();
  if (show) state.drawMs = median(windows.draw, performance.now() - drawStart);
  updatePanel();
  lastTickAt = now;
  requestAnimationFrame(tick);
}

function fmt(x, unit = " ms") {
  return x === null || x === undefined ? "–" : `${x.toFixed(1)}${unit}`;
}

let panelAt = 0;
function updatePanel() {
  const t = nowS();
  if (t - panelAt < 0.25) return;
  panelAt = t;
  $("stats").textContent = [
    `frames shown   ${state.frames}`,
    `lost (gaps)    ${state.lost}`,
    `skipped        ${state.skipped}`,
    `display        ${fmt(state.displayHz, " /s")}`,
    `delivery       ${fmt(state.deliveryMs)}`,
    `behind audio   ${fmt(state.behindAudioMs)}`,
    `buffer         ${fmt(state.waitMs)}`,
    `draw           ${fmt(state.drawMs)}`,
    `resyncs        ${state.resyncs} (+${state.catchups} catch-ups)`,
    `audio          ${audio.running ? `on (${audio.played} blocks)` : "off"}`,
    `audio sync     ${fmt(audio.syncMs)}`,
  ].join("\n");
  $("sound").hidden = audio.running || !audio.ctx;
}

$("sound").addEventListener("click", () => audio.resume().then(updatePanel));
window.addEventListener("error", () => { state.errors += 1; });

window.facecast = {
  state,
  freeze(on) {
    frozen = Boolean(on);
    if (!frozen) caught = null;
    return state.lastPeak;
  },
  applied: (from = 0) => appliedLog.filter((r) => r.n >= from),
  appliedCount: () => appliedCount,
  freezeWhen(bound) {
    caught = null;
    armed = bound;
  },
  caught: () => caught,
  mouthBox: () => view.mouthBox(),
  normalsLag: () => view.normalsLag(),
  morphNormals: () => view.morphNormals(),
  morph: () => ({ names: view.morph?.names ?? null, index: shown?.index ?? null,
    weights: shown && state.kind === "morph" ? Array.from(shown.values) : null, influences: view.influences() }),
  audio: () => ({ running: audio.running, played: audio.played, lateDropped: audio.lateDropped, syncMs: audio.syncMs }),
};

pollSessions();
setInterval(() => { pollSessions(); }, POLL_S * 1000);
requestAnimationFrame(tick);
