// A scripted person at LunarLanderContinuous-v3 on arld's web expert in real time (headless Chromium), asked at
// every step (the greedy rule) with long segments: the agent's proposal at every step of a segment, the line after
// each segment, and a retry. Question 1: Enter with nothing held (the engines off: the lander falls), then R in the
// breath after the segment's line, and the retry is played with the right arrow held (the side engine at full
// throttle); that attempt is kept. Question 2: Enter with nothing held, kept. Every later question is handed back
// (Esc). Half a second into the first segment it reads the ghost (the proposal the prompt carries, the slider's
// mark, what the proposal adds to the canvas) and takes segment-ghost.png; segment-line.png shows the line after it.
// Usage: node segments.mjs --url URL --shots DIR
// Prints one JSON line: {"segments": [segment messages], "plays": [{id, proposal}] of the played steps,
//  "mid": {prompt, marks, ghostPixels}, "lastStatus", "endScreen"}.
import { openBrowser, parseArgs } from "./browser.mjs";
import path from "node:path";

const args = parseArgs(process.argv.slice(2));
const shots = args.shots;
const fail = (msg) => { console.error(`segments: ${msg}`); process.exit(1); };
const { page, pageErrors, close } = await openBrowser(shots, { tap: true });
await page.goto(args.url);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
if (!hello.box || !hello.fps || hello.env !== "LunarLanderContinuous-v3") fail(`not the real-time lander: ${JSON.stringify(hello)}`);

const state = () => page.evaluate(() => ({ prompt: arld.prompt, ended: arld.ended, replaying: arld.replaying, segments: arld.segments.length }));
const until = async (what, test, ms = 60000) => {
  const t0 = Date.now();
  for (;;) {
    const s = await state();
    if (test(s)) return s;
    if (s.ended) fail(`the run ended waiting for ${what}`);
    if (Date.now() - t0 > ms) fail(`timed out waiting for ${what}: ${JSON.stringify(s)}`);
    await page.waitForTimeout(10);
  }
};
const question = () => until("a question", (s) => !s.replaying && s.prompt && s.prompt.waits && s.prompt.agent_action !== null);

// Question 1, first attempt: Enter with nothing held (after the countdown the engines stay off).
let q = await question();
const firstQuestion = q.prompt.id;
await page.keyboard.press("Enter");
// Half a second into the segment: the ghost of the agent's proposal on the slider and the drawing.
await until("the segment to play", (s) => s.prompt && !s.prompt.waits && !s.prompt.starts_in && s.prompt.id > firstQuestion + 10);
const mid = await page.evaluate(() => {
  // The ghost on the canvas: the pixels that change when the same frame is drawn without the proposal.
  const c = document.getElementById("env"), snap = () => c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
  const withGhost = snap(), shown = arld.prompt;
  arld.prompt = { ...shown, proposal: null, agent_action: null };
  draw();
  const without = snap();
  arld.prompt = shown;
  draw();
  let ghostPixels = 0;
  for (let i = 0; i < withGhost.length; i += 4) {
    if (Math.abs(withGhost[i] - without[i]) + Math.abs(withGhost[i + 1] - without[i + 1]) + Math.abs(withGhost[i + 2] - without[i + 2]) > 30) ghostPixels++;
  }
  const marks = arld.hello.box.names.map((_, d) => {
    const m = document.getElementById(`axis-ghost-${d}`);
    return { hidden: m.hidden, left: m.style.left, shown: document.getElementById(`axis-value-${d}`).textContent };
  });
  return { prompt: arld.prompt, marks, ghostPixels, ghostsDrawn: arld.ghosts };
});
await page.screenshot({ path: path.join(shots, "segment-ghost.png") });
await until("the first segment's line", (s) => s.segments >= 1);
await page.screenshot({ path: path.join(shots, "segment-line.png") });
await page.keyboard.press("r");

// The retry: the same question again; the right arrow held answers it at once and fires the side engine.
q = await question();
if (q.prompt.id <= firstQuestion) fail("no retry question");
await page.keyboard.down("ArrowRight");
await until("the retry's line", (s) => s.segments >= 2);
await page.keyboard.up("ArrowRight");
await page.screenshot({ path: path.join(shots, "segment-retried.png") });

// Question 2: Enter with nothing held; kept. Then every question goes back to the agent.
await until("the next question", (s) => !s.replaying && s.prompt && s.prompt.waits && s.prompt.agent_action !== null && s.prompt.id > q.prompt.id + 2);
await page.keyboard.press("Enter");
await until("the second question's line", (s) => s.segments >= 3);
for (;;) {
  const s = await state();
  if (s.ended) break;
  if (s.replaying) await page.keyboard.press("Shift");
  else if (s.prompt && s.prompt.waits) await page.keyboard.press("Escape");
  await page.waitForTimeout(30);
}
await page.waitForFunction(() => !document.getElementById("end").hidden, null, { timeout: 10000 }).catch(() => fail("no end screen"));
const report = await page.evaluate(() => ({
  segments: arld.segments,
  plays: window.__prompts.filter((p) => !p.waits && !p.starts_in && p.agent_action === null).map((p) => ({ id: p.id, proposal: p.proposal })),
  lastStatus: arld.status,
  endScreen: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
}));
await close();
if (pageErrors.length) fail(`page errors: ${pageErrors.join("; ")}`);
console.log(JSON.stringify({ ...report, mid, firstQuestion }));
