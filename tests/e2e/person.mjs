// A scripted person for arld's web expert: opens the page in headless Chromium (Playwright), answers the agent's
// questions by pressing keys with a simple controller that reads the state the page received, saves screenshots
// (training, asking, mid-segment) and checks that the drawing is not blank and that requests without the token
// are refused. Usage:
//   node person.mjs --url URL --shots DIR [--skip N] [--realtime] [--after STEP] [--reload] [--answer N]
// (--policy ENV: answer with the controller of ENV, e.g. CartPole-v0 for a CartPole registered under another id.)
// (--expect-image: the page must show frames the environment rendered, not a drawing of its geometry.)
// (--answer: answer N opening questions, then leave as soon as the next one is open, reporting it as "open".)
// (--reload: open a second, watching tab, and reload the answering tab once while training runs.)
// (--after: take the screenshots only once the run has passed STEP, e.g. to show a learning curve.)
// (--undo: turn-based; at the first question with steps to come press a wrong key, check the page shows the state
//  after it, undo it with Backspace, check the question's own state is back, then answer.)
// Replays of the agent's steps before a question: the first is watched to its end, later ones are skipped with a
// key; each must end at the state the question shows.
// Prints one JSON line: {"answers": [actions answered to opening questions, in order], "skipped": N, ...}.
import { chromium } from "playwright-core";
import http from "node:http";
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
const skip = Number(args.skip || 0);
const realtime = !!args.realtime;
const after = Number(args.after || 0);
const reload = !!args.reload;
const answerLimit = Number(args.answer || 0);
const expectImage = !!args["expect-image"];
const undoTest = !!args.undo;
// (--think MS: wait MS milliseconds before each key, as a person reading the state would (in real time, before
//  the key that answers a question, once the question can be answered); --watch: watch every replay to its end
//  instead of skipping all but the first.)
// Real time: the report's "overhead" times each question on the page's clock: from its first sign (its replay, or
// its prompt) to the person's segment's first running step ("waitS": the replay, their reaction and any countdown;
// not the breath before, which the page cannot see), and the segment's play from then to its end ("playS").
const think = Number(args.think || 0);
const watchAll = !!args.watch;
const thinkPause = () => (think ? page.waitForTimeout(think) : null);
fs.mkdirSync(shots, { recursive: true });
const fail = (msg) => { console.error(`person: ${msg}`); process.exit(1); };

// ---- the person's controllers: the state in, an action out ----------------------------------------------
function lander(s) {
  const angleTarg = Math.max(-0.4, Math.min(0.4, s[0] * 0.5 + s[2]));
  const hoverTarg = 0.55 * Math.abs(s[0]);
  let angleTodo = (angleTarg - s[4]) * 0.5 - s[5];
  let hoverTodo = (hoverTarg - s[1]) * 0.5 - s[3] * 0.5;
  if (s[6] || s[7]) { angleTodo = 0; hoverTodo = -s[3] * 0.5; }
  if (hoverTodo > Math.abs(angleTodo) && hoverTodo > 0.05) return 2;
  if (angleTodo < -0.05) return 3;
  if (angleTodo > 0.05) return 1;
  return 0;
}
const policies = {
  "CartPole-v0": (s) => (0.1 * s[0] + 0.5 * s[1] + 10 * s[2] + 2 * s[3] > 0 ? 1 : 0),
  "CartPole-v1": (s) => (0.1 * s[0] + 0.5 * s[1] + 10 * s[2] + 2 * s[3] > 0 ? 1 : 0),
  "Acrobot-v1": (s) => (s[4] > 0 ? 0 : 2),
  "MountainCar-v0": (s) => (s[1] >= 0 ? 2 : 0),
  "LunarLander-v2": lander,
  "LunarLander-v3": lander,
};

