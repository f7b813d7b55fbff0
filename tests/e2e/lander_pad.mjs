// A scripted person who lands LunarLanderContinuous-v3 with a gamepad on arld's web expert in real time (headless
// Chromium, the scripted pad of browser.mjs), asked at every step with segments longer than an episode. The pad is
// moved by Gymnasium's heuristic lander controller (its formula, ported here) through the page's default mapping
// (the main engine on the right trigger, the side engines on the left stick X), reading the state the page showed
// --delay steps earlier (4 by default): the person reacts inside the page to each step's message as it arrives,
// so the reaction is counted in the run's own steps, not by a clock (on a loaded machine the page's own lag adds
// about a step: 200-250 ms at 20 steps a second, a person's reaction). A question opens with the pad at rest; the
// controller's first move out of rest answers it (or A, when it wants nothing). After --episodes segments that
// ended with their episode, every later question is handed back (Esc).
// Usage: node lander_pad.mjs --url URL --shots DIR [--delay STEPS] [--episodes N]
// Prints one JSON line: {"segments": [segment messages], "delay", "steps": steps the controller set, "endScreen"}.
import { openBrowser, parseArgs } from "./browser.mjs";
import path from "node:path";

const args = parseArgs(process.argv.slice(2));
const shots = args.shots;
const delay = Number(args.delay || 4);
const episodes = Number(args.episodes || 2);
const fail = (msg) => { console.error(`lander_pad: ${msg}`); process.exit(1); };

// Gymnasium's heuristic lander controller, continuous branch, as pad positions: the lateral value on the left stick
// X, the main engine's value (-1 to 1) on the right trigger (0 to 1).
function heuristicPad(s) {
  const clip = (x) => Math.max(-1, Math.min(1, x));
  const angleTarg = Math.max(-0.4, Math.min(0.4, s[0] * 0.5 + s[2]));
  const hoverTarg = 0.55 * Math.abs(s[0]);
  let angleTodo = (angleTarg - s[4]) * 0.5 - s[5];
  let hoverTodo = (hoverTarg - s[1]) * 0.5 - s[3] * 0.5;
  if (s[6] || s[7]) { angleTodo = 0; hoverTodo = -s[3] * 0.5; }
  const main = clip(hoverTodo * 20 - 1), lateral = clip(-angleTodo * 20);
  return { axes: [lateral, 0, 0, 0], trigger: (main + 1) / 2 };
}

const { page, pageErrors, close } = await openBrowser(shots, { pad: true, tap: true });
await page.goto(args.url);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
if (hello.env !== "LunarLanderContinuous-v3" || !hello.fps) fail(`not the real-time lander: ${JSON.stringify(hello)}`);

// The person, inside the page: each step's message sets the pad from the state `delay` steps before it (a
// segment's steps are consecutive prompts; before the segment began, the question's state).
await page.evaluate(({ src, delay, episodes }) => {
  const controller = eval(`(${src})`);
  const seen = new Map();
  const setPad = (p) => { window.__pad.axes = p.axes.slice(); window.__pad.buttons[7] = p.trigger; };
  const rest = (p) => p.axes.every((x) => Math.abs(x) < 0.1) && p.trigger < 0.1;
  let question = null;
  window.__person = { steps: 0, done: 0, handBack: false };
  window.__onmsg = (m) => {
    if (m.type === "segment") {
      // After the segment the pad goes back to rest; after `episodes` segments that ended with their episode the
      // person hands every question back.
      setPad({ axes: [0, 0, 0, 0], trigger: 0 });
      if (m.outcome !== null) window.__person.done++;
      if (window.__person.done >= episodes) window.__person.handBack = true;
      return;
    }
    if (m.type !== "prompt" || !m.prompt || window.__person.handBack) return;
    const p = m.prompt;
    seen.set(p.id, p.obs);
    if (p.waits && p.agent_action !== null) {
      // A question: the pad at rest, then (a reaction later) the controller's first move, or A.
      question = p;
      setPad({ axes: [0, 0, 0, 0], trigger: 0 });
      setTimeout(() => {
        if (!arld.prompt || arld.prompt.id !== p.id || arld.replaying) return;
        const want = controller(p.obs);
        if (rest(want)) { window.__pad.buttons[0] = 1; setTimeout(() => (window.__pad.buttons[0] = 0), 100); }
        else setPad(want);
      }, 250);
      return;
    }
    if (p.waits || p.starts_in || !question) return;
    const old = seen.get(p.id - delay) || question.obs;
    setPad(controller(old));
    window.__person.steps++;
    seen.delete(p.id - 4 * delay);
  };
  // A question open before the person was ready (the page shows it on connecting) is seen now.
  if (arld.prompt) window.__onmsg({ type: "prompt", prompt: arld.prompt });
}, { src: heuristicPad.toString(), delay, episodes });

let shot = false;
for (;;) {
  await page.waitForTimeout(50);
  const s = await page.evaluate(() => ({
    ended: arld.ended, prompt: arld.prompt, replaying: arld.replaying,
    done: arld.segments.filter((x) => x.outcome !== null).length,
  }));
  if (s.ended) break;
  if (s.replaying) { await page.keyboard.press("Shift"); continue; }
  if (s.done >= episodes) {
    if (s.prompt && s.prompt.waits) await page.keyboard.press("Escape");
  } else if (!shot && s.prompt && !s.prompt.waits && s.prompt.steps_left < 1100) {
    shot = true;
    await page.screenshot({ path: path.join(shots, "lander-pad-mid-segment.png") });
  }
}
await page.waitForFunction(() => !document.getElementById("end").hidden, null, { timeout: 10000 }).catch(() => fail("no end screen"));
const report = await page.evaluate(() => ({
  segments: arld.segments,
  steps: window.__person.steps,
  endScreen: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
}));
await close();
if (pageErrors.length) fail(`page errors: ${pageErrors.join("; ")}`);
console.log(JSON.stringify({ ...report, delay }));
