// The web expert's page: shows the environment (drawn from the geometry the server sends, or the frames the
// environment rendered, or its observation as a table), the run's status, the person's time and the charts,
// and answers the agent's questions with the keyboard or the buttons, and for actions in a box (a list of numbers)
// with keys held toward a bound, a slider per dimension or a gamepad's sticks and triggers.
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
// Everything the page knows, readable from the console (and by automated tests).
const arld = (window.arld = {
  client: null, hello: null, controller: null, status: null, frame: null, prompt: null, paused: false,
  uncertainty: [], curve: [], ended: null, outcome: null, errors: [], connected: false, obsHistory: [],
  replaying: false, replays: [], countdowns: 0, undos: 0, handed: null, takeovers: 0,
  takeover: { offered: false, pending: false }, watch: false, segments: [], retries: 0, ghosts: 0,
});
let socket = null;
let replay = null; // the replay being played: {frames, at, timer, live}
let answered = null; // id of the prompt this tab already answered
let held = null; // the action whose key or button is held down (real time)
const $ = (id) => document.getElementById(id);

function send(msg) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(msg));
}
const controls = () => arld.client !== null && arld.controller === arld.client;

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws?token=${encodeURIComponent(token)}`);
  socket.onopen = () => { arld.connected = true; banner(null); };
  socket.onmessage = (ev) => receive(JSON.parse(ev.data));
  socket.onclose = () => {
    arld.connected = false;
    if (arld.ended) return;
    if (arld.handed) {
      // The program had the run back and has ended without saying so (a Python program exits): nothing to wait for.
      arld.ended = "The program has ended; the run will not go on.";
      showPrompt(); showRole(); showEnd(); banner(arld.ended);
      return;
    }
    banner("Connection lost; reconnecting…");
    setTimeout(connect, 1000);
  };
}

function receive(m) {
  // While the agent's steps are replayed, the live picture waits (the last one is drawn when the replay ends).
  if (replay && (m.type === "frame" || m.type === "image" || m.type === "table")) { replay.live = m; return; }
  switch (m.type) {
    case "welcome":
      arld.client = m.client;
      if (!arld.hello) $("prompt-text").textContent = "Waiting for the run to start…";
      break;
    case "hello": arld.hello = { ...m, client: arld.client }; setup(); break;
    case "paused": arld.paused = m.paused; showPaused(); break;
    case "image": showImage(m.png); break;
    case "table": showTable(m.labels, m.obs); break;
    case "roles": arld.controller = m.controller; showRole(); break;
    case "status": arld.status = m; showStatus(); break;
    case "replay": startReplay(m.frames); break;
    case "frame": arld.frame = m; draw(); if (arld.replaying && m.obs) showObs(m.obs, "replayed"); break;
    case "eval": arld.curve.push([m.step, m.mean]); drawCurve(); break;
    case "history": arld.uncertainty = m.uncertainty.slice(); arld.curve = m.curve.slice(); drawCharts(); break;
    case "prompt": {
      // A question that waited for this tab and goes away unanswered timed out: say so, not silently.
      const before = arld.prompt, h = arld.hello;
      if (before && before.waits && h && h.timeout && answered !== before.id && controls() && (!m.prompt || m.prompt.id !== before.id)) {
        arld.timedOut = (arld.timedOut || 0) + 1;
        banner(`Time is up: the agent took that question back (${h.timeout} s to answer).`, 4000);
      }
      arld.prompt = m.prompt; showPrompt();
      // The agent's proposal at this step is drawn over the state (a ghost of its action).
      if (arld.prompt && arld.prompt.proposal !== null && arld.prompt.proposal !== undefined) arld.ghosts++;
      if (arld.frame && arld.frame.geometry && !replay) draw();
      if (arld.prompt && arld.prompt.waits) closeRetry();
      break;
    }
    case "error": arld.errors.push(m.message); banner(m.message, 3000); break;
    case "end":
      arld.ended = m.message; arld.outcome = m.outcome || arld.outcome; arld.prompt = null;
      showPrompt(); showRole(); showEnd(); banner(m.message);
      break;
    case "handed":
      // (No banner: the panel and the end screen say it.)
      arld.handed = { message: m.message, stopped: m.stopped }; arld.outcome = m.outcome; arld.prompt = null;
      showPrompt(); showRole(); showEnd(); banner(null);
      break;
    case "watch": arld.watch = m.on; showWatch(); break;
    case "segment": showSegment(m); break;
    case "takeover": arld.takeover = { offered: m.offered, pending: m.pending }; showPrompt(); break;
    case "resumed": arld.handed = null; arld.outcome = null; $("end").hidden = true; banner(null); showRole(); showPrompt(); break;
  }
}

let bannerTimer = null;
function banner(text, ms) {
  const b = $("banner");
  clearTimeout(bannerTimer);
  b.hidden = !text;
  b.textContent = text || "";
  if (text && ms) bannerTimer = setTimeout(() => (b.hidden = true), ms);
}

function setup() {
  const h = arld.hello;
  $("env-name").textContent = h.env;
  $("mode").textContent = h.fps ? `real time, ${h.fps} steps/s` : "turn-based: one step per key";
  if (h.timeout) $("mode").textContent += `, questions wait ${h.timeout} s`;
  const box = $("buttons");
  box.textContent = "";
  axesSetup();
  h.actions.forEach((a, i) => {
    const b = document.createElement("button");
    b.textContent = `${a.label} [${a.keys.map(keyName).join(" / ")}]`;
    b.dataset.action = i;
    b.addEventListener("click", () => { if (replay) stopReplay(); else if (!h.fps) press(i); });
    b.addEventListener("pointerdown", () => { if (h.fps && !replay) { hold(i); press(i, true); } });
    b.addEventListener("pointerup", () => { if (h.fps) release(i); });
    b.addEventListener("pointerleave", () => { if (h.fps) release(i); });
    box.appendChild(b);
  });
  $("keys-help").textContent = h.box ? axesHelp() : h.fps
    ? `A fresh press of an action's key starts your segment at once; then hold a key to act (with no key held the environment takes "${h.actions[h.noop].label}"). T takes over while the agent acts (T again cancels a request; Esc hands back); V shows its steps at the real-time rate. P pauses.`
    : h.undo
      ? "Each key (or button) takes one step; Backspace undoes your last key of the segment. P pauses, Esc lets the agent decide."
      : "Each key (or button) takes one step. P pauses, Esc lets the agent decide.";
  showRole();
  showPrompt();
  showWatch();
  padSetup();
}

// What an action does, as the page names it: a discrete action's label, or a box's numbers by dimension.
function actionName(a) {
  const h = arld.hello;
  if (h.box) return Array.isArray(a) ? h.box.names.map((n, d) => `${n} ${Number(a[d]).toFixed(2)}`).join(", ") : "–";
  return h.actions[a] ? h.actions[a].label : `action ${a}`;
}

const keyName = (k) => ({ ArrowLeft: "←", ArrowRight: "→", ArrowUp: "↑", ArrowDown: "↓", " ": "Space" })[k] || k.toUpperCase();

function showRole() {
  if (!arld.hello) return;
  const r = $("role");
  const over = arld.ended !== null, handed = !over && arld.handed !== null;
  r.textContent = over ? "run over" : handed ? "the program has the run" : controls() ? "you answer" : "watching (another tab answers)";
  r.className = "badge " + (over || handed ? "idle" : controls() ? "control" : "watch");
  $("take-control").hidden = controls() || over;
  // (A program that has the run back runs nothing to pause.)
  $("pause").disabled = over || handed;
  showWatch();
  // The panel follows the role at once (an open question is answerable as soon as control is taken).
  showPrompt();
}
$("take-control").addEventListener("click", () => send({ type: "control" }));

function fmt(x, d = 3) { return x === null || x === undefined ? "–" : Number(x).toFixed(d); }

// Seconds as "1 min 05 s" (or "42 s").
function duration(t) {
  if (t === null || t === undefined) return "–";
  t = Math.round(t);
  return t >= 60 ? `${Math.floor(t / 60)} min ${String(t % 60).padStart(2, "0")} s` : `${t} s`;
}
const noneLeft = () => arld.status && arld.status.questions_left_max === 0;

