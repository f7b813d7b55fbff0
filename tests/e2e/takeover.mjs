// A scripted person who takes over unasked, for arld's web expert in real time: opens the page in headless
// Chromium (Playwright), answers the agent's questions with a controller that reads the state the page received,
// and once a question was answered and the agent acts again, presses T ("Take over"), answers the takeover's
// opening prompt with a fresh key, holds the controller's keys for a while, saves a screenshot of the takeover in
// progress (takeover.png) and hands back with Esc; then answers the agent's questions until the run ends. Usage:
//   node takeover.mjs --url URL --shots DIR [--hold N] [--stop N --pid PID] [--resumed]
// (--hold N: hand back after the person's N-th step of the takeover; 15 by default.)
// --stop N --pid PID: instead of handing back, once the person has had N steps of the takeover, send SIGTERM to
// PID (the run) while they hold control, and wait for the page to show the stop (takeover-stopped.png); the report
// then has "stopped" (the page's status and panel just before) and no end screen.
// --resumed: the run was resumed from such a stop: the takeover must go on as the page opens (before any question
// of the agent), once the person presses a fresh key: the report's takeover.resumed says what the page showed then
// (takeover-resumed.png), a second later before any key (beforeKey), and the key pressed (first); then the
// person holds control for --hold steps more, hands back and answers the agent's questions to the end.
// --breath: instead of the above, a person who presses T the moment each of their segments ends, whatever the page
// shows: the run is then either acting (a takeover opens before any question: "granted", handed back at once with
// Esc) or about to ask again (its breath before the next question: "refused" when the agent's question comes first).
// After a refused T the person presses nothing until that question's segment has ended, and a takeover opening
// then is one nobody asked for: the script fails. The report has "breath": {granted, refused, banners}.
// --watch: after the first question the person turns on watch mode (V: the agent's own steps at the real-time rate,
// so that the button is offered for long stretches, where at full speed the agent may ask again within
// milliseconds) and takes over in it; once the takeover is handed back (the agent's questions in the next 100 steps
// go back to it unasked, so it acts) they sample the run's status for two seconds: the report's "watch" has the steps
// and seconds of those samples and the person's seconds that grew meanwhile (none should: watching is not
// answering); then V again: full speed (also once no budget is left).
// T is pressed only with the pole near upright. A takeover the episode ends before the person had what is measured
// (the stop's N steps, or 5) is listed in takeover.early ({openedAtStep, steps}) and the person takes over again.
// Prints one JSON line: {"takeover": {...what the page showed of it...}, "questions": N, "endScreen": {...}}.
import { chromium } from "playwright-core";
import fs from "node:fs";
import path from "node:path";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => {
    if (a.startsWith("--")) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith("--") ? all[i + 1] : true]);
    return acc;
  }, []),
);
const url = new URL(args.url);
const shots = args.shots;
const holdSteps = Number(args.hold || 15);
fs.mkdirSync(shots, { recursive: true });
const fail = (msg) => { console.error(`takeover: ${msg}`); process.exit(1); };
const cartpole = (s) => (0.1 * s[0] + 0.5 * s[1] + 10 * s[2] + 2 * s[3] > 0 ? 1 : 0);

const userDataDir = fs.mkdtempSync(path.join(shots, ".chromium-"));
const browser = await chromium.launchPersistentContext(userDataDir, {
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync"],
  viewport: { width: 1000, height: 720 },
});
const page = browser.pages()[0] || (await browser.newPage());
const pageErrors = [];
page.on("pageerror", (e) => pageErrors.push(String(e)));
await page.goto(url.href);
await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
const hello = await page.evaluate(() => arld.hello);
if (!hello.fps) fail("the run is not in real time");
if (hello.env !== "CartPole-v0") fail(`no controller for ${hello.env}`);
const keyOf = (a) => hello.actions[a].keys[0];
let held = null;
async function holdKey(a) {
  if (held === a) return;
  if (held !== null) await page.keyboard.up(keyOf(held));
  held = a;
  if (a !== null) await page.keyboard.down(keyOf(a));
}
const state = () => page.evaluate(() => ({
  prompt: arld.prompt, status: arld.status, ended: arld.ended, replaying: arld.replaying,
  theta: arld.frame && arld.frame.geometry && arld.frame.geometry.kind === "CartPole" ? arld.frame.geometry.theta : null,
  button: { hidden: document.getElementById("takeover").hidden, disabled: document.getElementById("takeover").disabled },
}));
const panel = () => page.evaluate(() => ({
  text: document.getElementById("prompt-text").textContent,
  className: document.getElementById("prompt").className,
  pass: { text: document.getElementById("pass").textContent, disabled: document.getElementById("pass").disabled },
  takeoverButton: { hidden: document.getElementById("takeover").hidden, disabled: document.getElementById("takeover").disabled,
    text: document.getElementById("takeover").textContent },
  budget: document.getElementById("s-budget").textContent,
  takeovers: document.getElementById("s-takeovers").textContent,
}));

