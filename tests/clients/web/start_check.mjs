// The start of a session in the browser viewer (Debian's Chromium, headless, SwiftShader WebGL):
//
//   node start_check.mjs URL SESSION
//
// Opens the page on SESSION before it exists; once the page shows that it waits for it, prints
// {"step":"polled"} right after the page's next /sessions poll was answered (the test then starts
// SESSION at once), then, when the page has received 10 frames, {"step":"joined", "state": ...}
// (state.firstIndex: the first frame the page received). {"step":"error", ...} (exit 1) on a timeout.

import { errors, openPage, run, say } from "./harness.mjs";

const [url, session] = process.argv.slice(2);

async function main() {
  const page = await openPage(`${url}/?session=${encodeURIComponent(session)}`);
  await page.waitForFunction(() => window.facecast && /waiting for session/.test(window.facecast.state.status),
    null, { timeout: 30000 });
  await page.waitForResponse((r) => new URL(r.url()).pathname === "/sessions", { timeout: 30000 });
  say({ step: "polled" });
  await page.waitForFunction(() => window.facecast.state.received >= 10, null, { timeout: 30000 });
  const state = await page.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "joined", state, console_errors: errors });
}

run(main);