function showStatus() {
  const s = arld.status;
  $("s-questions").textContent = s.questions_left_max === 0 ? "none left: the agent trains on its own" : `at most ${s.questions_left_max}`;
  showPersonTime();
  $("s-time-left").textContent = s.questions_left_max === 0 ? "0 s" : s.time_left_s === null ? "after your first answer" : `about ${duration(s.time_left_s)}`;
  $("s-step").textContent = `${s.step} / ${s.train_steps}`;
  $("s-episode").textContent = s.episode;
  $("s-budget").textContent = `${s.budget_used} / ${s.budget}`;
  $("s-left").textContent = s.budget - s.budget_used;
  $("s-queries").textContent = s.queries;
  $("s-takeovers").textContent = s.takeovers;
  $("s-eval").textContent = s.last_eval ? `${fmt(s.last_eval[1], 1)} (step ${s.last_eval[0]})` : "–";
  if (s.uncertainty !== null) {
    arld.uncertainty.push([s.step, s.uncertainty, s.threshold]);
    if (arld.uncertainty.length > 300) arld.uncertainty.shift();
  }
  drawUncertainty();
  // The panel says whether questions can still come.
  if (!arld.prompt) showPrompt();
}

function showPrompt() {
  const p = arld.prompt, h = arld.hello, box = $("prompt");
  if (!h) return;
  let text;
  if (arld.ended) { text = arld.ended; box.className = "idle"; }
  else if (arld.handed) { text = arld.handed.message; box.className = arld.handed.stopped ? "stopped" : "idle"; }
  else if (!p && noneLeft()) { text = "No questions left: the agent trains on its own."; box.className = "idle"; }
  else if (!p && arld.takeover.pending) {
    text = `You take over at the agent's next step${arld.paused ? ", when the run goes on" : ""}. T again (or Esc) cancels.`;
    box.className = "takeover";
  }
  else if (!p) { text = "Training runs. When the agent is unsure it asks you here."; box.className = "idle"; }
  else if (p.takeover && p.starts_in) {
    text = "Get ready: you take over in a moment. Hold the key you want; Esc hands back.";
    box.className = "takeover";
  }
  else if (h.fps && p.waits && p.agent_action === null) {
    // A real-time segment in progress when the run was stopped: it goes on after a fresh key and the countdown.
    text = p.takeover
      ? "The run goes on where it stopped, and you still have control: press the key of your next action. Esc hands back."
      : `The run goes on where it stopped, in your segment (${p.steps_left} step${p.steps_left > 1 ? "s" : ""} left): press the key of your next action.`;
    box.className = p.takeover ? "takeover" : "asking";
  }
  else if (p.takeover && p.waits) {
    text = `You take over from here: press the key of your first action (the agent would "${actionName(p.agent_action)}"). ` +
      "Esc hands back.";
    box.className = "takeover";
  }
  else if (p.takeover) {
    text = `You have control: hold a key to act (budget for ${p.steps_left} more step${p.steps_left > 1 ? "s" : ""}). Esc hands back to the agent.`;
    box.className = "takeover";
  }
  else if (p.starts_in) {
    text = `Get ready: your ${p.steps_left} step${p.steps_left > 1 ? "s" : ""} start in a moment. Hold the key you want.`;
    box.className = "running";
  }
  else if (p.agent_action !== null) {
    text = `The agent asks: what would you do? It would "${actionName(p.agent_action)}". ` +
      `You act for ${p.steps_left} step${p.steps_left > 1 ? "s" : ""}.`;
    box.className = "asking";
  } else if (p.undo) {
    text = `Your turn: ${p.steps_left} step${p.steps_left > 1 ? "s" : ""} left in this segment. Backspace undoes your last key.`;
    box.className = "asking";
  } else {
    text = `Your turn: ${p.steps_left} step${p.steps_left > 1 ? "s" : ""} left in this segment.`;
    box.className = p.waits ? "asking" : "running";
  }
  if (p && !controls()) text += " (Another tab answers.)";
  if (replay) text = `Replaying the agent's ${replay.frames.length - 1} steps since your last one… (any key skips)`;
  $("prompt-text").textContent = text;
  document.querySelectorAll("#buttons button").forEach((b) => {
    b.disabled = !p || !controls() || arld.ended !== null || arld.handed !== null || !!replay;
    b.classList.toggle("proposed", ghostAction() === Number(b.dataset.action));
    b.classList.toggle("held", held === Number(b.dataset.action));
  });
  showAxes();
  $("pass").disabled = !p || !(p.waits || p.takeover) || !controls() || arld.ended !== null;
  $("pass").textContent = p && p.takeover ? "Hand back [Esc]" : "Let the agent decide [Esc]";
  const t = $("takeover");
  t.hidden = !h.fps || !controls() || arld.ended !== null || arld.handed !== null || !!(p && p.takeover);
  // Offered only while the agent acts (not in the breath before its question); a request can be cancelled.
  t.disabled = !!p || noneLeft() || !!replay || !(arld.takeover.offered || arld.takeover.pending);
  t.textContent = arld.takeover.pending ? "Cancel take over [T]" : "Take over [T]";
  $("undo").disabled = !p || !p.undo || !controls() || arld.ended !== null || !!replay;
  $("undo").hidden = !!h.fps || !h.undo;
  if (p && p.starts_in && startsAt.id !== p.id) startsAt = { id: p.id, at: performance.now() + p.starts_in * 1000 };
  if (!replay) showObs(p ? p.obs : null, "");
  // A question waiting for this tab shows in the tab's title, also when the tab is in the background.
  document.title = p && p.waits && controls() && !arld.ended ? "● Your turn: the agent asks" : "arld: the agent asks";
}
$("pass").addEventListener("click", () => pass());
$("undo").addEventListener("click", () => undo());

// Real time: the countdown between the person's key and the start of their segment.
let startsAt = { id: null, at: 0 };
setInterval(() => {
  const p = arld.prompt, el = $("start-countdown");
  const left = p && p.starts_in && startsAt.id === p.id ? (startsAt.at - performance.now()) / 1000 : 0;
  el.hidden = !(left > 0) || arld.ended !== null;
  if (left > 0) { el.textContent = `${Math.ceil(left * 2) / 2 >= 1 ? Math.ceil(left) : "Go"}`; arld.countdowns = Math.max(arld.countdowns, p.id); }
}, 50);

// The agent's own steps since the person's last one, played fast (within 1 s, while the run takes its breath before
// the question) before the question; a key skips.
function startReplay(frames) {
  if (!frames.length) return;
  if (replay) stopReplay();
  arld.replaying = true;
  arld.replays.push({ steps: frames.length - 1, last: frames[frames.length - 1] });
  const interval = Math.max(4, Math.min(1000 / 60, 1000 / frames.length));
  replay = { frames, at: 0, live: null, timer: null };
  const tick = () => {
    if (!replay) return;
    if (replay.at >= replay.frames.length) { stopReplay(); return; }
    const f = replay.frames[replay.at++], saved = replay;
    replay = null; // draw it as a live frame
    receive(f);
    replay = saved;
    replay.timer = setTimeout(tick, interval);
  };
  showPrompt();
  tick();
}
function stopReplay() {
  if (!replay) return;
  clearTimeout(replay.timer);
  const live = replay.live;
  replay = null;
  arld.replaying = false;
  if (live) receive(live);
  showPrompt();
}

// Takes back the last key (turn-based, within a segment): the run asks that step again.
function undo() {
  const p = arld.prompt;
  if (!p || !p.undo || !controls() || answered === p.id || replay) return;
  answered = p.id;
  arld.undos++;
  send({ type: "undo", id: p.id });
}

