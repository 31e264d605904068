// Completes a whole perceptual test session in Debian's Chromium (headless) as a simulated participant.
//
//   node session_check.mjs OPTIONS.json
//
// OPTIONS: {url, truth: {media: {kind, condition, truth}}, participant?, reloadAt?, pauseAt?, doubleAt?}
// The answer policy (mirrored by policy() in test_browser.py) depends only on the stimulus' kind,
// condition and correct answer. Clicks are real input events (page.click). Mid-session it closes the
// tab during trial `reloadAt` (after Play, before answering) and opens the page again (it must resume at
// that trial), pauses and resumes before trial `pauseAt`, and re-sends trial `doubleAt`'s answer (the
// server must answer "duplicate"). Prints one JSON line per step; the last is
// {"step": "done", metrics: [...], console_errors: [...], duplicate: "..."}.
import { chromium } from "playwright-core";
import { mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const opts = JSON.parse(readFileSync(process.argv[2], "utf8"));
const say = (o) => process.stdout.write(JSON.stringify(o) + "\n");
const LETTERS = "abcdefghijklmnopqrstuvxyz".split("");
const CONSONANTS = ["p", "b", "m", "f", "t", "d", "s", "sh", "k"];

function policy(info) {
  const t = info.truth;
  if (info.kind === "keywords") {
    const wrongLetter = LETTERS[(LETTERS.indexOf(t.letter) + 1) % LETTERS.length];
    const wrongDigit = String((Number(t.digit) + 1) % 10);
    if (info.condition === "N") return { letter: t.letter, digit: t.digit };
    if (info.condition.startsWith("S")) return { letter: t.letter, digit: wrongDigit };
    return { letter: wrongLetter, digit: Number(t.digit) % 2 === 0 ? t.digit : wrongDigit };
  }
  if (info.kind === "syllable") {
    if (info.condition.startsWith("S")) return { syllable: t.syllable };
    const vowel = t.syllable.slice(-1);
    if (vowel === "a") return { syllable: t.syllable };
    const cons = t.syllable.slice(0, -1);
    return { syllable: CONSONANTS[(CONSONANTS.indexOf(cons) + 1) % CONSONANTS.length] + vowel };
  }
  if (info.kind === "emotion") return { emotion: { neutral: "neutral", smile: "happy", sad: "not sure" }[info.condition] };
  if (info.condition === "N") return { accuracy: 5, naturalness: 4 };
  if (info.condition === "S") return { accuracy: 3, naturalness: 2 };
  return { accuracy: 3, naturalness: 3 };
}

const errors = [];
const metrics = [];
let duplicate = null;
let context;

async function openPage() {
  const page = await context.newPage();
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  const q = opts.participant ? `?p=${encodeURIComponent(opts.participant)}` : "";
  await page.goto(`${opts.url}/${q}`);
  await page.waitForFunction(() => window.perceptual && window.perceptual.state.screen !== "loading");
  return page;
}

const screen = (page) => page.evaluate(() => window.perceptual.state.screen);

const profile = mkdtempSync(join(tmpdir(), "facecast-perceptual-"));

async function main() {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    viewport: { width: 1000, height: 900 },
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
      "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
      "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--autoplay-policy=no-user-gesture-required"],
  });
  let page = await openPage();
  if ((await screen(page)) !== "consent") throw new Error(`expected the consent screen, got ${await screen(page)}`);
  await page.click("#agree");
  await page.click("#start");
  await page.waitForFunction(() => ["intro", "trial", "fatal"].includes(window.perceptual.state.screen));
  const participant = await page.evaluate(() => window.perceptual.state.participant);
  say({ step: "consented", participant });
  let reloaded = false;
  let paused = false;
  for (;;) {
    await page.waitForFunction(() => {
      const s = window.perceptual.state;
      return ["intro", "done", "fatal"].includes(s.screen) || (s.screen === "trial" && s.phase === "ready");
    }, null, { timeout: 60000 });
    const sc = await screen(page);
    if (sc === "fatal") throw new Error(await page.textContent("#fatal-text"));
    if (sc === "done") break;
    if (sc === "intro") { await page.click("#intro-go"); continue; }
    const st = await page.evaluate(() => { const s = window.perceptual.state; return { pos: s.pos, media: s.trials[s.pos].media }; });
    if (opts.pauseAt === st.pos && !paused) {
      paused = true;
      await page.click("#pause");
      await page.waitForFunction(() => window.perceptual.state.screen === "paused");
      await page.click("#unpause");
      say({ step: "paused", trial: st.pos });
    }
    await page.click("#play");
    if (opts.reloadAt === st.pos && !reloaded) {
      // Close the tab mid-trial (the stimulus is playing, nothing answered), then come back.
      reloaded = true;
      metrics.push(...(await page.evaluate(() => window.perceptual.metrics)));
      await page.close();
      page = await openPage();
      if ((await screen(page)) !== "resume") throw new Error(`expected the resume screen, got ${await screen(page)}`);
      await page.click("#resume-go");
      const pos = await page.evaluate(async () => {
        for (let i = 0; i < 200 && window.perceptual.state.screen !== "trial" && window.perceptual.state.screen !== "intro"; i++) await new Promise((r) => setTimeout(r, 50));
        return window.perceptual.state.pos;
      });
      say({ step: "reopened", trial: st.pos, resumed_at: pos });
      continue;
    }
    await page.waitForFunction(() => window.perceptual.state.phase === "responding", null, { timeout: 60000 });
    const info = opts.truth[st.media];
    if (!info) throw new Error(`no truth for ${st.media}`);
    const answer = policy(info);
    for (const [key, value] of Object.entries(answer)) {
      await page.click(`button[data-key="${key}"][data-value="${value}"]`);
    }
    await page.click("#submit");
    await page.waitForFunction((p) => window.perceptual.state.answered.has(p), st.pos, { timeout: 30000 });
    if (opts.doubleAt === st.pos) {
      duplicate = await page.evaluate(async ([p, media, response]) => {
        const s = window.perceptual.state;
        const r = await fetch("/api/answers", { method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify({ participant: s.participant, token: s.token, trial: p, media, response }) });
        return (await r.json()).status;
      }, [st.pos, st.media, answer]);
    }
  }
  metrics.push(...(await page.evaluate(() => window.perceptual.metrics)));
  await page.screenshot({ path: opts.screenshot || join(tmpdir(), "perceptual_done.png") });
  say({ step: "done", participant, metrics, console_errors: errors, duplicate });
}

// The browser closed and its profile removed however the check ends.
const close = async () => {
  if (context) await context.close().catch(() => {});
  rmSync(profile, { recursive: true, force: true, maxRetries: 5 });
};
main().then(close).catch(async (e) => {
  say({ step: "error", error: String(e && e.stack || e), console_errors: errors });
  await close();
  process.exit(1);
});
