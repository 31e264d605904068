// The participant page of `facecast perceptual serve`: consent, block instructions, practice, trials with
// closed-set response grids, pause/resume, answers POSTed one by one (retried until the server confirms).
//
// Timing (stored with each answer, and kept in window.perceptual.metrics for the browser test):
//   latency_ms    from the Play click (event.timeStamp) to the stimulus start: for video, the display time
//                 of media time 0 (requestVideoFrameCallback: expectedDisplayTime - mediaTime), and not
//                 before the element's 'playing' event (audio running); for audio only, 'playing'.
//   av_offset_ms  median over displayed frames of (audio clock at the frame's display time - the frame's
//                 timestamp): how late the picture is behind the sound (0 ideal; negative: picture early).
//                 The audio clock is the element's currentTime carried forward to expectedDisplayTime.
// The stimulus is fetched whole into a Blob before Play is enabled, so a click never waits on the network.
"use strict";

const $ = (id) => document.getElementById(id);
const screens = ["loading", "consent", "resume", "intro", "trial", "paused", "done", "fatal"];
const state = { test: null, participant: null, token: null, trials: [], answered: new Set(), pos: 0,
  screen: "loading", phase: "idle", lastBlock: null, response: {}, prefetch: new Map() };
const metrics = [];
window.perceptual = { state, metrics };

function show(name) {
  for (const s of screens) $(s).hidden = s !== name;
  state.screen = name;
}

function fatal(msg) {
  $("fatal-text").textContent = msg;
  show("fatal");
}

async function api(method, url, body) {
  const res = await fetch(url, { method, headers: body ? { "Content-Type": "application/json" } : {},
    body: body ? JSON.stringify(body) : undefined });
  let data = null;
  try { data = await res.json(); } catch { data = null; }
  if (!res.ok) {
    const err = new Error((data && data.error) || `${res.status} ${res.statusText}`);
    err.status = res.status;
    throw err;
  }
  return data;
}

const storageKey = () => `facecast-perceptual:${state.test.test_id}`;

async function init() {
  try {
    state.test = await api("GET", "/api/test");
  } catch (e) {
    return fatal(`The test server cannot be reached (${e.message}).`);
  }
  $("credits").textContent = state.test.credits.join(" · ");
  buildResponseGrids();
  const saved = JSON.parse(localStorage.getItem(storageKey()) || "null");
  if (saved) {
    try {
      state.participant = saved.participant;
      state.token = saved.token;
      await loadSession();
      if (state.answered.size >= state.trials.length) return finish();
      $("resume-done").textContent = state.answered.size;
      $("resume-total").textContent = state.trials.length;
      show("resume");
      return;
    } catch (e) {
      if (e.status === undefined) return fatal(`The test server cannot be reached (${e.message}).`);
      localStorage.removeItem(storageKey());
    }
  }
  show("consent");
}

async function loadSession() {
  const q = new URLSearchParams({ participant: state.participant, token: state.token });
  const s = await api("GET", `/api/session?${q}`);
  state.trials = s.trials;
  state.answered = new Set(s.answered);
}

$("agree").addEventListener("change", () => { $("start").disabled = !$("agree").checked; });
$("start").addEventListener("click", async () => {
  $("start").disabled = true;
  const wanted = new URLSearchParams(location.search).get("p");
  try {
    const r = await api("POST", "/api/participants", { id: wanted || null });
    state.participant = r.participant;
    state.token = r.token;
    localStorage.setItem(storageKey(), JSON.stringify({ participant: r.participant, token: r.token }));
    await loadSession();
    next();
  } catch (e) {
    $("consent-error").textContent = e.message;
    $("consent-error").hidden = false;
    $("start").disabled = !$("agree").checked;
  }
});
$("resume-go").addEventListener("click", () => {
  const first = state.trials.find((t) => !state.answered.has(t.index));
  event("reload", first ? first.index : null, "the page was opened again and resumed");
  state.lastBlock = null;
  next();
});

