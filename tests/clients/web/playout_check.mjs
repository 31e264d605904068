// A whole session played out in the browser viewer (Debian's Chromium, headless, SwiftShader WebGL):
//
//   node playout_check.mjs URL SESSION
//
// Opens the page on SESSION before it exists; once the page waits for it, prints {"step":"polled"} (the
// test then starts SESSION). When the session has ended and every frame received was shown or skipped,
// prints {"step":"played", state, audio, applied, display}: the page's counters, its audio player's, the
// record of every frame it applied, and its display rate beside one counted here (requestAnimationFrame
// callbacks of the same last second, wrapped before the page's scripts run). {"step":"error"} (exit 1) on
// a timeout.

import { errors, openPage, run, say } from "./harness.mjs";

const [url, session] = process.argv.slice(2);

function countRefreshes() {
  window.refreshTimes = [];
  const raf = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (cb) => raf((t) => {
    window.refreshTimes.push(performance.now() / 1000);
    cb(t);
  });
}

async function main() {
  const page = await openPage(`${url}/?session=${encodeURIComponent(session)}`, countRefreshes);
  await page.waitForFunction(() => window.facecast && /waiting for session/.test(window.facecast.state.status),
    null, { timeout: 30000 });
  await page.waitForResponse((r) => new URL(r.url()).pathname === "/sessions", { timeout: 30000 });
  say({ step: "polled" });
  await page.waitForFunction(() => window.facecast.state.received > 0, null, { timeout: 30000 });
  // Mid-session: the page's display rate and the refreshes counted here over the same last second.
  await page.waitForTimeout(2000);
  const display = await page.evaluate(() => {
    const t = window.refreshTimes, last = t[t.length - 1];
    const recent = t.filter((x) => x >= last - 1);
    return { page: window.facecast.state.displayHz, counted: (recent.length - 1) / (last - recent[0]) };
  });
  await page.waitForFunction(() => {
    const s = window.facecast.state;
    return s.ended !== null && s.frames + s.skipped === s.received;
  }, null, { timeout: 60000 });
  say({ step: "played", ...(await page.evaluate(() => ({ state: { ...window.facecast.state },
    audio: window.facecast.audio(), applied: window.facecast.applied(0) }))), display, console_errors: errors });
}

run(main);
