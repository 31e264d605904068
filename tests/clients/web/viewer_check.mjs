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

import { chromium } from "playwright-core";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { createInterface } from "node:readline";

const [url, session, outDir] = process.argv.slice(2);
const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const profile = mkdtempSync(join(tmpdir(), "facecast-chromium-"));
const errors = [];
let context;
// Lines from the test on stdin, one reader for the whole run.
const lines = [];
const waiters = [];
createInterface({ input: process.stdin }).on("line", (l) => (waiters.length ? waiters.shift()(l) : lines.push(l)));
const nextLine = () => new Promise((resolve) => (lines.length ? resolve(lines.shift()) : waiters.push(resolve)));

async function main() {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    viewport: { width: 900, height: 600 },
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
      "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
      "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--autoplay-policy=no-user-gesture-required"],
  });
  const page = context.pages()[0] ?? (await context.newPage());
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${url}/?session=${encodeURIComponent(session)}`);

  await page.waitForFunction(() => window.facecast && window.facecast.state.frames >= 30, null, { timeout: 30000 });
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

  // Let the mouth move for a while so the page knows which vertices move (mouthBox), then learn
  // the range of per-frame peaks and capture a frame near each end of it.
  const peaks = [];
  const t0 = Date.now();
  while (Date.now() - t0 < 2000) {
    peaks.push(await page.evaluate(() => window.facecast.state.lastPeak));
    await page.waitForTimeout(30);
  }
  const lo = Math.min(...peaks), hi = Math.max(...peaks);
  const box = await page.evaluate(() => window.facecast.mouthBox());
  const clip = { x: Math.max(0, box.x), y: Math.max(0, box.y), width: Math.max(8, box.width), height: Math.max(8, box.height) };
  const shots = {};
  const closedBelow = lo + 0.2 * (hi - lo), openAbove = hi - 0.2 * (hi - lo);
  for (const [name, test] of [["closed", `p <= ${closedBelow}`], ["open", `p >= ${openAbove}`]]) {
    const deadline = Date.now() + 15000;
    let got = null;
    while (got === null && Date.now() < deadline) {
      // Read the shown frame's peak and freeze in one evaluation, so the screenshot is that frame.
      got = await page.evaluate(`(() => { const p = window.facecast.state.lastPeak;
        if (${test}) { window.facecast.freeze(true); return p; } return null; })()`);
      if (got === null) await page.waitForTimeout(15);
    }
    if (got === null) throw new Error(`no ${name} frame within 15 s (peaks ${lo}..${hi})`);
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    await page.screenshot({ path: join(outDir, `${name}.png`), clip });
    shots[name] = got;
    await page.evaluate(() => window.facecast.freeze(false));
  }
  await page.screenshot({ path: join(outDir, "viewer.png") });
  st = await page.evaluate(() => ({ ...window.facecast.state, audio: window.facecast.audio() }));
  say({ step: "mouth", peaks: shots, range: [lo, hi], clip, state: st });

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

main()
  .then(async () => { await context.close(); rmSync(profile, { recursive: true, force: true }); process.exit(0); })
  .catch(async (err) => {
    say({ step: "error", error: String(err && err.stack || err), console_errors: errors });
    if (context) await context.close().catch(() => {});
    rmSync(profile, { recursive: true, force: true });
    process.exit(1);
  });
