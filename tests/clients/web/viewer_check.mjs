// Drives the browser viewer in Debian's Chromium (headless, SwiftShader WebGL) with playwright-core.
//
//   node viewer_check.mjs URL SESSION OUTDIR
//
// Prints one JSON object per line on stdout; the Python test reads them and does the pixel checks
// on the PNGs written to OUTDIR (closed.png, open.png: the same mouth-region clip with the mouth
// closed and open; viewer.png: the whole page). Steps:
//   {"step":"frames", ...}    the page shows frames of SESSION (state, the session list, audio)
//   {"step":"picker", ...}    the expression picker's buttons; "smile" then "neutral" acknowledged
//   {"step":"mouth", ...}     closed/open frames captured (their peak vertex deltas, the clip box)
//   {"step":"waiting"}        then it waits for a line on stdin (the test restarts the session)
//   {"step":"reconnected",..} the page reconnected on its own and shows frames again
//   {"step":"waiting"}        again: the test restarts the whole server (same port) and the session
//   {"step":"restarted",..}   the page found the new server and shows frames again
//   {"step":"done", "console_errors": [...], "outage_errors": [...]}: errors outside the server's
//                             outage, and the connection-refused reports during it
// Exits 1 with {"step":"error", ...} when something does not happen within its time limit.

import { join } from "node:path";
import { createInterface } from "node:readline";
import { captureMouth, errors, openViewer, run, say } from "./harness.mjs";

const [url, session, outDir] = process.argv.slice(2);
// Lines from the test on stdin, one reader for the whole run.
const lines = [];
const waiters = [];
createInterface({ input: process.stdin }).on("line", (l) => (waiters.length ? waiters.shift()(l) : lines.push(l)));
const nextLine = () => new Promise((resolve) => (lines.length ? resolve(lines.shift()) : waiters.push(resolve)));

async function main() {
  const page = await openViewer(`${url}/?session=${encodeURIComponent(session)}`);
  const listed = await page.locator("#sessions").textContent();
  let st = await page.evaluate(() => ({ ...window.facecast.state, audio: window.facecast.audio() }));
  say({ step: "frames", listed, state: st });

  // The expression picker: its buttons come from the description; a click is acknowledged by the
  // server. Back to neutral afterwards so the mouth checks below see speech only.
  await page.waitForSelector("#expressions button", { timeout: 10000 });
  const buttons = await page.locator("#expressions button").allTextContents();
  await page.locator("#expressions button", { hasText: "smile" }).click();
  await page.waitForFunction(() => /smile: applied/.test(document.getElementById("expression-status").textContent),
    null, { timeout: 10000 });
  const smiled = await page.locator("#expression-status").textContent();
  await page.locator("#expressions button", { hasText: "neutral" }).click();
  await page.waitForFunction(() => /neutral: applied/.test(document.getElementById("expression-status").textContent),
    null, { timeout: 10000 });
  say({ step: "picker", buttons, smiled });

  // Then a frame near each end of the mouth's range, the same clip around the mouth.
  // On the frozen open frame: how far the normals drawn are from that shape's own.
  const { shots, range, clip } = await captureMouth(page, outDir, "", async (p) => ({
    normalsLag: await p.evaluate(() => window.facecast.normalsLag()),
  }));
  await page.screenshot({ path: join(outDir, "viewer.png") });
  st = await page.evaluate(() => ({ ...window.facecast.state, audio: window.facecast.audio() }));
  say({ step: "mouth", peaks: { closed: shots.closed.peak, open: shots.open.peak }, range, clip, state: st,
    normalsLag: shots.open.normalsLag });
  // Reconnection: the test ends the session and starts it again; the page must follow by itself.
  const before = st.connections;
  say({ step: "waiting" });
  await nextLine();
  await page.waitForFunction((n) => window.facecast.state.connections > n && window.facecast.state.received >= 15,
    before, { timeout: 30000 });
  st = await page.evaluate(() => ({ ...window.facecast.state, audio: window.facecast.audio() }));
  say({ step: "reconnected", state: st });

  // Server restart: while it is down the browser itself reports refused connections (the page's
  // polls); those are expected and kept apart from real errors.
  say({ step: "waiting" });
  const outageFrom = errors.length;
  await nextLine();
  await page.waitForFunction((n) => window.facecast.state.connections > n && window.facecast.state.received >= 15,
    st.connections, { timeout: 30000 });
  const outage = errors.splice(outageFrom);
  st = await page.evaluate(() => ({ ...window.facecast.state, audio: window.facecast.audio() }));
  say({ step: "restarted", state: st });
  say({ step: "done", console_errors: errors, outage_errors: outage });
}

run(main);