// The person's time: the run's count, and while a question waits (the run is blocked, so no status comes) the
// seconds since it opened, paused time excepted.
let waiting = { id: null, s: 0, last: 0 };
function showPersonTime() {
  const s = arld.status;
  if (!s) return;
  const extra = arld.prompt && waiting.id === arld.prompt.id ? waiting.s : 0;
  $("s-person").textContent = `${duration(s.person_s + extra)} (${s.answered} answered, ${s.keys} ${padState.id === null ? "keys" : "inputs"})`;
}
setInterval(() => {
  const p = arld.prompt, now = performance.now();
  if (!p || !p.waits || arld.ended) { waiting = { id: null, s: 0, last: now }; return; }
  if (waiting.id !== p.id) waiting = { id: p.id, s: 0, last: now };
  if (!arld.paused) waiting.s += (now - waiting.last) / 1000;
  waiting.last = now;
  showPersonTime();
}, 250);

// With a timeout, the seconds left to answer the open question (paused time does not count).
let asked = { id: null, left: 0, last: 0 };
setInterval(() => {
  const p = arld.prompt, h = arld.hello, el = $("countdown"), now = performance.now();
  if (!p || !p.waits || !h || !h.timeout || arld.ended) { el.textContent = ""; return; }
  if (asked.id !== p.id) asked = { id: p.id, left: h.timeout, last: now };
  if (!arld.paused) asked.left -= (now - asked.last) / 1000;
  asked.last = now;
  el.textContent = ` ${Math.max(0, Math.ceil(asked.left))} s left to answer`;
}, 200);

// Real time: takes over from the state the agent is in (the run opens the segment at its next step), only while the
// agent acts; pressed again before the run took it (it waits for a paused run to go on), it cancels the request.
function takeOver() {
  const h = arld.hello;
  if (!h || !h.fps || arld.prompt || !controls() || arld.ended || arld.handed || noneLeft()) return;
  if (arld.takeover.pending) { send({ type: "takeover", cancel: true }); return; }
  if (!arld.takeover.offered) { banner("The agent is about to ask you: its question comes first.", 2500); return; }
  arld.takeovers++;
  send({ type: "takeover" });
}
$("takeover").addEventListener("click", () => takeOver());

// The agent's proposal at the step shown: its test-time action at every step of a segment (`proposal`), or at a
// question its own proposal; null when there is none (no question open, or a replay plays).
function ghostAction() {
  const p = arld.prompt;
  if (!p || replay) return null;
  if (p.proposal !== null && p.proposal !== undefined) return p.proposal;
  return p.agent_action === undefined ? null : p.agent_action;
}

// Real time: after each of the person's segments, how it went (its steps, return and, for a task with a goal,
// landed or crashed, the flag reached), and while the run allows it, a retry from the segment's start state (R):
// the new answers replace the first ones, and both are charged to the budget.
let retryOpen = null; // {id, until, timer}
function showSegment(m) {
  arld.segments.push(m);
  const el = $("segment-line");
  el.hidden = false;
  el.className = m.outcome === "landed" || m.outcome === "reached the flag" ? "landed" : m.outcome === "crashed" ? "crashed" : "";
  const attempt = m.attempt > 1 ? ` (attempt ${m.attempt})` : "";
  $("segment-text").textContent = `Your segment${attempt}: ${m.steps} step${m.steps === 1 ? "" : "s"}, return ${fmt(m["return"], 1)}` +
    (m.outcome ? `: ${m.outcome}.` : ".") + (m.retry_s ? " R plays it again from its start." : "");
  closeRetry();
  if (m.retry_s && controls()) {
    retryOpen = { id: m.id, timer: setTimeout(closeRetry, m.retry_s * 1000) };
    $("retry").disabled = false;
  }
}
function closeRetry() {
  if (retryOpen) clearTimeout(retryOpen.timer);
  retryOpen = null;
  $("retry").disabled = true;
}
function retry() {
  if (!retryOpen || !controls() || arld.ended) return;
  arld.retries++;
  send({ type: "retry", id: retryOpen.id });
  $("segment-text").textContent += " Retrying: press a key when ready.";
  closeRetry();
}
$("retry").addEventListener("click", () => retry());

// Hands the open question (or the person's takeover) back to the agent.
function pass() {
  const p = arld.prompt;
  if (!p && arld.takeover.pending && controls()) { send({ type: "takeover", cancel: true }); return; }
  if (!p || !(p.waits || p.takeover) || !controls() || answered === p.id) return;
  answered = p.id;
  send({ type: "pass", id: p.id });
}
function showPaused() {
  $("pause").textContent = arld.paused ? "Go on" : "Pause";
  document.body.classList.toggle("paused", arld.paused);
  if (arld.paused) banner("Paused: the run and your clock wait."); else banner(null);
}
$("pause").addEventListener("click", () => { if (controls()) send({ type: "pause", paused: !arld.paused }); });
// Real time: watch mode, the agent's own steps at the real-time rate (or back to full speed).
function showWatch() {
  const h = arld.hello, w = $("watch");
  if (!h) return;
  w.hidden = !h.fps;
  w.textContent = arld.watch ? `Full speed [V]` : `Watch at ${h.fps} steps/s [V]`;
  w.classList.toggle("on", arld.watch);
  w.disabled = arld.ended !== null || arld.handed !== null || !controls();
}
$("watch").addEventListener("click", () => { if (controls() && arld.hello && arld.hello.fps) send({ type: "watch", on: !arld.watch }); });

// The end screen: how the run ended (or where it stands when its program has it back) and what the person gave.
// An environment without a solve threshold is neither solved nor not solved.
function showEnd() {
  const o = arld.outcome, box = $("end"), h = arld.hello;
  if (!o) return;
  box.hidden = false;
  const solvable = !!h && h.solve_threshold !== null;
  const stopped = !arld.ended && arld.handed && arld.handed.stopped;
  box.className = stopped ? "stopped" : !solvable ? "trained" : o.solved ? "solved" : "unsolved";
  $("end-title").textContent = stopped ? `Stopped at step ${o.train_steps}`
    : o.solved ? `Solved at step ${o.steps_to_solve} of ${o.train_steps}`
    : solvable ? `Not solved in ${o.train_steps} steps` : `Trained ${o.train_steps} steps`;
  $("end-note").textContent = arld.ended || (arld.handed && arld.handed.message) || "";
  const rows = [
    ["Final score", fmt(o.final_score, 1)],
    ["Questions answered", `${o.answered}` + (o.unanswered ? ` (${o.unanswered} left to the agent)` : "")],
    // (With a gamepad the answers came from its buttons and sticks too.)
    [padState.id === null ? "Keys pressed" : "Keys, buttons and sticks", `${o.keys}` + (o.undone ? ` (and ${o.undone} undone)` : "")],
    ["Takeovers", `${o.takeovers}`],
    ["Your time", `${duration(o.person_s)} (${o.person_s.toFixed(1)} s)`],
    ["Run directory", o.run_dir || "– (not saved)"],
  ];
  const t = $("end-table");
  t.textContent = "";
  for (const [k, v] of rows) {
    const tr = t.insertRow(), th = document.createElement("th");
    th.textContent = k; tr.appendChild(th); tr.insertCell().textContent = v;
  }
}

// Answers the open prompt with `action` (once per prompt); never during a replay or a pause (input then is not an
// answer to a question the person is looking at). `acting`: the gesture is the action itself (an action's key, a
// stick or trigger leaving rest), so a real-time segment starts at once, without a countdown.
function press(action, acting = false) {
  const p = arld.prompt;
  if (!p || !p.waits || !controls() || answered === p.id || replay || arld.paused) return;
  answered = p.id;
  send({ type: "key", id: p.id, action, acting });
}
function hold(action) { held = action; send({ type: "hold", action }); showPrompt(); }
function release(action) { if (held === action) { held = null; send({ type: "hold", action: null }); showPrompt(); } }

