// What the browser checks share: Debian's Chromium (headless, SwiftShader WebGL) driven with
// playwright-core, one JSON object per line on stdout, and the closed/open mouth screenshots.
// Each check script imports these and keeps only its own steps.

import { chromium } from "playwright-core";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

export const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");

/** Console and page errors of every page opened through `watch`, in the order they came. */
export const errors = [];

const profile = mkdtempSync(join(tmpdir(), "facecast-chromium-"));
let context;

/** Record a page's console errors and uncaught exceptions in `errors`. */
export function watch(page) {
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  return page;
}

/** A page of the browser (launched on first use) showing `url`, once it has drawn 30 frames. */
export async function openViewer(url) {
  if (!context) {
    context = await chromium.launchPersistentContext(profile, {
      executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
      headless: true,
      viewport: { width: 900, height: 600 },
      args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
        "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--autoplay-policy=no-user-gesture-required"],
    });
  }
  const fresh = context.pages().find((p) => p.url() === "about:blank");
  const page = watch(fresh ?? (await context.newPage()));
  await page.goto(url);
  await page.waitForFunction(() => window.facecast && window.facecast.state.frames >= 30, null, { timeout: 30000 });
  return page;
}

/**
 * Let the mouth move for 2 s so the page knows which vertices move (mouthBox) and the range of its
 * per-frame peaks, then freeze a frame near each end of that range and screenshot the same clip around
 * the mouth as `${prefix}closed.png` and `${prefix}open.png` in outDir. `describe(page)` (optional)
 * adds what the caller wants to know about the frozen frame. Returns {shots, range, clip}.
 */
export async function captureMouth(page, outDir, prefix = "", describe = async () => ({})) {
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
    const more = await describe(page);
    await page.screenshot({ path: join(outDir, `${prefix}${name}.png`), clip });
    shots[name] = { peak: got, ...more };
    await page.evaluate(() => window.facecast.freeze(false));
  }
  return { shots, range: [lo, hi], clip };
}

/** Run the check: exit 0 when it ends, or print {"step":"error"} and exit 1; the browser closed either way. */
export function run(main) {
  const close = async () => {
    if (context) await context.close().catch(() => {});
    rmSync(profile, { recursive: true, force: true });
  };
  main()
    .then(async () => { await close(); process.exit(0); })
    .catch(async (err) => {
      say({ step: "error", error: String(err && err.stack || err), console_errors: errors });
      await close();
      process.exit(1);
    });
}
