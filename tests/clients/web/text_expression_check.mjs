// The expression picker on a text session (a chatbot's avatar) in the browser viewer (Debian's Chromium, headless).
//
//   node text_expression_check.mjs URL SESSION
//
// Opens the page on SESSION (a text session speaking), waits for its frames, then prints
// {"step":"picker", "buttons": [...], "smiled": "...", "console_errors": [...]}: the picker's buttons (from the
// description) and the status after a click on "smile" (the server's answer). {"step":"error", ...} (exit 1) on a
// timeout.

import { errors, openViewer, run, say } from "./harness.mjs";

const [url, session] = process.argv.slice(2);

async function main() {
  const page = await openViewer(`${url}/?session=${encodeURIComponent(session)}`);
  await page.waitForSelector("#expressions button", { timeout: 10000 });
  const buttons = await page.locator("#expressions button").allTextContents();
  await page.locator("#expressions button", { hasText: "smile" }).click();
  await page.waitForFunction(() => /smile: /.test(document.getElementById("expression-status").textContent),
    null, { timeout: 10000 });
  const smiled = await page.locator("#expression-status").textContent();
  say({ step: "picker", buttons, smiled, console_errors: errors });
}

run(main);
