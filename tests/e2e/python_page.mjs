// A person on the page of a run that a Python program drives (python/tests/test_web.py): opens the page in headless
// Chromium, answers every question with the key of a fixed action, and checks what the page shows when the program
// has the run back. Usage:
//   node python_page.mjs --url URL --shots DIR --key KEY [--pause MS] [--go FILE --pid PID]
// With --pause, the first question is paused for MS milliseconds, the tab closed meanwhile and opened again (the
// pause must hold), then answered: the report says how long the question was open and how long paused.
// With --gamepad ACTION, the page gets a scripted pad (navigator.getGamepads replaced by an init script, as
// headless Chromium has no pad): the second question is answered on it, after ACTION's button is changed to the
// d-pad's down on the page's mapping. With --handback K, the K-th question is handed back (Esc).
// The first `learn` runs to its end: the page must show where the run stands (the end screen, no live buttons)
// while the program still runs. With --go, the person then creates FILE (the program waits for it and trains on),
// checks the note is lifted, and when a question is open sends SIGTERM to PID: the page must show the stop, with the
// question closed. Prints one JSON line with what the page showed.
import { chromium } from "playwright-core";
import fs from "node:fs";
import path from "node:path";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => {
    if (a.startsWith("--")) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith("--") ? all[i + 1] : true]);
    return acc;
  }, []),
);
const fail = (msg) => { console.error(`python_page: ${msg}`); process.exit(1); };
fs.mkdirSync(args.shots, { recursive: true });
const userDataDir = fs.mkdtempSync(path.join(args.shots, ".chromium-"));
const browser = await chromium.launchPersistentContext(userDataDir, {
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync"],
  viewport: { width: 1000, height: 720 },
});
let page = null;
const pageErrors = [];
if (args.gamepad) {
  // A standard-mapping pad whose buttons the test sets in window.__pad (17 buttons, 4 axes).
  await browser.addInitScript(() => {
    window.__pad = { buttons: new Array(17).fill(false), axes: [0, 0, 0, 0] };
    const pad = () => ({
      id: "Scripted pad (STANDARD GAMEPAD)", index: 0, connected: true, mapping: "standard", timestamp: performance.now(),
      axes: window.__pad.axes.slice(), buttons: window.__pad.buttons.map((p) => ({ pressed: p, touched: p, value: p ? 1 : 0 })),
    });
    Object.defineProperty(Navigator.prototype, "getGamepads", { value: () => [pad(), null, null, null], configurable: true });
  });
}
// Presses button `b` of the scripted pad for a moment.
async function padPress(b) {
  await page.evaluate((b) => { window.__pad.buttons[b] = true; }, b);
  await page.waitForTimeout(80);
  await page.evaluate((b) => { window.__pad.buttons[b] = false; }, b);
}
let padReport = null;
async function padAnswer() {
  const action = Number(args.gamepad);
  await page.waitForFunction(() => arld.pad && !document.getElementById("pad").hidden, null, { timeout: 5000 })
    .catch(() => fail("the page shows no gamepad mapping"));
  const before = await page.evaluate(() => ({ map: arld.pad.map, rows: [...document.querySelectorAll("#pad-map tr")].map((r) => [r.cells[0].textContent, r.querySelector("select").selectedOptions[0].textContent]) }));
  await page.selectOption(`#pad-map select[data-action="${action}"]`, "13");
  const after = await page.evaluate(() => arld.pad.map);
  await page.screenshot({ path: path.join(args.shots, "gamepad-mapping.png"), fullPage: true });
  const id = await page.evaluate(() => arld.prompt.id);
  await padPress(13);
  await page.waitForFunction((id) => !arld.prompt || arld.prompt.id !== id, id, { timeout: 5000 })
    .catch(async () => fail(`the pad's button did not answer: ${JSON.stringify(await page.evaluate(() => ({ prompt: arld.prompt, pad: arld.pad, errors: arld.errors })))} ${pageErrors.join("; ")}`));
  padReport = { before, after };
}
async function openPage(tab) {
  page = tab;
  page.on("pageerror", (e) => pageErrors.push(String(e)));
  await page.goto(args.url);
  await page.waitForFunction(() => window.arld && arld.hello && arld.controller === arld.hello.client, null, { timeout: 30000 });
}
await openPage(browser.pages()[0] || (await browser.newPage()));
const hello = await page.evaluate(() => ({
  ...arld.hello,
  buttons: [...document.querySelectorAll("#buttons button")].map((b) => b.textContent),
  help: document.getElementById("keys-help").textContent,
  undoHidden: document.getElementById("undo").hidden,
}));

