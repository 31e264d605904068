// Unit checks of the viewer's pure modules under Node (no browser): node units.mjs DIR
// DIR holds messages encoded by server/protocol.py (NAME.bin); prints one JSON object with the
// decoded values per message and the playout clock's behaviour in scripted arrival patterns.
import { readFileSync, readdirSync } from "node:fs";
import { join } from "node:path";
import { decodeMessage, KIND, ENC } from "../../../wire/protocol.js";
import { DisplayRate, PlayoutClock, takeDue } from "../../../clients/web/js/playout.js";
import { pageOptions } from "../../../clients/web/js/options.js";

const dir = process.argv[2];
const decoded = {};
for (const f of readdirSync(dir).filter((n) => n.endsWith(".bin"))) {
  const b = readFileSync(join(dir, f));
  const m = decodeMessage(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));
  decoded[f.slice(0, -4)] = { ...m, values: Array.from(m.values) };
}
let rejected = null;
try {
  decodeMessage(new ArrayBuffer(10));
} catch (err) {
  rejected = String(err.message);
}

// Frames every 1/30 s arriving 0.2 s after their media time (steady), one arriving 0.15 s late,
// then 4 s of frames arriving 0.3 s earlier than before (the network recovered).
const clock = new PlayoutClock({ bufferS: 0.08 });
const slack = [];
let k = 0;
for (; k < 60; k++) slack.push(clock.arrive(k / 30, k / 30 + 0.2) - (k / 30 + 0.2));
const beforeLate = clock.offset;
slack.push(clock.arrive(k / 30, k / 30 + 0.2 + 0.15 + 0.08) - (k / 30 + 0.2 + 0.15 + 0.08));
k++;
const afterLate = clock.offset;
for (; k < 61 + 120; k++) slack.push(clock.arrive(k / 30, k / 30 + 0.2) - (k / 30 + 0.2));
const recovery = { baseOffset: clock.baseOffset, afterRecovery: clock.offset, resyncs: clock.resyncs, catchups: clock.catchups };

// A text session's arrivals (docs/protocol.md, section 9): its first 0.5 s of frames at once, then each
// frame 0.5 s before its media time (the server's lead), 12 s in all, played out by a page whose display
// refreshes at 60/s for 4 s, then irregularly every 40-100 ms (a display slower than the frames) for 4 s,
// then at 60/s again. Every frame's arrival, due time and fate (shown or skipped, at which refresh).
function textPlayout() {
  const c = new PlayoutClock({ bufferS: 0.08 });
  const fps = 30, n = 12 * fps, lead = 0.5;
  const arrivals = Array.from({ length: n }, (_, k) => Math.max(0, k / fps - lead));
  const frames = [];
  const queue = [];
  const shown = [];
  let next = 0;
  let rng = 7;
  const jitter = () => ((rng = (rng * 16807) % 2147483647) / 2147483647);
  for (let t = 0; t < n / fps + 1;) {
    for (; next < n && arrivals[next] <= t; next++) {
      const due = c.arrive(next / fps, arrivals[next]);
      frames.push({ index: next, arrival: arrivals[next], due, tick: null, fate: null });
      queue.push({ index: next, due });
    }
    const { show, skipped } = takeDue(queue, t);
    for (const q of skipped) Object.assign(frames[q.index], { tick: t, fate: "skipped" });
    if (show) {
      Object.assign(frames[show.index], { tick: t, fate: "shown" });
      shown.push(show.index);
    }
    t += t >= 4 && t < 8 ? 0.04 + 0.06 * jitter() : 1 / 60;
  }
  return { frames, shown, catchups: c.catchups, resyncs: c.resyncs, offset: c.offset, baseOffset: c.baseOffset };
}

const rate = new DisplayRate();
const rates = [];
for (let i = 0; i <= 120; i++) {
  rate.tick(i < 60 ? i / 60 : 1 + (i - 60) * 0.05); // 1 s at 60/s, then 3 s at 20/s
  rates.push(rate.hz);
}

// The page's look from its query (clients/web/js/options.js): one result per query string.
const queries = ["", "embed=1", "embed", "embed=0", "embed=maybe", "background=transparent", "background=%23ff8000",
  "background=ff8000", "background=F80", "background=red", "background=12345", "embed=1&background=none"];
const page = Object.fromEntries(queries.map((q) => [q, pageOptions(new URLSearchParams(q))]));

console.log(JSON.stringify({ decoded, rejected, kinds: KIND, encodings: ENC, beforeLate, afterLate, ...recovery, slack,
  text: textPlayout(), rates, page }));
