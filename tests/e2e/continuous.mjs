// A scripted person answering a task with actions in a box (Pendulum-v1, one dimension "torque" in [-2, 2]) on
// arld's web expert in real time, in headless Chromium (Playwright), with each of the page's continuous controls
// in turn:
//   question 1: a gamepad's left stick X held at 0.5 (the stick leaving the centre answers);
//   question 2: the mapping changed on the page (torque on the right stick X), that stick held at -0.25;
//   question 3: the left arrow held down (a fresh key answers; the torque ramps to its lower bound);
//   question 4: the slider set to 0.8, then Enter;
//   later questions: two malformed answers sent on the page's socket (null, what JSON makes of NaN, and a value
//   outside the box; each must come back as an error frame), then Esc hands the question back.
// Headless Chromium has no gamepad: an init script (page.addInitScript) replaces navigator.getGamepads with one
// standard pad whose axes and buttons the script sets (window.__pad), as a real pad's state would read.
// Usage: node continuous.mjs --url URL --shots DIR [--env ID]
// --env: the environment's id begins with ID (a Python program's Gymnasium Pendulum is registered as
// `Pendulum-v1[...]`); without it the id is Pendulum-v1. The person stays until the run is over, or until a Python
// program has the run back (`learn` returned: the page shows the same end screen).
// Screenshots: gamepad-mapping.png (the pad's mapping table for the box), continuous-answer.png (the keyboard's
// segment in progress), end-screen.png (the end screen). Prints one JSON line:
//   {"questions": [{"id", "obs", "control", "expected", "segmentS", "pad"?}...], "errors": [...], "hello": {...},
//    "endScreen": {...}}; segmentS: seconds from the segment's first running step (after the countdown) to its end.
import { chromium } from "playwright-core";
import fs from "node:fs";
import path from "node:path";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => {
    if (a.startsWith("--")) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith("--") ? all[i + 1] : true]);
    return acc;
  }, []),
);
const shots = args.shots;
fs.mkdirSync(shots, { recursive: true });
const fail = (msg) => { console.error(`continuous: ${msg}`); process.exit(1); };

const userDataDir = fs.mkdtempSync(path.join(shots, ".chromium-"));
const browser = await chromium.launchPersistentContext(userDataDir, {
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync"],
  viewport: { width: 1000, height: 820 },
});
// The scripted pad: what navigator.getGamepads() returns, read from window.__pad at each call.
await browser.addInitScript(() => {
  window.__pad = { axes: [0, 0, 0, 0], buttons: new Array(17).fill(0) };
  const read = () => ({
    id: "Scripted pad (standard mapping)", index: 0, connected: true, mapping: "standard", timestamp: performance.now(),
    axes: window.__pad.axes.slice(),
    buttons: window.__pad.buttons.map((v) => ({ pressed: v > 0.5, touched: v > 0, value: v })),
  });
  Object.defineProperty(Navigator.prototype, "getGamepads", { value: () => [read(), null, null, null], configurable: true });
});
const page = browser.pages()[0] || (await browser.newPage());
const pageErrors = [];
page.on("pageerror", (e) => pageErrors.push(String(e)));
await page.goto(args.url);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
const envOk = args.env ? hello.env.startsWith(args.env) : hello.env === "Pendulum-v1";
if (!hello.box || !envOk) fail(`not Pendulum-v1's box: ${JSON.stringify(hello)}`);
const setPad = (axes) => page.evaluate((a) => { window.__pad.axes = a; }, axes);