// ---- requests without the token are refused ----------------------------------------------------------------
function status(pathAndQuery, headers = {}) {
  return new Promise((resolve, reject) => {
    const req = http.get({ host: url.hostname, port: url.port, path: pathAndQuery, headers }, (res) => {
      res.resume();
      resolve(res.statusCode);
    });
    req.on("upgrade", (res, socket) => { socket.destroy(); resolve(res.statusCode); });
    req.on("error", reject);
  });
}
const upgrade = { Connection: "Upgrade", Upgrade: "websocket", "Sec-WebSocket-Version": "13", "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ==" };
const refused = {
  page: await status("/"),
  script: await status("/app.js"),
  wrongToken: await status("/?token=0000"),
  websocket: await status("/ws", upgrade),
  other: await status("/../../etc/passwd"),
};
for (const [what, code] of Object.entries(refused)) if (code !== 403) fail(`a request without the token (${what}) got ${code}, not 403`);
// With the token, but naming another host or origin (DNS rebinding, another site's page), or the token twice.
const token = url.searchParams.get("token");
const withToken = `/?token=${token}`;
Object.assign(refused, {
  foreignHost: await status(withToken, { Host: `rebound.example:${url.port}` }),
  foreignOrigin: await status(`/ws?token=${token}`, { ...upgrade, Origin: "http://evil.example" }),
  otherPort: await status(withToken, { Host: `127.0.0.1:${Number(url.port) + 1}` }),
  repeatedToken: await status(`/?token=${token}&token=${token}`),
});
for (const what of ["foreignHost", "foreignOrigin", "otherPort", "repeatedToken"])
  if (refused[what] !== 403) fail(`a request with the token but ${what} got ${refused[what]}, not 403`);
const csp = await new Promise((resolve, reject) =>
  http.get({ host: url.hostname, port: url.port, path: withToken }, (res) => { res.resume(); resolve(res.headers["content-security-policy"]); }).on("error", reject));
if (!csp || !csp.includes("default-src 'none'")) fail(`the page has no Content-Security-Policy: ${csp}`);
refused.csp = csp;
if ((await status(`/ws?token=${url.searchParams.get("token")}`, upgrade)) !== 101) fail("the WebSocket with the token was not accepted");

// ---- the browser ------------------------------------------------------------------------------------------
const userDataDir = fs.mkdtempSync(path.join(shots, ".chromium-"));
// A fresh profile each time (Playwright passes it as --user-data-dir).
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
const controlling = () =>
  page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
await page.goto(url.href);
await controlling();
const hello = await page.evaluate(() => arld.hello);
const policy = policies[args.policy || hello.env] || fail(`no controller for ${args.policy || hello.env}`);
const keyOf = (a) => hello.actions[a].keys[0];

// A second tab watches: its keys are refused, malformed messages get error frames, and the run goes on.
const watcher = await page.evaluate(async () => {
  const ws = new WebSocket(`ws://${location.host}/ws${location.search}`);
  const errors = [];
  ws.onmessage = (e) => { const m = JSON.parse(e.data); if (m.type === "error") errors.push(m.message); };
  await new Promise((r) => (ws.onopen = r));
  for (const bad of ['{"type":"key","id":1,"action":0}', "nonsense", '{"type":"hold","action":99}', '{"type":"launch"}'])
    ws.send(bad);
  await new Promise((r) => setTimeout(r, 300));
  ws.close();
  return errors;
});
if (watcher.length !== 4) fail(`the watching tab got ${watcher.length} error frames for 4 bad messages: ${JSON.stringify(watcher)}`);