function event(kind, trial, detail) {
  // Fire-and-forget: the experimenter's log; never blocks the trial.
  api("POST", "/api/events", { participant: state.participant, token: state.token, kind, trial, detail: detail || "" })
    .catch(() => {});
}

function blockInfo(name) { return state.test.blocks.find((b) => b.name === name); }

function next() {
  const t = state.trials.find((tr) => !state.answered.has(tr.index));
  if (!t) return finish();
  state.pos = t.index;
  if (t.block !== state.lastBlock) {
    const b = blockInfo(t.block);
    $("intro-title").textContent = b.title;
    $("intro-text").textContent = b.instructions;
    state.lastBlock = t.block;
    show("intro");
    prefetch(t);
    return;
  }
  runTrial(t);
}
$("intro-go").addEventListener("click", () => runTrial(state.trials[state.pos]));

function finish() {
  $("done-id").textContent = state.participant;
  show("done");
}

function prefetch(t) {
  if (!t || state.prefetch.has(t.media)) return;
  const p = fetch(t.media).then((r) => {
    if (!r.ok) throw new Error(`stimulus ${t.media}: ${r.status}`);
    return r.blob();
  }).then((b) => URL.createObjectURL(b));
  p.catch(() => state.prefetch.delete(t.media));
  state.prefetch.set(t.media, p);
}

async function runTrial(t) {
  const video = $("media");
  state.phase = "loading";
  state.response = {};
  $("respond").hidden = true;
  $("trial-error").hidden = true;
  $("play").hidden = false;
  $("play").disabled = true;
  $("pause").disabled = false;
  $("progress").textContent = `Trial ${t.index + 1} of ${state.trials.length}`;
  $("block-name").textContent = blockInfo(t.block).title;
  $("audio-only").hidden = t.has_video;
  show("trial");
  prefetch(t);
  let url;
  try {
    url = await state.prefetch.get(t.media);
  } catch (e) {
    return fatal(`A stimulus could not be loaded (${e.message}). Please tell the experimenter.`);
  }
  const ready = new Promise((resolve) => {
    if (video.src === url && video.readyState >= 4) return resolve();
    video.addEventListener("canplaythrough", () => resolve(), { once: true });
  });
  if (video.src !== url) { video.src = url; video.load(); }
  await ready;
  // Prefetch the next trial while this one runs.
  prefetch(state.trials.find((tr) => tr.index > t.index && !state.answered.has(tr.index)));
  state.phase = "ready";
  $("play").disabled = false;
}

$("play").addEventListener("click", (ev) => {
  const t = state.trials[state.pos];
  const video = $("media");
  const tClick = ev.timeStamp;
  $("play").disabled = true;
  $("pause").disabled = true;
  state.phase = "playing";
  const m = { trial: t.index, kind: t.kind, has_video: t.has_video, click: tClick, playing: null, videoStart: null,
    offsets: [], frames: 0 };
  if (t.has_video && "requestVideoFrameCallback" in video) {
    const onFrame = (now, md) => {
      // A callback left pending when the previous stimulus ended fires on this one's first frame: ignore.
      if (m.done) return;
      m.frames += 1;
      if (m.videoStart === null) m.videoStart = md.expectedDisplayTime - md.mediaTime * 1000;
      // The first frames after play() race the clock's start; measure once playback is steady.
      if (m.frames > 3 && !video.paused) {
        const audioAt = video.currentTime + (md.expectedDisplayTime - now) / 1000;
        m.offsets.push((audioAt - md.mediaTime) * 1000);
      }
      if (!video.ended) video.requestVideoFrameCallback(onFrame);
    };
    video.requestVideoFrameCallback(onFrame);
  }
  video.addEventListener("playing", (e) => {
    m.playing = e.timeStamp;
    event("play", t.index);
  }, { once: true });
  video.addEventListener("ended", () => {
    m.done = true;
    const start = m.videoStart === null ? m.playing : Math.max(m.videoStart, m.playing);
    m.latency_ms = start - tClick;
    const sorted = [...m.offsets].sort((a, b) => a - b);
    m.av_offset_ms = sorted.length ? sorted[Math.floor(sorted.length / 2)] : null;
    m.av_offset_max_ms = sorted.length ? Math.max(...sorted.map(Math.abs)) : null;
    m.ended = performance.now();
    metrics.push(m);
    state.current = m;
    showResponse(t);
  }, { once: true });
  video.currentTime = 0;
  video.play().catch((e) => {
    $("trial-error").textContent = `Playback failed: ${e.message}`;
    $("trial-error").hidden = false;
  });
});

