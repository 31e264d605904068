// Drives the browser viewer on a head driven by its own morph targets, in Debian's Chromium
// (headless, SwiftShader WebGL) with playwright-core.
//
//   node morph_check.mjs URL SESSION OUTDIR
//
// Prints one JSON object per line on stdout; the Python test compares the influences with weights it
// computes itself and does the pixel checks on the PNGs written to OUTDIR (morph_closed.png,
// morph_open.png: the same mouth-region clip with the mouth closed and open; morph_viewer.png: the page).
//   {"step":"samples", ...}  the page's kind and target names, and ~80 shown frames
//                            {index, weights (streamed), influences (what three.js draws with)}
//   {"step":"mouth", ...}    closed/open frames captured (their peaks, the clip box), draw time
//   {"step":"deltas", ...}   the same session watched as vertex deltas (?kind=deltas): its draw time
//   {"step":"done", "console_errors": [...]}
// Exits 1 with {"step":"error", ...} when something does not happen within its time limit.

import { chromium } from "playwright-core";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const [url, session, outDir] = process.argv.slice(2);
const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const profile = mkdtempSync(join(tmpdir(), "facecast-chromium-"));
const errors = [];
let context;

async function drawTimes(page, seconds) {
  // The page's per-frame draw time (median of its last 30 frames), sampled once a second.
  const out = [];
  const t0 = await page.evaluate(() => [performance.now(), window.facecast.state.ticks]);
  for (let i = 0; i < seconds; i++) {
    await page.waitForTimeout(1000);
    out.push(await page.evaluate(() => window.facecast.state.drawMs));
  }
  const t1 = await page.evaluate(() => [performance.now(), window.facecast.state.ticks]);
  return { drawMs: out, ticksPerS: (1000 * (t1[1] - t0[1])) / (t1[0] - t0[0]) };
}

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

  // Shown frames: the streamed weights and the influences, read in one evaluation (one frame).
  const samples = [];
  let names = null;
  for (let i = 0; i < 80; i++) {
    const m = await page.evaluate(() => window.facecast.morph());
    names = m.names;
    if (m.index !== null && (!samples.length || samples[samples.length - 1].index !== m.index)) {
      samples.push({ index: m.index, weights: m.weights, influences: m.influences });
    }
    await page.waitForTimeout(40);
  }
  let st = await page.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "samples", kind: st.kind, names, samples, state: st });

  // Closed and open frames (by the page's peak estimate), the same clip around the mouth.
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
      got = await page.evaluate(`(() => { const p = window.facecast.state.lastPeak;
        if (${test}) { window.facecast.freeze(true); return p; } return null; })()`);
      if (got === null) await page.waitForTimeout(15);
    }
    if (got === null) throw new Error(`no ${name} frame within 15 s (peaks ${lo}..${hi})`);
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    const m = await page.evaluate(() => window.facecast.morph());
    await page.screenshot({ path: join(outDir, `morph_${name}.png`), clip });
    shots[name] = { peak: got, index: m.index, weights: m.weights };
    await page.evaluate(() => window.facecast.freeze(false));
  }
  await page.screenshot({ path: join(outDir, "morph_viewer.png") });
  const morphDraw = await drawTimes(page, 3);
  st = await page.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "mouth", shots, range: [lo, hi], clip, ...morphDraw, state: st });
  await page.close();

  // The same session as vertex deltas: what the page did before (for the draw-time comparison).
  const page2 = await context.newPage();
  page2.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page2.on("pageerror", (e) => errors.push(String(e)));
  await page2.goto(`${url}/?session=${encodeURIComponent(session)}&kind=deltas`);
  await page2.waitForFunction(() => window.facecast && window.facecast.state.frames >= 30, null, { timeout: 30000 });
  const deltasDraw = await drawTimes(page2, 3);
  st = await page2.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "deltas", ...deltasDraw, state: st });
  say({ step: "done", console_errors: errors });
}

main()
  .then(async () => { await context.close(); rmSync(profile, { recursive: true, force: true }); process.exit(0); })
  .catch(async (err) => {
    say({ step: "error", error: String(err && err.stack || err), console_errors: errors });
    if (context) await context.close().catch(() => {});
    rmSync(profile, { recursive: true, force: true });
    process.exit(1);
  });