function actionOfKey(key) {
  if (!arld.hello) return null;
  const k = key.length === 1 ? key.toLowerCase() : key;
  const i = arld.hello.actions.findIndex((a) => a.keys.includes(k));
  return i < 0 ? null : i;
}
document.addEventListener("keydown", (e) => {
  // A key during a replay only skips it: it never answers a question the person has not seen yet.
  if (replay) { if (!e.repeat) { e.preventDefault(); stopReplay(); } return; }
  if (e.key === "Escape") { pass(); return; }
  if (arld.hello && arld.hello.box) { if (boxKeyDown(e)) return; }
  if (e.key === "Backspace" || ((e.ctrlKey || e.metaKey) && (e.key === "z" || e.key === "Z"))) { e.preventDefault(); undo(); return; }
  if ((e.key === "p" || e.key === "P") && actionOfKey(e.key) === null) { $("pause").click(); return; }
  if ((e.key === "v" || e.key === "V") && actionOfKey(e.key) === null) { if (!e.repeat) $("watch").click(); return; }
  if ((e.key === "t" || e.key === "T") && actionOfKey(e.key) === null) { if (!e.repeat) takeOver(); return; }
  if ((e.key === "r" || e.key === "R") && actionOfKey(e.key) === null) { if (!e.repeat) retry(); return; }
  const a = actionOfKey(e.key);
  if (a === null) return;
  e.preventDefault();
  // Only a fresh press answers: a key held from before the question (or its auto-repeat) never does.
  if (arld.hello.fps) { if (held !== a) hold(a); if (!e.repeat) press(a, true); } else if (!e.repeat) press(a);
});
document.addEventListener("keyup", (e) => {
  if (arld.hello && arld.hello.box) { boxKeyUp(e); return; }
  const a = actionOfKey(e.key);
  if (a !== null && arld.hello.fps) release(a);
});
window.addEventListener("blur", () => { if (held !== null) release(held); axesKeys.clear(); });

// ---- a gamepad (the browser's Gamepad API) ---------------------------------------------------------------
// Discrete actions on buttons: by default the d-pad gives the actions whose keys are arrows (or WASD), the face
// buttons the others in order; Start pauses, Back/Select lets the agent decide. The mapping shows on the page once a
// pad is seen (a pad shows itself to a page at its first button press) and each action's button can be changed
// there; it is kept for this pad in the browser (localStorage).
const PAD_BUTTONS = ["A / Cross", "B / Circle", "X / Square", "Y / Triangle", "LB / L1", "RB / R1", "LT / L2", "RT / R2",
  "Back / Select", "Start", "L3", "R3", "D-pad up", "D-pad down", "D-pad left", "D-pad right", "Home"];
const PAD_BACK = 8, PAD_START = 9;
const padState = { index: null, id: null, map: [], before: [], values: null, rest: null };
arld.pad = null;

function padDefault(actions) {
  const dpad = { ArrowUp: 12, w: 12, ArrowDown: 13, s: 13, ArrowLeft: 14, a: 14, ArrowRight: 15, d: 15 };
  const used = new Set(), map = actions.map((a) => {
    const b = a.keys.map((k) => dpad[k]).find((b) => b !== undefined && !used.has(b));
    if (b !== undefined) used.add(b);
    return b === undefined ? null : b;
  });
  const free = [0, 1, 2, 3, 4, 5, 6, 7, 10, 11].filter((b) => !used.has(b));
  return map.map((b) => (b === null ? free.shift() ?? null : b));
}
function padKey() { return `arld.pad:${padState.id}:${arld.hello.env}`; }
function padSetup() {
  if (!arld.hello || padState.id === null) return;
  if (arld.hello.box) { padAxesSetup(); return; }
  let map = null;
  try { map = JSON.parse(localStorage.getItem(padKey()) || "null"); } catch (e) { map = null; }
  padState.map = Array.isArray(map) && map.length === arld.hello.actions.length ? map : padDefault(arld.hello.actions);
  showPad();
}
function showPad() {
  const box = $("pad");
  if (padState.id === null || !arld.hello) { box.hidden = true; return; }
  if (arld.hello.box) { showPadAxes(); return; }
  box.hidden = false;
  $("pad-name").textContent = padState.id;
  const t = $("pad-map");
  t.textContent = "";
  arld.hello.actions.forEach((a, i) => {
    const tr = t.insertRow(), th = document.createElement("th");
    th.textContent = a.label; tr.appendChild(th);
    const sel = document.createElement("select");
    sel.dataset.action = i;
    sel.add(new Option("none", ""));
    PAD_BUTTONS.forEach((name, b) => { if (b !== PAD_BACK && b !== PAD_START) sel.add(new Option(name, String(b))); });
    sel.value = padState.map[i] === null ? "" : String(padState.map[i]);
    sel.addEventListener("change", () => {
      const b = sel.value === "" ? null : Number(sel.value);
      // A button gives one action: the action that had it gives up its button.
      padState.map = padState.map.map((x, j) => (j === i ? b : x === b ? null : x));
      try { localStorage.setItem(padKey(), JSON.stringify(padState.map)); } catch (e) { /* private mode */ }
      showPad();
    });
    tr.insertCell().appendChild(sel);
  });
  arld.pad = { id: padState.id, map: padState.map.slice() };
}
function padPoll() {
  const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
  const pad = pads.find((p) => p.index === padState.index) || pads[0];
  if (!pad) return;
  if (pad.id !== padState.id) {
    padState.index = pad.index; padState.id = pad.id; padState.before = [];
    padSetup();
  }
  const now = pad.buttons.map((b) => b.pressed || b.value > 0.5), before = padState.before;
  const fresh = (b) => now[b] && !before[b], gone = (b) => !now[b] && before[b];
  padState.before = now;
  if (!arld.hello) return;
  const h = arld.hello;
  if (fresh(PAD_START)) { $("pause").click(); return; }
  if (replay) {
    if (now.some((p, b) => fresh(b))) stopReplay();
    // The sticks are followed during a replay too, so that one moved then is not a gesture when it ends.
    else if (h.box) padAxesPoll(pad, () => false);
    return;
  }
  if (fresh(PAD_BACK)) { pass(); return; }
  if (h.box) { padAxesPoll(pad, fresh); return; }
  padState.map.forEach((b, a) => {
    if (b === null || b === undefined) return;
    if (fresh(b)) { if (h.fps) { if (held !== a) hold(a); press(a, true); } else press(a); }
    else if (gone(b) && h.fps) release(a);
  });
}
setInterval(padPoll, 16);

// ---- continuous controls: actions in a box -----------------------------------------------------------------
// The action is a vector, one number per dimension of the box (`hello.box`: bounds, names, keys). Three controls
// set it, the last one moved wins: keys held push a dimension toward a bound (from the centre to the bound in
// KEY_RAMP_S; released, the dimension goes back to the centre or holds its value, as the person chooses on the
// page), a slider per dimension, and a gamepad's sticks and triggers (mapped per dimension on the page, kept for
// the pad in the browser). Enter (or "Send", or the pad's A button) answers with the vector shown; in real time a
// fresh key (or a stick leaving the centre) answers the opening question too, then the vector held is the action
// of each step (sent to the run whenever it changes).
const KEY_RAMP_S = 0.4, STICK_DEADZONE = 0.1, TRIGGER_REST = 0.1, PAD_A = 0;
const axesKeys = new Set(); // keys held down (their `key` values)
let axes = null; // the vector set now
let axesSent = null; // the vector last sent as held (real time)
const centre = (d) => (arld.hello.box.low[d] + arld.hello.box.high[d]) / 2;
const clampTo = (d, v) => Math.min(arld.hello.box.high[d], Math.max(arld.hello.box.low[d], v));
arld.axes = null;

