// A scripted person answering a task with actions in a box (Pendulum-v1, one dimension "torque" in [-2, 2]) on
// arld's web expert in real time, in headless Chromium (Playwright), with each of the page's continuous controls
// in turn:
//   question 1: a gamepad's left stick X held at 0.5 (the stick leaving the centre answers);
//   question 2: the mapping changed on the page (torque on the right stick X), that stick held at -0.25;
//   question 3: the left arrow held down (a fresh key answers; the torque ramps to its lower bound);
//   question 4: the slider set to 0.8, then Enter;
//   question 5: the stick pushed (0.7) as question 4's segment ends, and held while the agent acts: the question
//   must still wait a second after it opens; the stick let go: it must still wait (a release answers nothing); the
//   stick pushed to -0.6 answers;
//   question 6: the run paused as the question opens, the stick pushed (0.7) while paused, the run goes on: the
//   question must still wait a second later (input left over from a pause answers nothing); let go, it still
//   waits; pushed to -0.6, it answers;
//   questions 7 on, until one came with a replay of the agent's steps (at most 5 tries): the stick pushed (0.6)
//   during the replay and held: the question must still wait a second after the replay (input left over from a
//   replay answers nothing); let go, it still waits; pushed to 0.3, it answers. A question that came without a
//   replay (the agent asked right after the last segment) is handed back, so that the agent acts (its questions in
//   the next 100 steps go back to it unasked) and the next one comes with a replay;
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
//   {"questions": [{"id", "obs", "control", "stick"?, "expected", "segmentS", "pad"?, "waited"?}...], "errors": [...],
//    "hello": {...},
//    "endScreen": {...}}; segmentS: seconds from the segment's first running step (after the countdown) to its end.
import { drawn, openBrowser, parseArgs } from "./browser.mjs";
import path from "node:path";

const args = parseArgs(process.argv.slice(2));
const shots = args.shots;
const fail = (msg) => { console.error(`continuous: ${msg}`); process.exit(1); };
const { page, pageErrors, close } = await openBrowser(shots, { pad: true });
await page.goto(args.url);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
const envOk = args.env ? hello.env.startsWith(args.env) : hello.env === "Pendulum-v1";
if (!hello.box || !envOk) fail(`not Pendulum-v1's box: ${JSON.stringify(hello)}`);
const setPad = (axes) => page.evaluate((a) => { window.__pad.axes = a; }, axes);
// Whether question `id` still waits for its answer (nothing answered it).
const stillWaits = (id) => page.evaluate((i) => !!arld.prompt && arld.prompt.id === i && arld.prompt.waits && !arld.prompt.starts_in, id);
// During the next replay the page shows, the right stick is pushed to `x` (by the page's own clock: replays are short).
const pushDuringReplay = (x) => page.evaluate((v) => {
  if (window.__replayArmed || window.__replayPush) return;
  window.__replayArmed = true;
  const timer = setInterval(() => {
    if (!arld.replaying) return;
    window.__pad.axes = [0, 0, v, 0];
    window.__replayPush = { replays: arld.replays.length };
    window.__replayArmed = false;
    clearInterval(timer);
  }, 1);
}, x);
let replayTries = 0, replayTested = false;
// Between segments: the controls go back to rest; the segment's play lasted from its first running step.
async function endSegment() {
  if (current.liveAt) current.segmentS = (Date.now() - current.liveAt) / 1000;
  if (current.control === "keys") await page.keyboard.up("ArrowLeft");
  if (current.control.startsWith("pad")) await setPad([0, 0, 0, 0]);
  // Before question 5 the stick is pushed and held.
  if (questions.length === 4) await setPad([0, 0, 0.7, 0]);
  current = null;
  // The next question's replay (if any) gets a push of the stick.
  if (questions.length >= 6 && !replayTested && replayTries < 5) await pushDuringReplay(0.6);
}
// Questions answered by something other than a deliberate gesture (the script fails at the end, naming each).
const failures = [];

