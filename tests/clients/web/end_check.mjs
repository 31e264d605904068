// The end of a session in the browser viewer (Debian's Chromium, headless, SwiftShader WebGL):
//
//   node end_check.mjs URL SESSION
//
// Opens the page on SESSION while it streams, waits until the server closes the viewer's socket
// (the session ended), lets the page run for 2 s more, then prints
//   {"step":"ended", "closeCode": ..., "applied": [{n, index, peak}, ...] (the frames applied last),
//    "kind", "lastPeak", "influences", "restSteps", "status" (the page then)}
// or {"step":"error", ...} (exit 1) when the session never shows or never ends within the time limits.

import { errors, openViewer, run, say } from "./harness.mjs";

const [url, session] = process.argv.slice(2);

async function main() {
  const page = await openViewer(`${url}/?session=${encodeURIComponent(session)}`);
  await page.waitForFunction(() => window.facecast.state.closeCode !== null, null, { timeout: 60000 });
  await page.waitForTimeout(2000);
  const got = await page.evaluate(() => ({
    closeCode: window.facecast.state.closeCode,
    applied: window.facecast.applied(Math.max(0, window.facecast.appliedCount() - 40)),
    // what is on screen 2 s after the close: the face at rest (or the last frame held)
    kind: window.facecast.state.kind,
    lastPeak: window.facecast.state.lastPeak,
    influences: window.facecast.morph().influences,
    restSteps: window.facecast.state.restSteps,
    status: window.facecast.state.status,
  }));
  say({ step: "ended", ...got, console_errors: errors });
}

run(main);