function axesSetup() {
  const h = arld.hello, el = $("axes");
  el.textContent = "";
  el.hidden = !h.box;
  $("release-mode").hidden = !h.box;
  if (!h.box) return;
  axes = h.box.names.map((_, d) => centre(d));
  h.box.names.forEach((name, d) => {
    const row = document.createElement("label");
    row.className = "axis";
    const title = document.createElement("span");
    const [lo, hi] = h.box.keys[d] || [[], []];
    title.textContent = `${name} [${lo.map(keyName).join("/")} ${hi.map(keyName).join("/")}]`;
    const slider = document.createElement("input");
    Object.assign(slider, { type: "range", min: h.box.low[d], max: h.box.high[d], step: (h.box.high[d] - h.box.low[d]) / 200 });
    slider.dataset.dim = d;
    slider.value = axes[d];
    slider.addEventListener("input", () => setAxis(d, Number(slider.value), "slider"));
    const value = document.createElement("output");
    value.id = `axis-value-${d}`;
    const track = document.createElement("span"), ghost = document.createElement("span");
    track.className = "track";
    ghost.className = "ghost"; ghost.id = `axis-ghost-${d}`; ghost.hidden = true; ghost.title = "the agent's value";
    track.append(slider, ghost);
    row.append(title, track, value);
    el.appendChild(row);
  });
  const sendButton = document.createElement("button");
  sendButton.id = "send-axes";
  sendButton.textContent = "Send [Enter]";
  sendButton.addEventListener("click", () => pressAxes());
  el.appendChild(sendButton);
  showAxes();
}
function axesHelp() {
  const h = arld.hello;
  const centreText = h.box.names.map((n, d) => `${n} ${centre(d)}`).join(", ");
  const keys = "Hold a dimension's keys to push it toward its bound; released, it goes back to the centre (or holds, as chosen below). The sliders set a value directly.";
  return h.fps
    ? `${keys} A fresh key, a pad's stick leaving its dead zone or its trigger pressed starts your segment at once (Enter or the pad's A after a short countdown); then the values shown are the action of each step (nothing touched: ${centreText}). T takes over while the agent acts (T again cancels a request; Esc hands back); V shows its steps at the real-time rate. P pauses.`
    : `${keys} Enter (or Send) takes one step with the values shown. P pauses, Esc lets the agent decide${h.undo ? ", Backspace undoes your last step" : ""}.`;
}
function setAxis(d, v, source) {
  if (!axes) return;
  axes[d] = clampTo(d, v);
  arld.axes = { values: axes.slice(), source };
  showAxes();
  sendHeld();
}
// Real time: the vector held goes to the run whenever it changes.
function sendHeld() {
  const h = arld.hello;
  if (!h || !h.fps || !axes || !controls()) return;
  if (axesSent && axesSent.every((v, d) => v === axes[d])) return;
  axesSent = axes.slice();
  send({ type: "hold", action: axesSent });
}
function showAxes() {
  const h = arld.hello;
  if (!h || !h.box || !axes) return;
  const p = arld.prompt, off = !p || !controls() || arld.ended !== null || arld.handed !== null || !!replay;
  document.querySelectorAll("#axes input[type=range]").forEach((s) => {
    const d = Number(s.dataset.dim);
    if (Number(s.value) !== axes[d]) s.value = axes[d];
    s.disabled = !controls() || arld.ended !== null;
    const g = ghostAction(), ghost = $(`axis-ghost-${d}`);
    const proposed = Array.isArray(g) ? ` (agent: ${Number(g[d]).toFixed(2)})` : "";
    $(`axis-value-${d}`).textContent = `${axes[d].toFixed(2)}${proposed}`;
    // The agent's value on the slider: a ghost mark where it would set the dimension.
    ghost.hidden = !Array.isArray(g);
    if (Array.isArray(g)) ghost.style.left = `${(100 * (clampTo(d, g[d]) - h.box.low[d])) / (h.box.high[d] - h.box.low[d])}%`;
  });
  $("send-axes").disabled = off || !p.waits;
}
// Answers the open question with the vector shown (once per prompt); `acting` as for press().
function pressAxes(acting = false) {
  if (!axes) return;
  const h = arld.hello;
  if (h.fps) { axesSent = null; sendHeld(); }
  press(axes.slice(), acting);
}
// The dimension and direction (-1 toward the lower bound, +1 the upper) of a key, or null.
function axisOfKey(key) {
  const k = key.length === 1 ? key.toLowerCase() : key, b = arld.hello.box;
  for (let d = 0; d < b.keys.length; d++) {
    if (b.keys[d][0].includes(k)) return { d, dir: -1, k };
    if (b.keys[d][1].includes(k)) return { d, dir: 1, k };
  }
  return null;
}
function boxKeyDown(e) {
  if (e.key === "Enter") { e.preventDefault(); if (!e.repeat) pressAxes(); return true; }
  const a = axisOfKey(e.key);
  if (!a) return false;
  e.preventDefault();
  axesKeys.add(a.k);
  // Real time: a fresh key answers the opening question too (the value it pushes toward is held from then on).
  if (arld.hello.fps && !e.repeat) { axesTick(); pressAxes(true); }
  return true;
}
function boxKeyUp(e) {
  const a = axisOfKey(e.key);
  if (!a) return;
  axesKeys.delete(a.k);
  const b = arld.hello.box, still = [...b.keys[a.d][0], ...b.keys[a.d][1]].some((k) => axesKeys.has(k));
  if (!still && $("release-mode").value === "centre") setAxis(a.d, centre(a.d), "keys");
}
// Keys held push their dimension toward its bound, from the centre to the bound in KEY_RAMP_S.
let axesLast = performance.now();
function axesTick() {
  const now = performance.now(), dt = Math.min(0.1, (now - axesLast) / 1000);
  axesLast = now;
  const h = arld.hello;
  if (!h || !h.box || !axes || !axesKeys.size) return;
  h.box.keys.forEach(([lo, hi], d) => {
    const dir = (hi.some((k) => axesKeys.has(k)) ? 1 : 0) - (lo.some((k) => axesKeys.has(k)) ? 1 : 0);
    if (!dir) return;
    const half = (h.box.high[d] - h.box.low[d]) / 2;
    setAxis(d, axes[d] + dir * Math.max(dt, 1 / 60) * half / KEY_RAMP_S, "keys");
  });
}
setInterval(axesTick, 16);