const questions = [], errors = [];
let lastId = 0, current = null;
for (;;) {
  await page.waitForTimeout(5);
  const s = await page.evaluate(() => ({ prompt: arld.prompt, ended: arld.ended, handed: arld.handed, replaying: arld.replaying, status: arld.status }));
  if (s.ended || s.handed) break;
  if (s.replaying) {
    // A replay armed with a push of the stick plays to its end; others are skipped.
    if (!(await page.evaluate(() => window.__replayPush || window.__replayArmed))) await page.keyboard.press("Shift");
    continue;
  }
  const p = s.prompt;
  if (!p) {
    if (current) await endSegment();
    continue;
  }
  if (current && !p.waits && !p.starts_in && !current.liveAt) current.liveAt = Date.now();
  if (current && current.control === "keys" && !p.waits && !p.starts_in && !current.shot) {
    // The keyboard's segment in progress: the torque ramps toward its bound (in 0.4 s).
    await page.waitForFunction(() => arld.axes && arld.axes.values[0] <= arld.hello.box.low[0], null, { timeout: 3000 })
      .catch(() => fail("the held key did not push the torque to its bound"));
    current.shot = true;
    current.inProgress = await page.evaluate(() => ({
      axes: arld.axes, text: document.getElementById("prompt-text").textContent,
      shown: document.getElementById("axis-value-0").textContent,
    }));
    // The pendulum is drawn (not a table of numbers).
    current.inProgress.drawing = { ...(await drawn(page)), kind: await page.evaluate(() => arld.frame && arld.frame.geometry && arld.frame.geometry.kind) };
    await page.screenshot({ path: path.join(shots, "continuous-answer.png") });
  }
  if (!(p.waits && p.agent_action !== null) || p.id <= lastId) continue;
  // The last segment ended without the page showing a moment with no question (the episode's end cut it and the
  // agent asked at once): it ends here, the pad at rest long enough for the page to see it.
  if (current) { await endSegment(); await page.waitForTimeout(100); }
  lastId = p.id;
  if (!Array.isArray(p.agent_action) || p.agent_action.length !== 1) fail(`the agent's proposal is not a box action: ${JSON.stringify(p)}`);
  const n = questions.length + 1;
  const q = { id: p.id, obs: p.obs, agentAction: p.agent_action };
  if (n === 1) {
    await page.waitForFunction(() => arld.pad && arld.pad.map.length === 1, null, { timeout: 5000 });
    q.padBefore = await page.evaluate(() => arld.pad);
    Object.assign(q, { control: "pad left stick", stick: 0.5 });
    await setPad([0.5, 0, 0, 0]);
  } else if (n === 2) {
    // Torque moves to the right stick, changed on the page.
    await page.selectOption('#pad-map select[data-dim="0"]', { label: "right stick X" });
    q.padAfter = await page.evaluate(() => arld.pad);
    q.padTable = await page.evaluate(() => [...document.querySelectorAll("#pad-map tr")].map((tr) =>
      [tr.querySelector("th").textContent, tr.querySelector("select").selectedOptions[0].textContent]));
    await page.screenshot({ path: path.join(shots, "gamepad-mapping.png"), fullPage: true });
    Object.assign(q, { control: "pad right stick", stick: -0.25 });
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
  } else if (n === 5) {
    // The stick held since before the question opened, then let go.
    await page.waitForTimeout(1000);
    q.waited = { held: await stillWaits(p.id) };
    await setPad([0, 0, 0, 0]);
    await page.waitForTimeout(500);
    q.waited.afterRelease = await stillWaits(p.id);
    if (!q.waited.held || !q.waited.afterRelease) failures.push(`question 5 was answered by a stick held from before it or let go: ${JSON.stringify(q.waited)}`);
    Object.assign(q, { control: "pad after a release", stick: -0.6 });
    await setPad([0, 0, -0.6, 0]);
  } else if (n === 6) {
    // Paused as the question opens; the stick pushed meanwhile.
    await page.click("#pause");
    await page.waitForFunction(() => arld.paused, null, { timeout: 5000 });
    await setPad([0, 0, 0.7, 0]);
    await page.waitForTimeout(300);
    await page.click("#pause");
    await page.waitForFunction(() => !arld.paused, null, { timeout: 5000 });
    await page.waitForTimeout(1000);
    q.waited = { afterPause: await stillWaits(p.id) };
    await setPad([0, 0, 0, 0]);
    await page.waitForTimeout(500);
    q.waited.afterRelease = await stillWaits(p.id);
    if (!q.waited.afterPause || !q.waited.afterRelease) failures.push(`question 6 was answered by a stick pushed during a pause: ${JSON.stringify(q.waited)}`);
    Object.assign(q, { control: "pad after a pause", stick: -0.6 });
    await setPad([0, 0, -0.6, 0]);
  } else if (!replayTested && replayTries < 5) {
    replayTries++;
    const pushed = await page.evaluate(() => window.__replayPush);
    await page.evaluate(() => { window.__replayPush = null; window.__replayArmed = false; });
    if (pushed) {
      replayTested = true;
      await page.waitForTimeout(1000);
      q.waited = { afterReplay: await stillWaits(p.id) };
      await setPad([0, 0, 0, 0]);
      await page.waitForTimeout(500);
      q.waited.afterRelease = await stillWaits(p.id);
      if (!q.waited.afterReplay || !q.waited.afterRelease) failures.push(`question ${n} was answered by a stick pushed during its replay: ${JSON.stringify(q.waited)}`);
    }
    if (pushed) {
      Object.assign(q, { control: "pad after a replay", stick: 0.3 });
      await setPad([0, 0, 0.3, 0]);
    } else {
      Object.assign(q, { control: "handed back for a replay" });
      await pushDuringReplay(0.6);
      await page.keyboard.press("Escape");
    }
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
await close();
if (failures.length) fail(failures.join("; "));
console.log(JSON.stringify({ questions, errors, hello, endScreen, replayTested, replayTries }));