let lastId = 0, questions = 0, takeover = null, phase = args.resumed ? "resumed" : "before";
// --breath: the person's T is "asked" (pressed, nothing came of it yet), or "quiet" (refused: no T until the question
// that came first has had its segment).
const breath = args.breath ? { granted: 0, refused: 0, banners: [], t: null, segment: null } : null;
let stopped = null;
let running = 0;
// --watch: the stretches sampled while the agent acted (no prompt), and the last sample.
const watch = args.watch ? { on: false, measured: false, steps: 0, seconds: 0, personS: 0, samples: 0, skipped: 0, last: null, afterAt: null } : null;
for (;;) {
  await page.waitForTimeout(5);
  const s = await state();
  if (s.ended) break;
  if (s.replaying) { await page.keyboard.press("Shift"); continue; }
  const p = s.prompt;
  if (breath) {
    if (!p) {
      await holdKey(null);
      // A segment of the person's just ended: T at once (unless the last T was refused and this is that question's).
      if (breath.segment === "running") {
        breath.segment = null;
        if (breath.t === "quiet") { breath.t = null; continue; }
        await page.keyboard.press("t");
        breath.t = "asked";
        breath.banners.push(await page.evaluate(() => (document.getElementById("banner").hidden ? null : document.getElementById("banner").textContent)));
      }
      continue;
    }
    if (p.waits && p.agent_action !== null && p.id > lastId) {
      lastId = p.id;
      if (p.takeover) {
        if (breath.t !== "asked") fail(`a takeover nobody asked for: ${JSON.stringify({ prompt: p, breath })}`);
        breath.granted++;
        breath.t = null;
        await page.keyboard.press("Escape");
        continue;
      }
      questions++;
      if (breath.t === "asked") { breath.refused++; breath.t = "quiet"; }
      const a = cartpole(p.obs);
      await holdKey(null);
      if (a === hello.noop) await page.keyboard.press(keyOf(a)); else await holdKey(a);
      continue;
    }
    if (!p.waits && !p.starts_in && !p.takeover) breath.segment = "running";
    const a = cartpole(p.obs);
    await holdKey(a === hello.noop ? null : a);
    continue;
  }
  if (watch) {
    if (watch.on && watch.seconds >= 2) watch.measured = true;
    if (watch.on && (watch.measured || (s.status && s.status.questions_left_max === 0))) {
      await page.keyboard.press("v");
      await page.waitForFunction(() => !arld.watch, null, { timeout: 5000 }).catch(() => fail("watch mode did not go off"));
      watch.on = false;
      watch.measured = true;
    }
    // (Not during a replay, which a key only skips; tried again until watch mode is on.)
    if (!watch.on && !watch.measured && questions >= 1 && !p && !s.replaying) {
      await page.keyboard.press("v");
      watch.on = await page.waitForFunction(() => arld.watch, null, { timeout: 2000 }).then(() => true, () => false);
    }
    // Samples after the takeover (from 300 ms on: the status that counts the hand-back's own step comes a step later),
    // while the agent acts: no prompt and no replay. A stretch between two samples counts only if no question opened
    // in it (the run's query count and the person's answers unchanged): a question in a new episode, after the quiet
    // steps of the hand-back's, is the person's time, which the run adds when the question closes.
    const sample = !p && !s.replaying && watch.on && phase === "after" && s.status && Date.now() - (watch.afterAt ??= Date.now()) > 300
      ? { at: Date.now(), step: s.status.step, personS: s.status.person_s, queries: s.status.queries, answered: s.status.answered } : null;
    if (sample && watch.last && sample.queries === watch.last.queries && sample.answered === watch.last.answered) {
      watch.steps += sample.step - watch.last.step;
      watch.seconds += (sample.at - watch.last.at) / 1000;
      watch.personS += sample.personS - watch.last.personS;
      watch.samples++;
      if (sample.personS - watch.last.personS > 0.05) (watch.jumps ??= []).push({ from: watch.last, to: sample });
    } else if (sample && watch.last) {
      watch.skipped++;
    }
    watch.last = sample;
  }
  if (!p) {
    await holdKey(null);
    // (Only with the pole near upright, as the page draws it: the takeover opens at the agent's next step, a few
    // steps later under load, and a barely trained agent may have the pole falling by then.)
    const calm = s.theta === null || Math.abs(s.theta) < 0.04;
    if (phase === "before" && questions >= 1 && s.status && s.status.budget - s.status.budget_used > holdSteps + 10) {
      // The agent acts: the button is offered, and T takes over from here.
      if (s.button.hidden || s.button.disabled) continue;
      if (watch && !watch.cancel) {
        // First a request made while the run is paused (it waits for the run to go on), cancelled with T again:
        // no takeover may follow it.
        await page.click("#pause");
        await page.waitForFunction(() => arld.paused, null, { timeout: 5000 }).catch(() => fail("the run did not pause"));
        // (The agent may have asked meanwhile: then try again later.)
        if (!(await page.evaluate(() => arld.takeover.offered && !arld.prompt))) {
          await page.click("#pause");
          await page.waitForFunction(() => !arld.paused, null, { timeout: 5000 });
          continue;
        }
        await page.keyboard.press("t");
        await page.waitForFunction(() => arld.takeover.pending, null, { timeout: 5000 }).catch(() => fail("the request is not pending"));
        watch.cancel = { pending: await panel() };
        await page.keyboard.press("t");
        await page.waitForFunction(() => !arld.takeover.pending, null, { timeout: 5000 }).catch(() => fail("T again did not cancel"));
        watch.cancel.cancelled = await panel();
        await page.click("#pause");
        await page.waitForFunction(() => !arld.paused, null, { timeout: 5000 });
        continue;
      }
      if (!calm) continue;
      takeover = { ...(takeover || {}), pressedAtStep: s.status.step, offered: await panel() };
      await page.keyboard.press("t");
      phase = "asked";
    }
    continue;
  }
  if (phase === "resumed") {
    if (!p.takeover) fail(`the resumed run asked a question before its takeover went on: ${JSON.stringify(p)}`);
    // The takeover the stop interrupted goes on: where the run stands, and who has control.
    takeover = { openedAtStep: s.status.step, resumed: { prompt: p, status: s.status, panel: await panel() } };
    await page.screenshot({ path: path.join(shots, "takeover-resumed.png") });
    phase = "running";
    if (p.waits) {
      // The run waits for the person's key: a second later it still stands where it stopped.
      await page.waitForTimeout(1000);
      const later = await state();
      takeover.resumed.beforeKey = { status: later.status, prompt: later.prompt };
      lastId = p.id;
      const first = cartpole(p.obs);
      takeover.resumed.first = first;
      takeover.resumed.obs = p.obs;
      if (first === hello.noop) await page.keyboard.press(keyOf(first)); else await holdKey(first);
      continue;
    }
  }
  if (p.takeover) {
    if (p.waits && p.agent_action !== null && p.id > lastId) {
      if (phase !== "asked") fail(`a takeover nobody asked for: ${JSON.stringify(p)}`);
      // The takeover's opening prompt: the state the agent was in, with its proposal; a fresh key starts it.
      const first = cartpole(p.obs);
      Object.assign(takeover, { openedAtStep: s.status.step, obs: p.obs, agentAction: p.agent_action, stepsLeft: p.steps_left,
        first, opening: await panel() });
      await page.screenshot({ path: path.join(shots, "takeover-asking.png") });
      lastId = p.id;
      await holdKey(null);
      if (first === hello.noop) await page.keyboard.press(keyOf(first)); else await holdKey(first);
      phase = "running";
      continue;
    }
    if (phase === "running" && !p.waits && !p.starts_in && p.id > lastId) {
      lastId = p.id;
      const a = cartpole(p.obs);
      await holdKey(a === hello.noop ? null : a);
      // Steps the person took so far, from the run's status (a loaded machine may miss some of the prompts).
      running = s.status.step - takeover.openedAtStep;
      if (running >= 3 && !takeover.inProgress) {
        takeover.inProgress = await panel();
        await page.screenshot({ path: path.join(shots, "takeover.png") });
      }
      if (args.stop && running >= Number(args.stop)) {
        // The person holds control; the run is stopped (SIGTERM) under them.
        stopped = { status: s.status, panel: await panel(), prompt: p };
        process.kill(Number(args.pid), "SIGTERM");
        await page.waitForFunction(() => arld.ended, null, { timeout: 20000 })
          .catch(() => fail("the page did not show the stop"));
        await holdKey(null);
        stopped.after = await page.evaluate(() => ({
          ended: arld.ended, badge: document.getElementById("role").textContent,
          text: document.getElementById("prompt-text").textContent,
        }));
        await page.screenshot({ path: path.join(shots, "takeover-stopped.png") });
        break;
      }
      if (running >= holdSteps) {
        await holdKey(null);
        await page.keyboard.press("Escape");
        takeover.handedBackAtStep = s.status.step;
        // The page as the takeover ends (read at that moment: the agent may ask again soon after).
        const after = await page.waitForFunction(() => (arld.ended || !arld.prompt || !arld.prompt.takeover) && {
          prompt: arld.prompt ? "a question" : "none",
          className: document.getElementById("prompt").className,
          pass: document.getElementById("pass").textContent,
        }, null, { timeout: 10000, polling: 5 }).catch(() => fail("the takeover did not end after Esc"));
        takeover.after = await after.jsonValue();
        phase = "after";
      }
    }
    continue;
  }
  if (phase === "running") {
    // The episode ended during the takeover (its segment ends there) and the agent asks. The agent may have handed
    // over a pole already falling (it is barely trained): if the person had too few steps for what is measured
    // (the stop's N, or 5), that takeover counts in "early" and the person takes over again once the agent acts.
    const needed = args.stop ? Number(args.stop) : 5;
    if (running < needed && !(args.resumed && takeover.resumed)) {
      takeover.early = [...(takeover.early || []), { openedAtStep: takeover.openedAtStep, steps: running }];
      delete takeover.inProgress;
      running = 0;
      phase = "before";
    } else {
      takeover.endedByEpisode = true;
      phase = "after";
    }
  }
  // T was pressed while the agent was about to ask (between two of its segments): its question comes first and
  // the request is used up; T is pressed again once the agent acts.
  if (phase === "asked") { phase = "before"; takeover.retried = (takeover.retried || 0) + 1; }
  if (p.agent_action !== null && p.waits) {
    if (p.id <= lastId) continue;
    lastId = p.id;
    questions++;
    const a = cartpole(p.obs);
    await holdKey(null);
    if (a === hello.noop) await page.keyboard.press(keyOf(a)); else await holdKey(a);
    continue;
  }
  const a = cartpole(p.obs);
  await holdKey(a === hello.noop ? null : a);
}
await holdKey(null);
if (stopped) {
  await browser.close();
  fs.rmSync(userDataDir, { recursive: true, force: true });
  if (pageErrors.length) fail(`the page threw: ${pageErrors.join("; ")}`);
  console.log(JSON.stringify({ takeover, questions, running, stopped }));
  process.exit(0);
}
const endScreen = await page.evaluate(() => ({
  shown: !document.getElementById("end").hidden,
  rows: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
  outcome: arld.outcome,
}));
await page.screenshot({ path: path.join(shots, "takeover-end.png") });
await browser.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
if (pageErrors.length) fail(`the page threw: ${pageErrors.join("; ")}`);
if (breath) {
  console.log(JSON.stringify({ breath, questions, endScreen }));
  process.exit(0);
}
// Resumed, the page opened on the takeover in progress (its episode may end before many more steps).
if (!takeover || !(takeover.inProgress || takeover.resumed)) fail(`the person never had control long enough: ${JSON.stringify({ takeover, questions })}`);
console.log(JSON.stringify({ takeover, questions, running, endScreen, watch }));