// What the page shows now: the panel, the buttons, the end screen, the badge, and how tall the page is.
const view = () => page.evaluate(() => ({
  prompt: arld.prompt, handed: arld.handed, ended: arld.ended,
  text: document.getElementById("prompt-text").textContent,
  obsLine: document.getElementById("obs").textContent,
  tableRows: document.querySelectorAll("#obs-table tr").length,
  live: [...document.querySelectorAll("#buttons button")].filter((b) => !b.disabled).length,
  passLive: !document.getElementById("pass").disabled,
  badge: document.getElementById("role").textContent,
  pauseLive: !document.getElementById("pause").disabled,
  end: document.getElementById("end").hidden ? null : {
    title: document.getElementById("end-title").textContent,
    note: document.getElementById("end-note").textContent,
    rows: Object.fromEntries([...document.querySelectorAll("#end-table tr")].map((r) => [r.cells[0].textContent, r.cells[1].textContent])),
  },
  outcome: arld.outcome,
  height: document.documentElement.scrollHeight,
}));

// Answers every question until the program has the run back (or the run is over); returns the keys given (one a
// step), the questions answered (segments opened) and the page's largest height while a question was open.
let lastId = 0, pauseReport = null;
// The first question: paused, the tab closed and opened again while paused, then answered.
async function pauseThenAnswer() {
  const seen = Date.now();
  await page.click("#pause");
  await page.waitForFunction(() => arld.paused);
  const pausedAt = Date.now();
  await page.waitForTimeout(Number(args.pause) / 2);
  await page.close();
  await new Promise((r) => setTimeout(r, Number(args.pause) / 2));
  await openPage(await browser.newPage());
  const stillPaused = await page.evaluate(() => arld.paused);
  const banner = await page.evaluate(() => document.getElementById("banner").textContent);
  await page.click("#pause");
  await page.waitForFunction(() => !arld.paused);
  const goneOn = Date.now();
  await page.keyboard.press(args.key);
  pauseReport = { openS: (Date.now() - seen) / 1000, pausedS: (goneOn - pausedAt) / 1000, stillPaused, banner };
}
async function answerUntilHanded() {
  let answers = 0, questions = 0, tallest = 0, asked = null, handedBack = 0;
  for (;;) {
    await page.waitForFunction((last) => arld.handed || arld.ended || (arld.prompt && arld.prompt.waits && arld.prompt.id > last),
      lastId, { timeout: 0, polling: 5 });
    const v = await view();
    if (v.handed || v.ended) return { answers, questions, tallest, asked, handedBack };
    if (v.prompt.agent_action !== null && args.handback && questions + handedBack + 1 === Number(args.handback)) {
      lastId = v.prompt.id;
      handedBack++;
      await page.keyboard.press("Escape");
      continue;
    }
    if (v.prompt.agent_action !== null) questions++;
    lastId = v.prompt.id;
    if (!asked) asked = v;
    tallest = Math.max(tallest, v.height);
    if (args.pause && !pauseReport) await pauseThenAnswer();
    else if (args.gamepad && !padReport && v.prompt.agent_action !== null) await padAnswer();
    else await page.keyboard.press(args.key);
    answers++;
  }
}

const first = await answerUntilHanded();
// The program keeps running after learn returned: the page must say where the run stands, at once.
const handed = await view();
await page.screenshot({ path: path.join(args.shots, "python-end.png") });
const report = { hello, first, handed, pause: pauseReport, pad: padReport };

if (args.go) {
  fs.writeFileSync(args.go, "go\n");
  await page.waitForFunction(() => !arld.handed, null, { timeout: 30000 }).catch(() => fail("the note stayed when the run went on"));
  report.resumed = await view();
  // A question open: the program is stopped (SIGTERM) while the person has not answered yet.
  await page.waitForFunction(() => arld.handed || (arld.prompt && arld.prompt.waits), null, { timeout: 60000 })
    .catch(() => fail("no question came after the run went on"));
  report.openWhenStopped = (await view()).prompt;
  process.kill(Number(args.pid), "SIGTERM");
  await page.waitForFunction(() => arld.handed || arld.ended, null, { timeout: 30000 }).catch(() => fail("the stop was not shown"));
  report.stopped = await view();
  await page.screenshot({ path: path.join(args.shots, "python-stop.png") });
  // The program exits: the page must not wait for a connection for ever.
  await page.waitForFunction(() => arld.ended, null, { timeout: 30000 }).catch(() => fail("the page did not see the program end"));
  report.exited = await view();
}
await browser.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
if (pageErrors.length) fail(`the page threw: ${pageErrors.join("; ")}`);
console.log(JSON.stringify(report));