// A pad's sources for a dimension: a stick's axis (-1 to 1, around the centre) or a trigger (0 to 1, from the
// lower bound to the upper).
const PAD_SOURCES = [
  { name: "left stick X", axis: 0 }, { name: "left stick Y", axis: 1 }, { name: "right stick X", axis: 2 },
  { name: "right stick Y", axis: 3 }, { name: "LT / L2 trigger", button: 6 }, { name: "RT / R2 trigger", button: 7 },
];
// The default mapping: the lander's main engine on the right trigger, other dimensions on the sticks in order
// (X, then Y pushed up toward the upper bound).
function padAxesDefault(names) {
  const free = [{ source: 0, invert: false }, { source: 3, invert: true }, { source: 2, invert: false }, { source: 1, invert: true }];
  return names.map((n) => (/engine/.test(n) && n.startsWith("main") ? { source: 5, invert: false } : free.shift() || { source: null, invert: false }));
}
function padAxesSetup() {
  let map = null;
  try { map = JSON.parse(localStorage.getItem(padKey()) || "null"); } catch (e) { map = null; }
  const n = arld.hello.box.names.length;
  padState.map = Array.isArray(map) && map.length === n && map.every((m) => m && "source" in m) ? map : padAxesDefault(arld.hello.box.names);
  padState.values = null;
  padState.rest = null;
  showPad();
}
function showPadAxes() {
  const box = $("pad"), b = arld.hello.box;
  box.hidden = false;
  $("pad-name").textContent = padState.id;
  const t = $("pad-map");
  t.textContent = "";
  b.names.forEach((name, d) => {
    const tr = t.insertRow(), th = document.createElement("th");
    th.textContent = `${name} (${b.low[d]} to ${b.high[d]})`; tr.appendChild(th);
    const sel = document.createElement("select");
    sel.dataset.dim = d;
    sel.add(new Option("none", ""));
    PAD_SOURCES.forEach((s, i) => sel.add(new Option(s.name, String(i))));
    const m = padState.map[d];
    sel.value = m.source === null ? "" : String(m.source);
    const inv = document.createElement("input");
    inv.type = "checkbox"; inv.checked = m.invert; inv.dataset.dim = d; inv.title = "inverted";
    const invLabel = document.createElement("label");
    invLabel.append(inv, " inverted");
    const change = () => {
      padState.map = padState.map.map((x, j) => (j === d ? { source: sel.value === "" ? null : Number(sel.value), invert: inv.checked } : x));
      try { localStorage.setItem(padKey(), JSON.stringify(padState.map)); } catch (e) { /* private mode */ }
      padState.values = null;
      showPad();
    };
    sel.addEventListener("change", change);
    inv.addEventListener("change", change);
    const td = tr.insertCell();
    td.append(sel, invLabel);
  });
  $("pad-help").textContent = "A sends the values shown, Start pauses, Back/Select lets the agent decide. A stick moves around the centre of its dimension, a trigger from its lower bound to its upper. Change a source here; it is kept for this pad.";
  arld.pad = { id: padState.id, map: padState.map.map((m) => ({ ...m })) };
}
// The pad's value for dimension `d` under mapping `m`, or null when it has none.
function padValue(pad, d, m) {
  if (m.source === null) return null;
  const s = PAD_SOURCES[m.source], b = arld.hello.box;
  if (s.button !== undefined) {
    const btn = pad.buttons[s.button];
    const t = btn ? Math.min(1, Math.max(0, btn.value)) : 0, f = m.invert ? 1 - t : t;
    return b.low[d] + f * (b.high[d] - b.low[d]);
  }
  let x = pad.axes[s.axis] || 0;
  if (Math.abs(x) < STICK_DEADZONE) x = 0;
  if (m.invert) x = -x;
  return centre(d) + x * (b.high[d] - b.low[d]) / 2;
}
// Whether the source of mapping `m` is at rest: a stick within its dead zone, a trigger released.
function padAtRest(pad, m) {
  if (m.source === null) return true;
  const s = PAD_SOURCES[m.source];
  if (s.button !== undefined) { const b = pad.buttons[s.button]; return !b || b.value < TRIGGER_REST; }
  return Math.abs(pad.axes[s.axis] || 0) < STICK_DEADZONE;
}
function padAxesPoll(pad, fresh) {
  const values = padState.map.map((m, d) => padValue(pad, d, m));
  const rest = padState.map.map((m) => padAtRest(pad, m));
  const before = padState.values, restBefore = padState.rest;
  padState.values = values;
  padState.rest = rest;
  // The pad sets a dimension when its value changed (so a slider or a key moved last still counts). A pad just
  // seen sets only its triggers: a trigger's rest is its lower bound (a stick's is the centre, as nothing touched).
  values.forEach((v, d) => {
    if (v === null) return;
    if (before ? before[d] !== v : PAD_SOURCES[padState.map[d].source].button !== undefined) setAxis(d, v, "pad");
  });
  // A deliberate gesture answers: A, or a source leaving its rest (a stick its dead zone, a trigger its release),
  // never a release, nor a position held since before the question could be answered (press() ignores input
  // during a replay or a pause, and the positions are followed meanwhile).
  const left = !!restBefore && rest.some((r, d) => restBefore[d] && !r);
  const h = arld.hello, p = arld.prompt;
  if (fresh(PAD_A)) pressAxes();
  else if (h.fps && left && p && p.waits) pressAxes(true);
}
window.addEventListener("gamepadconnected", padPoll);

// ---- drawing the environment ------------------------------------------------------------------------------
const cv = $("env"), ctx = cv.getContext("2d");

// A frame the environment rendered (PNG), drawn to fit the canvas.
let imageSeq = 0;
function showImage(png) {
  const img = new Image(), seq = ++imageSeq;
  img.onload = () => {
    if (seq !== imageSeq) return; // a newer frame came meanwhile
    arld.frame = { image: [img.width, img.height] };
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, cv.width, cv.height);
    const k = Math.min(cv.width / img.width, cv.height / img.height);
    const w = img.width * k, h = img.height * k;
    ctx.drawImage(img, (cv.width - w) / 2, (cv.height - h) / 2, w, h);
  };
  img.src = "data:image/png;base64," + png;
}

// The observation line under the question; a long observation is folded: its first values and how many more.
function showObs(obs, what) {
  if (!obs) { $("obs").textContent = ""; return; }
  const shown = obs.slice(0, OBS_SHOWN).map((v) => v.toFixed(3)).join("  ");
  const more = obs.length > OBS_SHOWN ? `  … (${obs.length - OBS_SHOWN} more of ${obs.length} values)` : "";
  $("obs").textContent = `${what ? what + " " : ""}observation: ${shown}${more}`;
}

// The values of an observation shown at most (in the line under the question, and as rows of the table); the
// rest is folded into a count, so that a large observation (an image, a grid) does not flood the page.
const OBS_SHOWN = 16, OBS_ROWS = 24, OBS_SERIES = 8;

// An environment without a picture: its observation as a table, and a chart of its recent values.
function showTable(labels, obs) {
  arld.frame = { table: labels };
  const t = $("obs-table");
  t.hidden = false;
  t.textContent = "";
  labels.slice(0, OBS_ROWS).forEach((label, i) => {
    const tr = t.insertRow(), th = document.createElement("th");
    th.textContent = label; tr.appendChild(th); tr.insertCell().textContent = obs[i].toFixed(4);
  });
  if (labels.length > OBS_ROWS) {
    const tr = t.insertRow(), th = document.createElement("th");
    th.textContent = "…"; tr.appendChild(th);
    tr.insertCell().textContent = `${labels.length - OBS_ROWS} more of ${labels.length} values`;
  }
  arld.obsHistory.push(obs.slice(0, OBS_SERIES));
  if (arld.obsHistory.length > 200) arld.obsHistory.shift();
  const colours = ["#2563eb", "#dc2626", "#16a34a", "#ca8a04", "#7c3aed", "#0891b2", "#db2777", "#4b5563"];
  chart(cv, labels.slice(0, OBS_SERIES).map((_, i) => ({ color: colours[i % colours.length], points: arld.obsHistory.map((o, k) => [k, o[i]]) })),
    { empty: "no observation yet", xname: "question" });
}

function draw() {
  const g = arld.frame && arld.frame.geometry;
  if (arld.frame && (arld.frame.image || arld.frame.table)) return;
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = "#ffffff";
  ctx.fillRect(0, 0, cv.width, cv.height);
  if (!g) return;
  const ghost = ghostAction();
  ({ CartPole: drawCartPole, Acrobot: drawAcrobot, MountainCar: drawMountainCar, LunarLander: drawLander, Pendulum: drawPendulum })[g.kind](g, ghost);
  // The agent's proposal named in the canvas' bottom left corner (the drawings above outline it where they can).
  if (ghost !== null) {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.font = "14px system-ui"; ctx.textAlign = "left"; ctx.fillStyle = "#6d28d9";
    ctx.fillText(`agent: ${actionName(ghost)} (outlined)`, 10, cv.height - 10);
  }
}
// A ghost's outline: dashed, violet, lightly filled.
const GHOST_FILL = "rgba(167, 139, 250, 0.25)", GHOST_LINE = "#a78bfa";
function dashed(draw) { ctx.save(); ctx.setLineDash([5, 4]); draw(); ctx.restore(); }

// A world-to-canvas map: `scale` pixels per unit, world point (ox, oy) at canvas (px, py), y up.
function view(scale, ox, oy, px, py) {
  return { s: scale, x: (x) => px + (x - ox) * scale, y: (y) => py - (y - oy) * scale };
}
function poly(v, pts, fill, stroke) {
  ctx.beginPath();
  pts.forEach(([x, y], i) => (i ? ctx.lineTo(v.x(x), v.y(y)) : ctx.moveTo(v.x(x), v.y(y))));
  ctx.closePath();
  if (fill) { ctx.fillStyle = fill; ctx.fill(); }
  if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = 1.5; ctx.stroke(); }
}

function drawCartPole(g) {
  const W = cv.width, world = 2 * g.x_threshold * 1.1;
  const v = view(W / world, 0, 0, W / 2, 280);
  ctx.strokeStyle = "#111827"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(v.x(-g.x_threshold), v.y(0)); ctx.lineTo(v.x(g.x_threshold), v.y(0)); ctx.stroke();
  for (const e of [-g.x_threshold, g.x_threshold]) {
    ctx.fillStyle = "#dc2626"; ctx.fillRect(v.x(e) - 2, v.y(0) - 12, 4, 24);
  }
  const cw = 0.4, ch = 0.24, axle = ch * 0.25;
  poly(v, [[g.x - cw / 2, 0], [g.x + cw / 2, 0], [g.x + cw / 2, ch], [g.x - cw / 2, ch]], "#1f2937");
  const bx = g.x, by = ch - axle, L = g.pole_length, pw = 0.04;
  const dx = Math.sin(g.theta), dy = Math.cos(g.theta), nx = dy * pw, ny = -dx * pw;
  poly(v, [[bx - nx, by - ny], [bx + nx, by + ny], [bx + nx + dx * L, by + ny + dy * L], [bx - nx + dx * L, by - ny + dy * L]], "#ca9862", "#8b5a2b");
  ctx.fillStyle = "#818cd8"; ctx.beginPath(); ctx.arc(v.x(bx), v.y(by), 5, 0, 2 * Math.PI); ctx.fill();
}

