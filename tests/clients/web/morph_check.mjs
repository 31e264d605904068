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
//   {"step":"mouth", ...}    closed/open frames captured (their peaks, weights, the normals drawn there:
//                            HeadView.morphNormals; the clip box), draw time
//   {"step":"deltas", ...}   the same session watched as vertex deltas (?kind=deltas): its draw time
//   {"step":"done", "console_errors": [...]}
// Exits 1 with {"step":"error", ...} when something does not happen within its time limit.

import { join } from "node:path";
import { captureMouth, errors, openViewer, run, say } from "./harness.mjs";

const [url, session, outDir] = process.argv.slice(2);

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
  const page = await openViewer(`${url}/?session=${encodeURIComponent(session)}`);

  // Shown frames: the streamed weights and the influences, read in one evaluation (one frame).
  const samples = [];
  let names = null;
  // Until 40 distinct frames are seen (a loaded machine shows fewer per poll), at most 60 s.
  const until = Date.now() + 60000;
  for (let i = 0; (i < 80 || samples.length < 40) && Date.now() < until; i++) {
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
  const { shots, range, clip } = await captureMouth(page, outDir, "morph_", async (p) => {
    const m = await p.evaluate(() => window.facecast.morph());
    return { index: m.index, weights: m.weights, normals: await p.evaluate(() => window.facecast.morphNormals()) };
  });
  await page.screenshot({ path: join(outDir, "morph_viewer.png") });
  const morphDraw = await drawTimes(page, 3);
  st = await page.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "mouth", shots, range, clip, ...morphDraw, state: st });
  await page.close();

  // The same session as vertex deltas: what the page did before (for the draw-time comparison).
  const page2 = await openViewer(`${url}/?session=${encodeURIComponent(session)}&kind=deltas`);
  const deltasDraw = await drawTimes(page2, 3);
  st = await page2.evaluate(() => ({ ...window.facecast.state }));
  say({ step: "deltas", ...deltasDraw, state: st });
  say({ step: "done", console_errors: errors });
}

run(main);
