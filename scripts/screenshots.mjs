// Screenshot of the browser viewer for the README: node scripts/screenshots.mjs URL SESSION OUT.png
// Waits until the page shows frames of SESSION, then holds a frame with the mouth well open.
import { chromium } from "playwright-core";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const [url, session, out] = process.argv.slice(2);
const profile = mkdtempSync(join(tmpdir(), "facecast-chromium-"));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  viewport: { width: 960, height: 600 },
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--disable-quic", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--autoplay-policy=no-user-gesture-required"],
});
try {
  const page = context.pages()[0] ?? (await context.newPage());
  await page.goto(`${url}/?session=${encodeURIComponent(session)}`);
  await page.waitForFunction(() => window.facecast && window.facecast.state.frames >= 60, null, { timeout: 60000 });
  let hi = 0;
  for (let i = 0; i < 60; i++) {
    hi = Math.max(hi, await page.evaluate(() => window.facecast.state.lastPeak));
    await page.waitForTimeout(30);
  }
  // A moderately open mouth (a vowel), not the extreme of the take.
  await page.waitForFunction((h) => window.facecast.state.lastPeak >= 0.55 * h && window.facecast.state.lastPeak <= 0.8 * h &&
    window.facecast.freeze(true) >= 0,
    hi, { timeout: 30000, polling: 10 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  await page.screenshot({ path: out });
} finally {
  await context.close();
  rmSync(profile, { recursive: true, force: true });
}
