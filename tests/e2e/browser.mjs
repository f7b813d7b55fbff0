// What the scripted people of arld's browser tests share: their command line, a headless Chromium with a fresh
// profile, and a scripted gamepad. Headless Chromium has no gamepad: an init script replaces
// navigator.getGamepads with one standard pad whose axes and buttons (values 0 to 1) the script sets in
// window.__pad, as a real pad's state would read.
import { chromium } from "playwright-core";
import fs from "node:fs";
import path from "node:path";

/// The script's `--name value` arguments (a flag without a value is `true`).
export function parseArgs(argv) {
  return Object.fromEntries(
    argv.reduce((acc, a, i, all) => {
      if (a.startsWith("--")) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith("--") ? all[i + 1] : true]);
      return acc;
    }, []),
  );
}

/// Headless Chromium with a fresh profile under `shots` (removed by `close`), its first page, and the errors the
/// page throws. `pad`: add the scripted pad; `tap`: record the server's messages (see below).
export async function openBrowser(shots, { viewport = { width: 1000, height: 820 }, pad = false, tap = false } = {}) {
  fs.mkdirSync(shots, { recursive: true });
  const userDataDir = fs.mkdtempSync(path.join(shots, ".chromium-"));
  const browser = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
      "--disable-component-update", "--disable-sync"],
    viewport,
  });
  if (pad) {
    await browser.addInitScript(() => {
      window.__pad = { axes: [0, 0, 0, 0], buttons: new Array(17).fill(0) };
      const read = () => ({
        id: "Scripted pad (standard mapping)", index: 0, connected: true, mapping: "standard", timestamp: performance.now(),
        axes: window.__pad.axes.slice(),
        buttons: window.__pad.buttons.map((v) => ({ pressed: v > 0.5, touched: v > 0, value: v })),
      });
      Object.defineProperty(Navigator.prototype, "getGamepads", { value: () => [read(), null, null, null], configurable: true });
    });
  }
  if (tap) {
    // Every message the server sends, as the page receives it: the prompts in window.__prompts (each step's id,
    // state, proposal), and each message to window.__onmsg when the script sets one (an in-page person reacts at
    // once to each step, paced by the run's steps, not by a clock).
    await browser.addInitScript(() => {
      window.__prompts = [];
      const Native = window.WebSocket;
      class Tapped extends Native {
        constructor(...args) {
          super(...args);
          this.addEventListener("message", (ev) => {
            const m = JSON.parse(ev.data);
            if (m.type === "prompt" && m.prompt) window.__prompts.push(m.prompt);
            if (window.__onmsg) window.__onmsg(m);
          });
        }
      }
      window.WebSocket = Tapped;
    });
  }
  const page = browser.pages()[0] || (await browser.newPage());
  const pageErrors = [];
  page.on("pageerror", (e) => pageErrors.push(String(e)));
  const close = async () => {
    await browser.close();
    fs.rmSync(userDataDir, { recursive: true, force: true });
  };
  return { browser, page, pageErrors, close };
}

/// Whether the environment's canvas is drawn (not one flat colour): the share of pixels unlike the corner's, and
/// how many colours (up to 64) it holds.
export function drawn(page) {
  return page.evaluate(() => {
    const c = document.getElementById("env");
    const px = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    const bg = [px[0], px[1], px[2]];
    const colours = new Set();
    let differ = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (Math.abs(px[i] - bg[0]) + Math.abs(px[i + 1] - bg[1]) + Math.abs(px[i + 2] - bg[2]) > 30) differ++;
      if (colours.size < 64) colours.add((px[i] << 16) | (px[i + 1] << 8) | px[i + 2]);
    }
    return { share: differ / (px.length / 4), colours: colours.size };
  });
}
