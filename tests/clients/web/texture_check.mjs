// Shows a textured head in the browser viewer, in Debian's Chromium (headless, SwiftShader WebGL) with
// playwright-core, and writes the page's picture for the Python test's pixel checks.
//
//   node texture_check.mjs URL SESSION OUTDIR
//
// Prints one JSON object per line on stdout:
//   {"step":"shown", "state": {...}}   the page drew 30 frames of the session; OUTDIR/texture_viewer.png written
//   {"step":"done", "console_errors": [...]}
// Exits 1 with {"step":"error", ...} when something does not happen within its time limit.

import { join } from "node:path";
import { errors, openViewer, run, say } from "./harness.mjs";

const [url, session, outDir] = process.argv.slice(2);

async function main() {
  const page = await openViewer(`${url}/?session=${encodeURIComponent(session)}`);
  await page.screenshot({ path: join(outDir, "texture_viewer.png") });
  say({ step: "shown", state: await page.evaluate(() => ({ ...window.facecast.state })) });
  say({ step: "done", console_errors: errors });
}

run(main);