$("pause").addEventListener("click", () => {
  if (state.phase !== "ready" && state.phase !== "loading") return;
  event("pause", state.pos);
  show("paused");
});
$("unpause").addEventListener("click", () => {
  event("resume", state.pos);
  show("trial");
});

// -- response grids ------------------------------------------------------------------------------
function choiceButtons(container, values, key, labels) {
  for (const [i, v] of values.entries()) {
    const b = document.createElement("button");
    b.textContent = labels ? labels[i] : v;
    b.dataset.key = key;
    b.dataset.value = v;
    b.addEventListener("click", () => {
      for (const o of container.querySelectorAll("button")) o.classList.toggle("chosen", o === b);
      state.response[key] = typeof v === "number" ? v : String(v);
      updateSubmit();
    });
    container.appendChild(b);
  }
}

function buildResponseGrids() {
  const r = state.test.responses;
  choiceButtons($("letters"), r.letters, "letter");
  choiceButtons($("digits"), r.digits, "digit");
  choiceButtons($("syllables"), r.syllables, "syllable");
  choiceButtons($("emotions"), r.emotions, "emotion");
  const mos = $("grid-mos");
  for (const scale of r.mos_scales) {
    const row = document.createElement("div");
    row.className = "mos-row";
    row.id = `mos-${scale}`;
    const label = document.createElement("span");
    label.textContent = scale[0].toUpperCase() + scale.slice(1);
    row.appendChild(label);
    choiceButtons(row, [1, 2, 3, 4, 5], scale, r.mos_labels.map((l, i) => `${i + 1} ${l}`));
    mos.appendChild(row);
  }
}

const needed = { keywords: ["letter", "digit"], syllable: ["syllable"], emotion: ["emotion"],
  mos: ["accuracy", "naturalness"] };

function showResponse(t) {
  state.phase = "responding";
  state.respondStart = performance.now();
  for (const b of document.querySelectorAll(".choices button")) b.classList.remove("chosen");
  for (const k of ["keywords", "syllable", "emotion", "mos"]) $(`grid-${k}`).hidden = k !== t.kind;
  $("play").hidden = true;
  $("respond").hidden = false;
  updateSubmit();
}

function updateSubmit() {
  const t = state.trials[state.pos];
  $("submit").disabled = state.phase !== "responding" || !needed[t.kind].every((k) => k in state.response);
}

$("submit").addEventListener("click", async () => {
  const t = state.trials[state.pos];
  if (state.phase !== "responding") return;
  state.phase = "saving";
  $("submit").disabled = true;
  const m = state.current || {};
  const body = { participant: state.participant, token: state.token, trial: t.index, media: t.media,
    response: { ...state.response }, rt_ms: performance.now() - state.respondStart,
    latency_ms: m.latency_ms ?? null, av_offset_ms: m.av_offset_ms ?? null, plays: 1 };
  for (let attempt = 0; ; attempt++) {
    try {
      const r = await api("POST", "/api/answers", body);
      m.status = r.status;
      break;
    } catch (e) {
      if (e.status !== undefined && e.status < 500) {
        $("trial-error").textContent = `The answer was not accepted: ${e.message}`;
        $("trial-error").hidden = false;
        state.phase = "responding";
        return;
      }
      // Network trouble or a restarting server: the answer is kept here and sent again.
      $("trial-error").textContent = "Saving... (connection problem, retrying)";
      $("trial-error").hidden = false;
      await new Promise((res) => setTimeout(res, Math.min(5000, 500 * (attempt + 1))));
    }
  }
  $("trial-error").hidden = true;
  state.answered.add(t.index);
  next();
});

init();
