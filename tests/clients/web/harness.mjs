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

/** A page of the browser (launched on first use) showing `url`, as soon as it has loaded; `init` (optional): a
 *  function the page runs before its own scripts (page.addInitScript). */
export async function openPage(url, init = null) {
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
  if (init) await page.addInitScript(init);
  await page.goto(url);
  return page;
}

/** A page of the browser (launched on first use) showing `url`, once it has drawn 30 frames. */
export async function openViewer(url) {
  const page = await openPage(url);
  await page.waitForFunction(() => window.facecast && window.facecast.state.frames >= 30, null, { timeout: 30000 });
  return page;
}

/**
 * Let the mouth move for at least 4 s of frames so the page knows which vertices move (mouthBox) and
 * the range of its per-frame peaks, then freeze a frame near each end of that range and screenshot the same clip around
 * the mouth as `${prefix}closed.png` and `${prefix}open.png` in outDir. `describe(page)` (optional)
 * adds what the caller wants to know about the frozen frame. Returns {shots, range, clip}; each shot
 * has the frozen frame's peak and index (caughtIndex).
 *
 * Both the range and the freezing use the page's own record of the frames it applied
 * (facecast.applied, facecast.freezeWhen): polling the shown frame's peak from here missed short
 * openings on a loaded machine, where a poll takes longer than a frame is shown.
 */
export async function captureMouth(page, outDir, prefix = "", describe = async () => ({})) {
  const from = await page.evaluate(() => window.facecast.appliedCount());
  await page.waitForTimeout(3000);
  // At least 120 applied frames (4 s of speech: many syllables; a loaded machine applies fewer per
  // second and a short record can span too little of the mouth's range), at most 40 s.
  await page.waitForFunction((n) => window.facecast.appliedCount() >= n + 120, from, { timeout: 40000 });
  const peaks = (await page.evaluate((n) => window.facecast.applied(n), from)).map((r) => r.peak);
  const lo = Math.min(...peaks), hi = Math.max(...peaks);
  const box = await page.evaluate(() => window.facecast.mouthBox());
  const clip = { x: Math.max(0, box.x), y: Math.max(0, box.y), width: Math.max(8, box.width), height: Math.max(8, box.height) };
  const shots = {};
  const closedBelow = lo + 0.2 * (hi - lo), openAbove = hi - 0.2 * (hi - lo);
  for (const [name, bound] of [["closed", { below: closedBelow }], ["open", { above: openAbove }]]) {
    // The page freezes on the first frame it applies past the bound, then draws that frame.
    await page.evaluate((b) => window.facecast.freezeWhen(b), bound);
    try {
      await page.waitForFunction(() => window.facecast.caught() !== null, null, { timeout: 30000 });
    } catch (err) {
      throw new Error(`no ${name} frame within 30 s (peaks ${lo}..${hi}, bound ${JSON.stringify(bound)})`);
    }
    const got = await page.evaluate(() => window.facecast.caught());
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    const more = await describe(page);
    await page.screenshot({ path: join(outDir, `${prefix}${name}.png`), clip });
    shots[name] = { peak: got.peak, caughtIndex: got.index, ...more };
    await page.evaluate(() => window.facecast.freeze(false));
  }
  return { shots, range: [lo, hi], clip };
}

/** Run the check: exit 0 when it ends, or print {"step":"error"} and exit 1; the browser closed either way. */
export function run(main) {
  const close = async () => {
    if (context) await context.close().catch(() => {});
    rmSync(profile, { recursive: true, force: true, maxRetries: 5 });
  };
  // The tests end a check with SIGTERM once they have read the step they wait for: close the browser
  // and remove its profile then too, else every run leaves a 2 MB profile in the temp folder.
  process.on("SIGTERM", () => { close().finally(() => process.exit(143)); });
  main()
    .then(async () => { await close(); process.exit(0); })
    .catch(async (err) => {
      say({ step: "error", error: String(err && err.stack || err), console_errors: errors });
      await close();
      process.exit(1);
    });
}
