// A scripted person with a gamepad at a continuous task (Pendulum-v1, MountainCarContinuous-v0 or
// LunarLanderContinuous-v3) on arld's web expert in real time, in headless Chromium: the pad (scripted, see
// browser.mjs) is moved by a controller of the task that reads the state the page drew a reaction time ago
// (--delay MS, 250 by default), through the page's default mapping (sticks around the centre, the lander's main
// engine on the right trigger). Before the first question it reads what the page shows of the pad at rest. Each
// question opens with the pad at rest and is answered by the controller's first move out of rest (or A, when the
// controller wants nothing for half a second). A screenshot of the first segment in progress, a second into it:
// <env>-mid-segment.png. Usage: node pad_person.mjs --url URL --shots DIR [--delay MS]
// Prints one JSON line: {"env", "rest": {values, shown}, "questions": N, "midSegment": {drawing, geometry, axes},
//  "frames": {kinds seen}, "endScreen": {...}}.
import { drawn, openBrowser, parseArgs } from "./browser.mjs";
import path from "node:path";

const args = parseArgs(process.argv.slice(2));
const shots = args.shots;
const delay = Number(args.delay || 250);
const fail = (msg) => { console.error(`pad_person: ${msg}`); process.exit(1); };
const { page, pageErrors, close } = await openBrowser(shots, { pad: true });
await page.goto(args.url);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
if (!hello.box || !hello.fps) fail(`not a real-time box task: ${JSON.stringify(hello)}`);

// The controllers (a state in, the pad's axes and buttons out: [axes, right trigger]); the pad's default mapping
// puts the first free dimension on the left stick X and the lander's main engine on the right trigger (0 to 1
// from the lower bound to the upper).
const clip = (x) => Math.max(-1, Math.min(1, x));
// Gymnasium's heuristic lander controller, continuous branch.
function lander(s) {
  const angleTarg = Math.max(-0.4, Math.min(0.4, s[0] * 0.5 + s[2]));
  const hoverTarg = 0.55 * Math.abs(s[0]);
  let angleTodo = (angleTarg - s[4]) * 0.5 - s[5];
  let hoverTodo = (hoverTarg - s[1]) * 0.5 - s[3] * 0.5;
  if (s[6] || s[7]) { angleTodo = 0; hoverTodo = -s[3] * 0.5; }
  const main = clip(hoverTodo * 20 - 1), lateral = clip(-angleTodo * 20);
  return { axes: [lateral, 0, 0, 0], trigger: (main + 1) / 2 };
}
const controllers = {
  // Swing-up: full torque with the motion far from the top, a feedback near it (torque / 2 on the stick).
  "Pendulum-v1": (s) => {
    const [c, sn, w] = s;
    let u;
    if (c > 0.8) u = -(10 * Math.atan2(sn, c) + 2 * w);
    else u = 0.5 * w * w + 15 * (c - 1) < 0 ? (w < 0 ? -2 : 2) : 0;
    return { axes: [clip(u / 2), 0, 0, 0], trigger: 0 };
  },
  // Push the way the car moves.
  "MountainCarContinuous-v0": (s) => ({ axes: [s[1] < 0 ? -1 : 1, 0, 0, 0], trigger: 0 }),
  "LunarLanderContinuous-v3": lander,
};
const controller = controllers[hello.env] || fail(`no controller for ${hello.env}`);
const setPad = (pad) => page.evaluate((p) => {
  window.__pad.axes = p.axes.slice();
  window.__pad.buttons[7] = p.trigger;
  window.__pad.buttons[0] = p.a ? 1 : 0;
}, pad);
const REST = { axes: [0, 0, 0, 0], trigger: 0 };

// The pad seen at rest: what the page's controls read before anything moved.
await page.waitForFunction(() => arld.pad && arld.pad.map.length === arld.hello.box.names.length, null, { timeout: 5000 });
await page.waitForTimeout(200);
const rest = await page.evaluate(() => ({
  values: arld.axes ? arld.axes.values : null,
  map: arld.pad.map,
  shown: arld.hello.box.names.map((_, d) => document.getElementById(`axis-value-${d}`).textContent),
}));

// The states the page showed, with when they came: the controller reads the latest one at least `delay` old.
await page.evaluate(() => {
  window.__seen = [];
  setInterval(() => {
    // The state of each step the page shows (the prompt's: the state the step acts from).
    const p = arld.prompt, now = performance.now();
    if (p && p.obs && p.obs.length && (!window.__seen.length || window.__seen[window.__seen.length - 1].obs !== p.obs))
      window.__seen.push({ at: now, obs: p.obs });
    while (window.__seen.length > 2 && window.__seen[1].at < now - 2000) window.__seen.shift();
  }, 5);
});
const delayed = () => page.evaluate((d) => {
  const now = performance.now();
  const old = window.__seen.filter((x) => x.at <= now - d);
  return old.length ? old[old.length - 1].obs : null;
}, delay);
const isRest = (p) => p.axes.every((x) => Math.abs(x) < 0.1) && p.trigger < 0.1;

let lastId = 0, questions = 0, midSegment = null, openedAt = 0, liveAt = null;
const kinds = new Set();
for (;;) {
  await page.waitForTimeout(20);
  const s = await page.evaluate(() => ({ prompt: arld.prompt, ended: arld.ended, replaying: arld.replaying, kind: arld.frame && arld.frame.geometry && arld.frame.geometry.kind }));
  if (s.ended) break;
  if (s.kind) kinds.add(s.kind);
  if (s.replaying) { await page.keyboard.press("Shift"); continue; }
  const p = s.prompt;
  if (!p) { await setPad(REST); liveAt = null; continue; }
  if (p.waits && p.agent_action !== null && p.id > lastId) {
    // A question: the pad at rest first, then the controller's first move out of rest answers it.
    lastId = p.id;
    questions++;
    await setPad(REST);
    await page.waitForTimeout(100);
    openedAt = Date.now();
    continue;
  }
  const obs = await delayed();
  const want = obs ? controller(obs) : { ...REST };
  if (p.waits && p.id === lastId && isRest(want) && Date.now() - openedAt > 500) want.a = true;
  await setPad(want);
  if (!p.waits && !p.starts_in) {
    liveAt = liveAt || Date.now();
    if (!midSegment && Date.now() - liveAt > 1000) {
      midSegment = await page.evaluate(() => ({ geometry: arld.frame.geometry, axes: arld.axes, prompt: document.getElementById("prompt-text").textContent }));
      midSegment.drawing = await drawn(page);
      await page.screenshot({ path: path.join(shots, `${hello.env}-mid-segment.png`) });
    }
  }
}
await setPad(REST);
await page.waitForFunction(() => !document.getElementById("end").hidden, null, { timeout: 5000 }).catch(() => fail("no end screen"));
const endScreen = await page.evaluate(() => ({
  rows: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
}));
await close();
if (pageErrors.length) fail(`page errors: ${pageErrors.join("; ")}`);
if (!midSegment) fail(`no segment ran a second: ${questions} questions`);
console.log(JSON.stringify({ env: hello.env, rest, questions, midSegment, kinds: [...kinds], endScreen }));