function drawAcrobot(g) {
  const [l1, l2] = g.link_lengths, bound = l1 + l2 + 0.2;
  const v = view(Math.min(cv.width, cv.height) / (2 * bound), 0, 0, cv.width / 2, cv.height / 2);
  ctx.strokeStyle = "#111827"; ctx.lineWidth = 1; ctx.setLineDash([6, 4]);
  ctx.beginPath(); ctx.moveTo(v.x(-bound), v.y(1)); ctx.lineTo(v.x(bound), v.y(1)); ctx.stroke();
  ctx.setLineDash([]);
  const p1 = [l1 * Math.sin(g.theta1), -l1 * Math.cos(g.theta1)];
  const p2 = [p1[0] + l2 * Math.sin(g.theta1 + g.theta2), p1[1] - l2 * Math.cos(g.theta1 + g.theta2)];
  ctx.lineCap = "round"; ctx.lineWidth = 0.2 * v.s; ctx.strokeStyle = "#0e7490";
  ctx.beginPath(); ctx.moveTo(v.x(0), v.y(0)); ctx.lineTo(v.x(p1[0]), v.y(p1[1])); ctx.lineTo(v.x(p2[0]), v.y(p2[1])); ctx.stroke();
  ctx.fillStyle = "#eab308";
  for (const [x, y] of [[0, 0], p1]) { ctx.beginPath(); ctx.arc(v.x(x), v.y(y), 0.1 * v.s, 0, 2 * Math.PI); ctx.fill(); }
}

function drawMountainCar(g, ghost) {
  const xs = g.hill.map((p) => p[0]), lo = Math.min(...xs), hi = Math.max(...xs);
  const v = view(cv.width / (hi - lo), lo, 0, 0, cv.height - 20);
  poly(v, [...g.hill, [hi, -0.1], [lo, -0.1]], "#e5e7eb", null);
  ctx.strokeStyle = "#111827"; ctx.lineWidth = 2; ctx.beginPath();
  g.hill.forEach(([x, y], i) => (i ? ctx.lineTo(v.x(x), v.y(y)) : ctx.moveTo(v.x(x), v.y(y)))); ctx.stroke();
  const fy = 0.45 * Math.sin(3 * g.goal) + 0.55;
  ctx.beginPath(); ctx.moveTo(v.x(g.goal), v.y(fy)); ctx.lineTo(v.x(g.goal), v.y(fy) - 50); ctx.stroke();
  poly(v, [[g.goal, fy + 50 / v.s], [g.goal, fy + 35 / v.s], [g.goal + 25 / v.s, fy + 42 / v.s]], "#eab308");
  ctx.save();
  ctx.translate(v.x(g.position), v.y(g.height)); ctx.rotate(-g.angle);
  ctx.fillStyle = "#1f2937"; ctx.fillRect(-20, -22, 40, 16);
  ctx.fillStyle = "#6b7280";
  for (const wx of [-12, 12]) { ctx.beginPath(); ctx.arc(wx, -5, 5, 0, 2 * Math.PI); ctx.fill(); }
  // Continuous actions: the force of the last step, an arrow along the slope (60 px at full force).
  if (g.force !== undefined && g.force !== 0) {
    const dir = Math.sign(g.force), from = dir * 22, to = from + g.force * 60;
    arrow(from, -14, to, -14, "#f97316");
  }
  // The agent's push, above the car: its force (continuous), or its direction (discrete: left, none, right).
  if (ghost !== null) {
    const f = Array.isArray(ghost) ? Math.max(-1, Math.min(1, ghost[0])) : ghost - 1;
    if (f !== 0) dashed(() => arrow(Math.sign(f) * 22, -34, Math.sign(f) * 22 + f * 60, -34, GHOST_LINE));
  }
  ctx.restore();
  if (g.force !== undefined) gauge([`force ${g.force.toFixed(2)}`]);
}

// An arrow from (x0, y0) to (x1, y1) in canvas units.
function arrow(x0, y0, x1, y1, colour) {
  const a = Math.atan2(y1 - y0, x1 - x0), head = 9;
  ctx.strokeStyle = colour; ctx.fillStyle = colour; ctx.lineWidth = 4; ctx.lineCap = "round";
  ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(x1 + Math.cos(a) * head, y1 + Math.sin(a) * head);
  ctx.lineTo(x1 + Math.cos(a + 2.4) * head, y1 + Math.sin(a + 2.4) * head);
  ctx.lineTo(x1 + Math.cos(a - 2.4) * head, y1 + Math.sin(a - 2.4) * head); ctx.closePath(); ctx.fill();
  ctx.lineCap = "butt";
}
// Lines of text in the canvas' top left corner (what the last step applied).
function gauge(lines, colour = "#111827") {
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.font = "14px system-ui"; ctx.fillStyle = colour; ctx.textAlign = "left";
  lines.forEach((l, i) => ctx.fillText(l, 10, 20 + 18 * i));
}

function drawPendulum(g, ghost) {
  // The pivot at the centre; theta from upright, counter-clockwise (as Gymnasium draws it).
  const cx = cv.width / 2, cy = cv.height / 2, L = Math.min(cv.width, cv.height) * 0.38;
  const tip = [cx - L * Math.sin(g.theta), cy - L * Math.cos(g.theta)];
  ctx.strokeStyle = "#e5e7eb"; ctx.lineWidth = 1; ctx.setLineDash([4, 4]);
  ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx, cy - L - 20); ctx.stroke(); ctx.setLineDash([]);
  ctx.strokeStyle = "#cc4d4d"; ctx.lineWidth = 0.14 * L; ctx.lineCap = "round";
  ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(tip[0], tip[1]); ctx.stroke(); ctx.lineCap = "butt";
  ctx.fillStyle = "#111827"; ctx.beginPath(); ctx.arc(cx, cy, 0.05 * L, 0, 2 * Math.PI); ctx.fill();
  // The torque of the last step: an arc around the pivot, counter-clockwise for a positive torque, its sweep
  // growing with the torque's size (three quarters of a turn at the bound).
  if (g.torque !== 0) {
    const r = 0.3 * L, sweep = (Math.abs(g.torque) / g.max_torque) * 1.5 * Math.PI, start = -Math.PI / 2;
    const ccw = g.torque > 0, end = ccw ? start - sweep : start + sweep;
    ctx.strokeStyle = "#f97316"; ctx.lineWidth = 5;
    ctx.beginPath(); ctx.arc(cx, cy, r, start, end, ccw); ctx.stroke();
    const ex = cx + r * Math.cos(end), ey = cy + r * Math.sin(end), t = ccw ? end - Math.PI / 2 : end + Math.PI / 2;
    arrow(ex - Math.cos(t) * 2, ey - Math.sin(t) * 2, ex + Math.cos(t) * 6, ey + Math.sin(t) * 6, "#f97316");
  }
  // The agent's torque: the same arc, dashed, further out.
  const gt = Array.isArray(ghost) ? Math.max(-g.max_torque, Math.min(g.max_torque, ghost[0])) : 0;
  if (gt !== 0) {
    const r = 0.45 * L, sweep = (Math.abs(gt) / g.max_torque) * 1.5 * Math.PI, start = -Math.PI / 2;
    const ccw = gt > 0, end = ccw ? start - sweep : start + sweep;
    dashed(() => { ctx.strokeStyle = GHOST_LINE; ctx.lineWidth = 4; ctx.beginPath(); ctx.arc(cx, cy, r, start, end, ccw); ctx.stroke(); });
  }
  gauge([`torque ${g.torque.toFixed(2)} (of ±${g.max_torque})`]);
}