const questions = [], errors = [];
let lastId = 0, current = null;
for (;;) {
  await page.waitForTimeout(5);
  const s = await page.evaluate(() => ({ prompt: arld.prompt, ended: arld.ended, handed: arld.handed, replaying: arld.replaying, status: arld.status }));
  if (s.ended || s.handed) break;
  if (s.replaying) { await page.keyboard.press("Shift"); continue; }
  const p = s.prompt;
  if (!p) {
    // Between segments: the controls go back to rest; the segment's play lasted from its first running step.
    if (current) {
      if (current.liveAt) current.segmentS = (Date.now() - current.liveAt) / 1000;
      if (current.control === "keys") await page.keyboard.up("ArrowLeft");
      if (current.control.startsWith("pad")) await setPad([0, 0, 0, 0]);
      current = null;
    }
    continue;
  }
  if (current && !p.waits && !p.starts_in && !current.liveAt) current.liveAt = Date.now();
  if (current && current.control === "keys" && !p.waits && !p.starts_in && !current.shot) {
    // The keyboard's segment in progress: the torque ramps toward its bound.
    await page.waitForTimeout(150);
    current.shot = true;
    current.inProgress = await page.evaluate(() => ({
      axes: arld.axes, text: document.getElementById("prompt-text").textContent,
      shown: document.getElementById("axis-value-0").textContent,
    }));
    await page.screenshot({ path: path.join(shots, "continuous-answer.png") });
  }
  if (!(p.waits && p.agent_action !== null) || p.id <= lastId) continue;
  lastId = p.id;
  if (!Array.isArray(p.agent_action) || p.agent_action.length !== 1) fail(`the agent's proposal is not a box action: ${JSON.stringify(p)}`);
  const n = questions.length + 1;
  const q = { id: p.id, obs: p.obs, agentAction: p.agent_action };
  if (n === 1) {
    await page.waitForFunction(() => arld.pad && arld.pad.map.length === 1, null, { timeout: 5000 });
    q.padBefore = await page.evaluate(() => arld.pad);
    Object.assign(q, { control: "pad left stick", expected: 1.0 });
    await setPad([0.5, 0, 0, 0]);
  } else if (n === 2) {
    // Torque moves to the right stick, changed on the page.
    await page.selectOption('#pad-map select[data-dim="0"]', { label: "right stick X" });
    q.padAfter = await page.evaluate(() => arld.pad);
    q.padTable = await page.evaluate(() => [...document.querySelectorAll("#pad-map tr")].map((tr) =>
      [tr.querySelector("th").textContent, tr.querySelector("select").selectedOptions[0].textContent]));
    await page.screenshot({ path: path.join(shots, "gamepad-mapping.png"), fullPage: true });
    Object.assign(q, { control: "pad right stick", expected: -0.5 });
    await setPad([0.9, 0, -0.25, 0]);
  } else if (n === 3) {
    Object.assign(q, { control: "keys", expected: "ramp to -2" });
    await page.keyboard.down("ArrowLeft");
  } else if (n === 4) {
    Object.assign(q, { control: "slider", expected: 0.8 });
    await page.evaluate(() => {
      const s = document.querySelector('#axes input[type=range][data-dim="0"]');
      s.value = "0.8";
      s.dispatchEvent(new Event("input"));
    });
    await page.keyboard.press("Enter");
  } else {
    Object.assign(q, { control: "handed back" });
    if (!errors.length) {
      for (const action of [[null], [5], [0.1, 0.2]]) {
        const before = await page.evaluate(() => arld.errors.length);
        await page.evaluate(([id, a]) => socket.send(JSON.stringify({ type: "key", id, action: a })), [p.id, action]);
        await page.waitForFunction((b) => arld.errors.length > b, before, { timeout: 5000 })
          .catch(() => fail(`no error for ${JSON.stringify(action)}`));
        errors.push({ action, message: await page.evaluate(() => arld.errors[arld.errors.length - 1]) });
      }
    }
    await page.keyboard.press("Escape");
  }
  questions.push(q);
  current = q;
}
await page.waitForFunction(() => !document.getElementById("end").hidden, null, { timeout: 5000 })
  .catch(() => fail("no end screen"));
const endScreen = await page.evaluate(() => ({
  title: document.getElementById("end-title").textContent,
  rows: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
  badge: document.getElementById("role").textContent,
  handed: arld.handed, outcome: arld.outcome,
}));
await page.screenshot({ path: path.join(shots, "end-screen.png"), fullPage: true });
if (pageErrors.length) fail(`page errors: ${pageErrors.join("; ")}`);
await browser.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
console.log(JSON.stringify({ questions, errors, hello, endScreen }));