async function blankCheck(name) {
  if (expectImage) {
    // A rendered frame arrives as a PNG and is drawn once decoded.
    await page.waitForFunction(() => arld.frame && arld.frame.image, null, { timeout: 10000 })
      .catch(() => fail(`no rendered frame on the page at "${name}"`));
  }
  const d = await page.evaluate(() => {
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
  if (d.share < 0.005 || d.colours < 3) fail(`the drawing is blank at "${name}" (${(d.share * 100).toFixed(2)}% drawn, ${d.colours} colours)`);
  return d;
}
const taken = {};
async function shot(name) {
  if (taken[name]) return;
  if (after && (await page.evaluate(() => (arld.status ? arld.status.step : 0))) < after) return;
  const drawn = await blankCheck(name);
  await page.screenshot({ path: path.join(shots, `${name}.png`) });
  taken[name] = drawn;
}

// A second tab watches; the answering tab reloads and must get control back, the run going on. Done while a
// question is open and budget is left, so that the run cannot end meanwhile.
async function reloadAndTakeBack() {
  // A second tab watches; the answering tab reloads and must get control back, the run going on.
  reloaded = true;
  watching = await browser.newPage();
  await watching.goto(url.href);
  await watching.waitForFunction(() => window.arld && arld.hello && arld.controller !== null &&
    arld.controller !== arld.hello.client && document.getElementById("role").textContent.includes("watching"));
  await page.reload();
  await page.waitForFunction(() => window.arld && arld.hello, null, { timeout: 30000 });
  // Control went to the watching tab when this one closed; take it back with the button while a question
  // is open: the panel must be answerable at once, not greyed until the next question.
  await page.waitForFunction(() => arld.ended || (arld.prompt && arld.prompt.waits), null, { timeout: 0, polling: 5 });
  await page.click("#take-control");
  await controlling().catch(async () => fail(`control did not come back: ${JSON.stringify(await page.evaluate(() =>
    ({ ended: arld.ended, connected: arld.connected, controller: arld.controller, client: arld.client, prompt: arld.prompt, status: arld.status, errors: arld.errors, hidden: document.getElementById("take-control").hidden })))}`));
  const panel = await page.evaluate(() => ({
    open: !!(arld.prompt && arld.prompt.waits),
    disabled: [...document.querySelectorAll("#buttons button")].some((b) => b.disabled),
    text: document.getElementById("prompt-text").textContent,
  }));
  if (!panel.open) fail("no question was open when control was taken back");
  if (panel.open && (panel.disabled || panel.text.includes("Another tab"))) fail(`after taking control back the panel stays greyed: ${JSON.stringify(panel)}`);
  await page.waitForFunction(() => arld.status !== null);
}

// ---- answering ------------------------------------------------------------------------------------------
const answers = [];
let skipped = 0, steps = 0, lastId = 0, held = null, reloaded = false, watching = null;
const timeoutNotices = [];
// The first opening question this person saw, and the one left open (with --answer).
let first = null, open = null, budgetSpentSeen = false;
const latencies = [];
// Real time: the page's times of each question (see "overhead" above).
const timings = [];
let timing = { from: null, live: null };
const state = () => page.evaluate(() => ({ prompt: arld.prompt, status: arld.status, ended: arld.ended, replaying: arld.replaying }));
let undoReport = null, replaysWatched = 0, replaysSkipped = 0, countdownsSeen = 0;
const sameObs = (a, b) => a.length === b.length && a.every((x, i) => x === b[i]);
// A replay before a question: watched (the first) or skipped with a key that is no action's; either way it must
// end at the question's state, and no key may answer the question meanwhile.
async function handleReplay() {
  const shown = await page.evaluate(() => arld.replays.length);
  if (replaysWatched === 0 || watchAll) {
    await shot("replay");
    await page.waitForFunction(() => !arld.replaying, null, { timeout: 10000 }).catch(() => fail("a replay did not end within 10 s"));
    replaysWatched++;
  } else {
    await page.keyboard.press("Shift");
    await page.waitForFunction(() => !arld.replaying, null, { timeout: 2000 }).catch(() => fail("a key did not skip the replay"));
    replaysSkipped++;
  }
  const r = await page.evaluate(() => ({ last: arld.replays[arld.replays.length - 1], prompt: arld.prompt }));
  if (shown && r.prompt && r.last.last.obs && !sameObs(r.last.last.obs, r.prompt.obs))
    fail(`the replay ended at ${JSON.stringify(r.last.last.obs)}, not at the question's state ${JSON.stringify(r.prompt.obs)}`);
}
async function holdKey(a) {
  if (held === a) return;
  if (held !== null) await page.keyboard.up(keyOf(held));
  held = a;
  if (a !== null) await page.keyboard.down(keyOf(a));
}

for (;;) {
  if (!realtime) {
    await page.waitForFunction((last) => arld.ended || (arld.prompt && arld.prompt.waits && arld.prompt.id > last) || arld.replaying ||
      (!arld.prompt && arld.status && arld.status.step > 0), lastId, { timeout: 0, polling: 5 });
  } else {
    await page.waitForTimeout(5);
  }
  let s = await state();
  if (s.ended) break;
  if (realtime) {
    // The page's clock for the overhead: a question's first sign (its replay, or its prompt), its first running
    // step, its end.
    const now = Date.now(), q = s.prompt;
    if (!q && timing.live !== null) { timings.push({ waitS: (timing.live - timing.from) / 1000, playS: (now - timing.live) / 1000 }); timing = { from: null, live: null }; }
    if (timing.from === null && (s.replaying || (q && q.waits && q.agent_action !== null))) timing.from = now;
    if (q && !q.waits && !q.starts_in && timing.live === null && timing.from !== null) timing.live = now;
  }
  if (s.replaying) { await handleReplay(); s = await state(); if (s.ended) break; }
  const p = s.prompt;
  if (p && p.starts_in) { countdownsSeen++; await shot("countdown"); }
  if (!p) {
    if (s.status && s.status.budget_used >= s.status.budget && !s.ended) {
      const text = await page.evaluate(() => document.getElementById("prompt-text").textContent);
      // The budget may have run out between the two reads; the page must never promise questions once it has.
      const still = await page.evaluate(() => !arld.prompt && arld.status.budget_used >= arld.status.budget && !arld.ended);
      if (still && !text.startsWith("No questions left")) fail(`with the budget spent the page says: "${text}"`);
      budgetSpentSeen = true;
    }
    if (s.status && s.status.step > 0) await shot("training");
    if (realtime) await holdKey(null);
    else await page.waitForFunction((a) => arld.ended || arld.prompt || (arld.status && arld.status.step >= a),
      taken.training ? Infinity : after, { timeout: 0, polling: 5 });
    continue;
  }
  if (p.agent_action !== null && p.waits) {
    if (p.id <= lastId) continue;
    lastId = p.id;
    // The status panel as the question opens (a resumed run fills it before asking again).
    const panel = await page.evaluate(() => document.getElementById("s-step").textContent);
    // The charts' points as the question opens (a resumed run draws its course before the stop).
    const charts = await page.evaluate(() => ({ curve: arld.curve, uncertainty: arld.uncertainty }));
    const question = { obs: p.obs, agent_action: p.agent_action, steps_left: p.steps_left, statusStep: s.status ? s.status.step : null, panel, charts };
    if (first === null) first = question;
    if (answerLimit && answers.length >= answerLimit) { open = question; break; }
    if (skipped < skip) {
      // Nobody answers this one: it must go back to the agent.
      skipped++;
      await page.waitForFunction((id) => arld.ended || !arld.prompt || arld.prompt.id !== id, p.id, { timeout: 0, polling: 20 });
      // A question that timed out is not replaced silently: the page says so.
      timeoutNotices.push(await page.evaluate(() => ({ count: arld.timedOut || 0, banner: document.getElementById("banner").textContent })));
      continue;
    }
    if (reload && !reloaded) {
      await reloadAndTakeBack();
      continue;
    }
    await shot("asking");
    const a = policy(p.obs);
    answers.push(a);
    steps++;
    if (undoTest && !undoReport && !realtime && p.steps_left > 1) {
      // A wrong key first: the page shows the state after it, one step ahead of the run, with undo offered.
      const wrong = (a + 1) % hello.actions.length;
      await page.keyboard.press(keyOf(wrong));
      await page.waitForFunction((id) => arld.ended || (arld.prompt && arld.prompt.id > id), p.id, { timeout: 10000 });
      const ahead = await page.evaluate(() => arld.prompt);
      if (!ahead || !ahead.undo || ahead.agent_action !== null) fail(`after a key mid-segment no undo was offered: ${JSON.stringify(ahead)}`);
      if (sameObs(ahead.obs, p.obs)) fail("the page did not show the state after the key");
      await shot("undo-offered");
      await page.keyboard.press("Backspace");
      await page.waitForFunction((id) => arld.ended || (arld.prompt && arld.prompt.id > id && arld.prompt.waits), ahead.id, { timeout: 10000 });
      const back = await page.evaluate(() => arld.prompt);
      if (!back || back.undo || back.agent_action !== p.agent_action || !sameObs(back.obs, p.obs))
        fail(`after undo the question's own state did not come back: ${JSON.stringify({ asked: p, back })}`);
      lastId = back.id;
      undoReport = { wrong, answer: a, asked: p.obs, ahead: ahead.obs, back: back.obs };
    }
    if (realtime) {
      // A fresh key press opens the segment; then the key stays held (none for the no-op action).
      await holdKey(null);
      await thinkPause();
      if (a === hello.noop) await page.keyboard.press(keyOf(a));
      else await holdKey(a);
    }
    else { await thinkPause(); await page.keyboard.press(keyOf(a)); }
    continue;
  }
  // Later steps of a segment. In real time a segment lasts seconds and its last steps pass in a blink that a
  // loaded machine's polling can miss: the picture is taken at the first running step the page shows.
  if (p.steps_left <= 3 || (realtime && !p.starts_in && !p.waits)) await shot("mid-segment");
  const a = policy(p.obs);
  if (realtime) await holdKey(a === hello.noop ? null : a);
  else if (p.waits && p.id > lastId) {
    lastId = p.id; steps++;
    // Key-to-answer latency, timed in the page: from the key press to the next question (or the end of the
    // segment) arriving over the WebSocket.
    await thinkPause();
    await page.evaluate(() => { window.__keyAt = performance.now(); });
    await page.keyboard.press(keyOf(a));
    const ms = await page.evaluate((id) => new Promise((resolve) => {
      const check = () => (arld.ended || !arld.prompt || arld.prompt.id !== id ? resolve(performance.now() - window.__keyAt) : setTimeout(check, 0));
      check();
    }), p.id);
    latencies.push(ms);
  }
}
await holdKey(null);
if (reload && !open) {
  if (!reloaded) fail("the run ended before the page could be reloaded");
  if (!(await watching.evaluate(() => arld.ended))) fail("the watching tab did not see the end of the run");
}
const endScreen = open ? null : await page.evaluate(() => ({
  shown: !document.getElementById("end").hidden,
  title: document.getElementById("end-title").textContent,
  rows: [...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent]),
  xlabels: [document.getElementById("uchart").dataset.xlabels, document.getElementById("curve").dataset.xlabels],
  outcome: arld.outcome,
}));
if (!open) await page.screenshot({ path: path.join(shots, "end.png") });
await browser.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
if (pageErrors.length) fail(`the page threw: ${pageErrors.join("; ")}`);
if (endScreen) {
  if (!endScreen.shown || !endScreen.outcome) fail(`no end screen at the end of the run: ${JSON.stringify(endScreen)}`);
  if (!endScreen.xlabels.every((l) => l && /\d/.test(l))) fail(`the charts have no x-axis labels: ${JSON.stringify(endScreen.xlabels)}`);
}
if (!answerLimit) for (const name of ["training", "asking", "mid-segment"]) if (!taken[name])
  fail(`no "${name}" screenshot: the run never showed that state (${answers.length} answers, ${steps} steps answered, budget spent seen: ${budgetSpentSeen})`);
if (undoTest && !undoReport) fail("no question with steps to come was asked: undo was not tried");
console.log(JSON.stringify({ env: hello.env, answers, skipped, timeoutNotices, steps, reloaded, refused, watcherErrors: watcher, drawn: taken, first, open, budgetSpentSeen, endScreen,
  undo: undoReport, replaysWatched, replaysSkipped, countdownsSeen, overhead: timings,
  keyLatencyMs: latencies.length ? { n: latencies.length, median: latencies.sort((x, y) => x - y)[latencies.length >> 1], max: latencies[latencies.length - 1] } : null }));