function drawLander(g, ghost) {
  // Gymnasium's viewport, with 1.5 m of sky above it: the lander starts at its top edge.
  const scale = Math.min(cv.width / g.width, cv.height / (g.height + 1.5));
  const v = view(scale, g.width / 2, 0, cv.width / 2, cv.height);
  ctx.fillStyle = "#0b1020"; ctx.fillRect(0, 0, cv.width, cv.height);
  // The surface, continued flat to the canvas' edges.
  const t = g.terrain, edge = g.width;
  poly(v, [[-edge, 0], [-edge, t[0][1]], ...t, [2 * edge, t[t.length - 1][1]], [2 * edge, 0]], "#d1d5db", "#9ca3af");
  for (const x of g.helipad_x) {
    ctx.strokeStyle = "#f9fafb"; ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.moveTo(v.x(x), v.y(g.helipad_y)); ctx.lineTo(v.x(x), v.y(g.helipad_y + 50 / 30)); ctx.stroke();
    poly(v, [[x, g.helipad_y + 50 / 30], [x, g.helipad_y + 40 / 30], [x + 25 / 30, g.helipad_y + 45 / 30]], "#eab308");
  }
  const hull = g.hull, cx = hull.reduce((a, p) => a + p[0], 0) / hull.length, cy = hull.reduce((a, p) => a + p[1], 0) / hull.length;
  // The hull's frame: "up" from the bottom edge (points 2-3) to the top edge (points 0, 5); "right" along the bottom.
  const right = norm([hull[3][0] - hull[2][0], hull[3][1] - hull[2][1]]), up = [-right[1], right[0]];
  const flame = (at, dir, len, fill = "#f97316", line = "#fde047") => {
    const side = [-dir[1] * 0.12, dir[0] * 0.12];
    poly(v, [[at[0] + side[0], at[1] + side[1]], [at[0] - side[0], at[1] - side[1]], [at[0] + dir[0] * len, at[1] + dir[1] * len]], fill, line);
  };
  const local = (x, y) => [cx + right[0] * x + up[0] * y, cy + right[1] * x + up[1] * y];
  // The agent's engines, outlined: a continuous action as the lander reads it (the main engine fires above 0 at
  // 50-100%, a side engine beyond ±0.5), a discrete one at full length.
  if (ghost !== null) {
    const [gm, gs] = Array.isArray(ghost)
      ? [ghost[0] > 0 ? (Math.min(ghost[0], 1) + 1) / 2 : 0, Math.abs(ghost[1]) > 0.5 ? Math.sign(ghost[1]) * Math.min(Math.abs(ghost[1]), 1) : 0]
      : [ghost === 2 ? 1 : 0, ghost === 1 ? -1 : ghost === 3 ? 1 : 0];
    dashed(() => {
      if (gm > 0) flame(local(0, -0.45), [-up[0], -up[1]], 0.9 * gm + 0.3, GHOST_FILL, GHOST_LINE);
      if (gs < 0) flame(local(0.6, 0.25), right, 0.5 * -gs + 0.2, GHOST_FILL, GHOST_LINE);
      if (gs > 0) flame(local(-0.6, 0.25), [-right[0], -right[1]], 0.5 * gs + 0.2, GHOST_FILL, GHOST_LINE);
    });
  }
  // Continuous actions: each flame as long as its engine's throttle (the main engine 50-100%, a side engine's
  // signed: negative is the left engine's); discrete: the engine that fired, at full length.
  const [main, side] = g.throttle || [g.engine === 2 ? 1 : 0, g.engine === 1 ? -1 : g.engine === 3 ? 1 : 0];
  if (main > 0) flame(local(0, -0.45), [-up[0], -up[1]], 0.9 * main);
  if (side < 0) flame(local(0.6, 0.25), right, 0.5 * -side);
  if (side > 0) flame(local(-0.6, 0.25), [-right[0], -right[1]], 0.5 * side);
  g.legs.forEach((leg, i) => poly(v, leg, g.leg_contact[i] ? "#22c55e" : "#7c3aed", "#4c1d95"));
  poly(v, hull, "#8b5cf6", "#4c1d95");
  if (g.throttle) {
    const pct = (x) => `${Math.round(Math.abs(x) * 100)}%`;
    gauge([`main engine ${main > 0 ? pct(main) : "off"}`, `side engine ${side < 0 ? "left " + pct(side) : side > 0 ? "right " + pct(side) : "off"}`], "#f9fafb");
  }
}
function norm([x, y]) { const n = Math.hypot(x, y) || 1; return [x / n, y / n]; }

// ---- charts -----------------------------------------------------------------------------------------------
function chart(canvas, series, opts) {
  const c = canvas.getContext("2d"), W = canvas.width, H = canvas.height, pad = 6;
  c.fillStyle = "#ffffff"; c.fillRect(0, 0, W, H);
  const pts = series.flatMap((s) => s.points).filter((p) => p[1] !== null && isFinite(p[1]));
  if (!pts.length) { c.fillStyle = "#9ca3af"; c.fillText(opts.empty, 10, H / 2); return; }
  let [x0, x1] = opts.xrange || [Math.min(...pts.map((p) => p[0])), Math.max(...pts.map((p) => p[0]))];
  let y0 = Math.min(...pts.map((p) => p[1])), y1 = Math.max(...pts.map((p) => p[1]));
  if (opts.zero) y0 = Math.min(0, y0);
  if (x1 <= x0) x1 = x0 + 1;
  // A flat series: a narrow band around its value (not ±1 around a value near 0).
  if (y1 <= y0) { const d = Math.abs(y0) / 2 || 0.5; y1 += d; y0 -= d; }
  const X = (x) => pad + ((x - x0) / (x1 - x0)) * (W - 2 * pad), Y = (y) => H - pad - 10 - ((y - y0) / (y1 - y0)) * (H - 2 * pad - 10);
  for (const s of series) {
    c.strokeStyle = s.color; c.lineWidth = 1.5; c.setLineDash(s.dash || []); c.beginPath();
    let started = false;
    for (const [x, y] of s.points) {
      if (y === null || !isFinite(y)) { started = false; continue; }
      started ? c.lineTo(X(x), Y(y)) : c.moveTo(X(x), Y(y));
      started = true;
    }
    c.stroke();
  }
  c.setLineDash([]); c.fillStyle = "#6b7280"; c.font = "10px system-ui";
  const label = (y) => (Math.abs(y) >= 100 || y === 0 ? y.toFixed(0) : y.toPrecision(3));
  c.fillText(label(y1), pad + 2, pad + 8); c.fillText(label(y0), pad + 2, H - pad - 12);
  // The x axis: its first and last values and what it counts.
  const xl = [`${opts.xname || "step"} ${Math.round(x0)}`, `${Math.round(x1)}`];
  c.textAlign = "left"; c.fillText(xl[0], pad + 2, H - 1);
  c.textAlign = "right"; c.fillText(xl[1], W - pad, H - 1);
  c.textAlign = "left";
  canvas.dataset.xlabels = xl.join(" … ");
}
function drawUncertainty() {
  const u = arld.uncertainty;
  chart($("uchart"), [
    { color: "#2563eb", points: u.map((p) => [p[0], p[1]]) },
    { color: "#dc2626", points: u.map((p) => [p[0], p[2]]) },
  ], { empty: "no uncertainty yet" });
}
function drawCurve() {
  const h = arld.hello, s = arld.status, c = arld.curve;
  const range = [0, s ? s.train_steps : Math.max(1, ...c.map((p) => p[0]))];
  const series = [{ color: "#16a34a", points: c }];
  if (h && c.length) series.push({ color: "#dc2626", dash: [4, 3], points: [[range[0], h.solve_threshold], [range[1], h.solve_threshold]] });
  chart($("curve"), series, { empty: "no evaluation yet", xrange: range });
}
function drawCharts() { drawUncertainty(); drawCurve(); }

drawCharts();
connect();
