// Opens a served cellflip recording (`cellflip run|compare|view ... --serve-web`) in Debian's
// chromium, headless, and takes a screenshot once the web viewer has loaded and drawn it.
//
//   node tools/browser/screenshot.mjs URL OUT.png [--theme light|dark] [--size 1600x900]
//
// A plain `chromium --screenshot` fires before the viewer's 40 MB of wasm has loaded; this waits
// in real time instead: for the page, then until two screenshots three seconds apart are the
// same (the viewer has drawn everything it was sent and is idle), at least --min seconds and at
// most --max. The theme is the browser's colour scheme, which the viewer follows.
// Needs: apt-get install chromium; npm install (in this folder).
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";

const [url, out, ...rest] = process.argv.slice(2);
if (!url || !out) {
  console.error("usage: screenshot.mjs URL OUT.png [--theme light|dark] [--size WxH] [--min S] [--max S]");
  process.exit(2);
}
const opt = (name, fallback) => {
  const i = rest.indexOf(`--${name}`);
  return i >= 0 ? rest[i + 1] : fallback;
};
const theme = opt("theme", "dark");
const [width, height] = opt("size", "1600x900").split("x").map(Number);
const minSecs = Number(opt("min", "15"));
const maxSecs = Number(opt("max", "180"));

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  // No GPU here: WebGL through SwiftShader. No background traffic: the machine's network is
  // closed, and chromium's own connections would only fail.
  args: [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
  ],
});
const page = await browser.newPage({ viewport: { width, height }, colorScheme: theme });
page.on("console", (m) => {
  if (m.type() === "error") console.error(`page: ${m.text()}`);
});
const t0 = Date.now();
await page.goto(url, { waitUntil: "load", timeout: maxSecs * 1000 });
await page.waitForSelector("canvas", { timeout: maxSecs * 1000 });
let last = null;
for (;;) {
  await page.waitForTimeout(3000);
  const shot = await page.screenshot();
  const secs = (Date.now() - t0) / 1000;
  const still = last !== null && shot.equals(last);
  if ((still && secs >= minSecs) || secs >= maxSecs) {
    writeFileSync(out, shot);
    console.log(`${out}: after ${secs.toFixed(0)} s (${still ? "idle" : "still drawing at the limit"})`);
    break;
  }
  last = shot;
}
await browser.close();
