// How the page looks, from its URL's query (no DOM here, so the rules are unit-tested in node):
//
//   ?embed=1                 the head alone, filling the page: no side panel (an avatar in a chat page, a
//                            streaming tool's browser source); the sound button still shows when the
//                            browser needs a click before it plays sound
//   ?background=transparent  no background: the page behind the canvas shows through (with embed=1 the
//                            page itself is transparent too)
//   ?background=RRGGBB       a background colour (hex, with or without a leading #, which a URL writes %23)
//
// A value these rules do not know is reported (warnings) and the default kept: a typo must not blank the page.

/** The background behind the head when the URL names none (0xRRGGBB). */
export const DEFAULT_BACKGROUND = 0x292b33;

const FLAGS = { 1: true, true: true, yes: true, on: true, 0: false, false: false, no: false, off: false };

/** opts: URLSearchParams -> {embed: bool, background: 0xRRGGBB or null (transparent), warnings: [string]}. */
export function pageOptions(opts) {
  const warnings = [];
  let embed = false;
  const e = opts.get("embed");
  if (e !== null) {
    const v = FLAGS[e.trim().toLowerCase() || "1"]; // a bare ?embed means on
    if (v === undefined) warnings.push(`embed=${e}: expected 1 or 0; the side panel stays`);
    else embed = v;
  }
  let background = DEFAULT_BACKGROUND;
  const b = opts.get("background");
  if (b !== null) {
    const t = b.trim().toLowerCase();
    const hex = t.replace(/^#/, "");
    if (t === "transparent" || t === "none") background = null;
    else if (/^[0-9a-f]{6}$/.test(hex)) background = parseInt(hex, 16);
    else if (/^[0-9a-f]{3}$/.test(hex)) background = parseInt([...hex].map((c) => c + c).join(""), 16);
    else warnings.push(`background=${b}: expected transparent or a hex colour (RRGGBB); the default kept`);
  }
  return { embed, background, warnings };
}
