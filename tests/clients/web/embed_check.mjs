// The viewer as an embedded avatar (clients/web/js/options.js), in Debian's Chromium (headless, SwiftShader
// WebGL) with playwright-core: the page's pictures for the Python test's pixel checks.
//
//   node embed_check.mjs URL SESSION OUTDIR
//
// Prints one JSON object per line on stdout:
//   {"step":"resting", morph, rest}     ?embed=1&background=transparent opened before SESSION exists shows the
//                                       server's head at rest (/head/description.json); OUTDIR/embed_rest.png
//   {"step":"embedded", layout, state}  the same page drew 30 frames of SESSION (the test starts it after "resting");
//                                       OUTDIR/embed_transparent.png written with the page's alpha
//   {"step":"coloured", layout, state}  ?background=%23ff8000 (panel kept) drew 30 frames; OUTDIR/embed_coloured.png
//   {"step":"done", "console_errors": [...], "console_warnings": [...]}  after ?background=red (a warning, default kept)
// Exits 1 with {"step":"error", ...} when something does not happen within its time limit.

import { join } from "node:path";
import { errors, openPage, openViewer, run, say } from "./harness.mjs";

const [url, session, outDir] = process.argv.slice(2);
const base = `${url}/?session=${encodeURIComponent(session)}`;

function layout() {
  const rect = (el) => {
    const r = el.getBoundingClientRect();
    return { x: r.x, y: r.y, width: r.width, height: r.height, display: getComputedStyle(el).display };
  };
  return { viewport: { width: innerWidth, height: innerHeight }, canvas: rect(document.getElementById("view")),
    aside: rect(document.querySelector("aside")), bodyBackground: getComputedStyle(document.body).backgroundColor };
}

async function main() {
  let page = await openPage(`${base}&embed=1&background=transparent`);
  // Before SESSION exists the page shows the server's head at rest (fetched once the page knows it waits).
  await page.waitForFunction(() => window.facecast && /waiting for session/.test(window.facecast.state.status)
    && window.facecast.morph().names !== null, null, { timeout: 30000 });
  await page.waitForTimeout(500); // a refresh or two to draw it
  await page.screenshot({ path: join(outDir, "embed_rest.png"), omitBackground: true });
  say({ step: "resting", morph: await page.evaluate(() => window.facecast.morph()),
    rest: await page.evaluate(async () => (await (await fetch("/head/description.json")).json()).rest_values) });
  await page.waitForFunction(() => window.facecast.state.frames >= 30, null, { timeout: 30000 });
  await page.screenshot({ path: join(outDir, "embed_transparent.png"), omitBackground: true });
  say({ step: "embedded", layout: await page.evaluate(layout), state: await page.evaluate(() => ({ ...window.facecast.state })) });
  page = await openViewer(`${base}&background=%23ff8000`);
  await page.screenshot({ path: join(outDir, "embed_coloured.png") });
  say({ step: "coloured", layout: await page.evaluate(layout), state: await page.evaluate(() => ({ ...window.facecast.state })) });
  const warnings = [];
  page = await page.context().newPage();
  page.on("console", (m) => { if (m.type() === "warning") warnings.push(m.text()); });
  await page.goto(`${base}&background=red`);
  await page.waitForFunction(() => window.facecast && window.facecast.state.frames >= 1, null, { timeout: 30000 });
  say({ step: "done", console_errors: errors, console_warnings: warnings });
}

run(main);
