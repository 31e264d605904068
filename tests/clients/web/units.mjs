// Unit checks of the viewer's pure modules under Node (no browser): node units.mjs DIR
// DIR holds messages encoded by server/protocol.py (NAME.bin); prints one JSON object with the
// decoded values per message and the playout clock's behaviour in scripted arrival patterns.
import { readFileSync, readdirSync } from "node:fs";
import { join } from "node:path";
import { decodeMessage, KIND, ENC } from "../../../wire/protocol.js";
import { PlayoutClock } from "../../../clients/web/js/playout.js";

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
console.log(JSON.stringify({ decoded, rejected, kinds: KIND, encodings: ENC, beforeLate, afterLate, afterRecovery: clock.offset,
  resyncs: clock.resyncs, catchups: clock.catchups, slack }));
