// Tessera dashboard: jobs with progress, their frames coloured by state with thumbnails,
// controls (pause, resume, cancel, retry, priority, clone, delete), workers with what each
// is doing, its speed and its recent failures; kept live by server-sent events. No
// framework, no CDN. Built for 1,000 frames a job and 100 workers: every element is found
// through a map, frame grids are filled only when opened, thumbnails load lazily.
"use strict";

const API = "/api/v1";
const TOKEN_KEY = "tessera-token";

// The client token, when the server needs one: asked for on the first 401 and kept for
// this browser session; `/#token=SECRET` still works once (and leaves the address bar).
let token = (() => {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    sessionStorage.setItem(TOKEN_KEY, decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
  return sessionStorage.getItem(TOKEN_KEY) || "";
})();
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "access_token=" + encodeURIComponent(token) : url;

class Unauthorized extends Error {}

async function call(method, path, body) {
  const headers = token ? { Authorization: "Bearer " + token } : {};
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const res = await fetch(API + path, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  if (res.status === 401) {
    askForToken();
    throw new Unauthorized("the server wants the client token");
  }
  if (!res.ok) {
    const text = await res.text();
    let message = text;
    try { message = JSON.parse(text).message || text; } catch (_) { /* not JSON */ }
    throw new Error(`${method} ${path}: ${message}`);
  }
  return res.status === 204 ? null : res.json();
}
const get = (path) => call("GET", path);

function el(tag, cls, text) {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
}

function duration(s) {
  if (s == null || !isFinite(s)) return "–";
  s = Math.round(s);
  if (s < 60) return s + " s";
  if (s < 3600) return Math.floor(s / 60) + " min " + (s % 60) + " s";
  return Math.floor(s / 3600) + " h " + Math.floor((s % 3600) / 60) + " min";
}

function rate(x) {
  if (!x) return "–";
  if (x >= 1e6) return (x / 1e6).toFixed(2) + " M";
  if (x >= 1e3) return (x / 1e3).toFixed(1) + " k";
  return x.toFixed(0);
}

function pad4(n) { return String(n).padStart(4, "0"); }

// ---- token ----

function askForToken() {
  const form = document.getElementById("login");
  if (!form.hidden) return;
  form.hidden = false;
  document.getElementById("live").textContent = "signed out";
  document.getElementById("token-input").focus();
}

document.getElementById("login").addEventListener("submit", (e) => {
  e.preventDefault();
  token = document.getElementById("token-input").value.trim();
  sessionStorage.setItem(TOKEN_KEY, token);
  e.target.hidden = true;
  start();
});

// ---- jobs ----

const cards = new Map();   // job id -> card element
const jobs = new Map();    // job id -> the latest JobStatus

const OPEN = ["queued", "running", "paused"];
// Which controls a job in each state offers (retry also while stuck).
const CONTROLS = [
  ["pause", "Pause", (j) => j.state === "queued" || j.state === "running"],
  ["resume", "Resume", (j) => j.state === "paused"],
  ["retry", "Retry failed", (j) => j.state === "failed" || !!j.stuck],
  ["cancel", "Cancel", (j) => OPEN.includes(j.state)],
  ["clone", "Clone", () => true],
  ["delete", "Delete", () => true],
  ["watch", "Notify me", (j) => OPEN.includes(j.state)],
];

function jobCard(job) {
  const previous = jobs.get(job.id);
  jobs.set(job.id, job);
  let card = cards.get(job.id);
  if (!card) {
    card = el("article", "job");
    card.dataset.jobId = job.id;
    const title = el("div", "title");
    title.append(el("span", "name"), el("span", "state"), el("span", "stats"));
    const bar = el("div", "bar");
    bar.append(el("div"));
    const actions = el("div", "actions");
    for (const [action, label] of CONTROLS) {
      const b = el("button", null, label);
      b.dataset.action = action;
      actions.append(b);
    }
    const priority = el("label", "priority", "Priority ");
    const input = el("input");
    input.type = "number";
    input.min = -1000;
    input.max = 1000;
    // A value being typed is not overwritten by the job's updates until it is set.
    input.addEventListener("input", () => { input.dataset.edited = "true"; });
    const set = el("button", null, "Set");
    set.dataset.action = "priority";
    priority.append(input, set);
    actions.append(priority);
    const stuck = el("p", "stuck");
    stuck.hidden = true;
    const failures = el("ul", "failures");
    failures.hidden = true;
    const panel = el("details", "frames-panel");
    panel.append(el("summary", null, "Frames"), flipbook(job.id), el("div", "frames"));
    // Small jobs show their frames at once; a big one's grid is made when opened.
    panel.open = job.frames_total <= 100;
    panel.addEventListener("toggle", () => {
      if (panel.open) loadFrames(job.id).catch(showError);
    });
    card.append(title, bar, actions, stuck, failures, panel);
    actions.addEventListener("click", (e) => {
      const action = e.target.dataset && e.target.dataset.action;
      if (action) act(job.id, action, card).catch(showError);
    });
    cards.set(job.id, card);
    document.getElementById("jobs").prepend(card);
    if (panel.open) loadFrames(job.id).catch(showError);
  }
  card.querySelector(".name").textContent = "#" + job.id + " " + job.name;
  const state = card.querySelector(".state");
  state.textContent = job.state;
  state.className = "state " + job.state;
  card.dataset.state = job.state;
  const pct = Math.round(job.progress * 1000) / 10;
  card.querySelector(".bar > div").style.width = pct + "%";
  card.dataset.progress = String(job.progress);
  card.querySelector(".stats").textContent =
    `${pct}% · frames ${job.frames_done}/${job.frames_total} · tasks ${job.tasks.done}/` +
    `${job.tasks.queued + job.tasks.leased + job.tasks.done + job.tasks.failed + job.tasks.cancelled}` +
    ` · ${rate(job.samples_per_second)} samples/s · ETA ${duration(job.eta_seconds)}`;
  for (const [action, , shown] of CONTROLS) {
    card.querySelector(`button[data-action="${action}"]`).hidden = !shown(job);
  }
  const priority = card.querySelector(".priority input");
  if (priority.dataset.edited !== "true") priority.value = job.spec.priority;
  const stuck = card.querySelector(".stuck");
  const why = job.stuck ? "Stuck: " + job.stuck : job.waiting ? "Waiting: " + job.waiting : "";
  stuck.hidden = !why;
  stuck.textContent = why;
  showFailures(card, job);
  const video = card.querySelector(".flipbook .video");
  video.hidden = !job.video;
  if (job.video) video.href = withToken(`${API}/jobs/${job.id}/video`);
  notifyIfEnded(card, previous, job);
  document.getElementById("no-jobs").hidden = true;
  return card;
}

async function act(id, action, card) {
  const job = jobs.get(id);
  let answer;
  switch (action) {
    case "pause": case "resume": case "cancel": case "retry":
      answer = await call("POST", `/jobs/${id}/${action}`);
      break;
    case "priority": {
      const input = card.querySelector(".priority input");
      answer = await call("POST", `/jobs/${id}/priority`, { priority: Number(input.value) });
      delete input.dataset.edited;
      break;
    }
    case "clone": {
      // The same scene and settings under a name of its own.
      const spec = { ...job.spec };
      delete spec.name;
      answer = await call("POST", "/jobs", spec);
      break;
    }
    case "delete":
      if (!confirm(`Delete job #${id} ${job.name} with every frame it made?`)) return;
      await call("DELETE", `/jobs/${id}`);
      removeJob(id);
      return;
    case "watch":
      card.dataset.watched = "true";
      card.querySelector('button[data-action="watch"]').textContent = "Watching";
      if ("Notification" in window && Notification.permission === "default") {
        await Notification.requestPermission();
      }
      return;
  }
  if (answer) jobCard(answer);
}

// A browser notification when a watched job ends.
function notifyIfEnded(card, previous, job) {
  if (card.dataset.watched !== "true" || !previous || OPEN.includes(job.state)) return;
  if (!OPEN.includes(previous.state)) return;
  card.dataset.watched = "false";
  card.dataset.notified = job.state;
  if ("Notification" in window && Notification.permission === "granted") {
    new Notification(`Tessera: job #${job.id} ${job.name} is ${job.state}`, {
      body: `frames ${job.frames_done}/${job.frames_total}` + (job.stuck ? " · " + job.stuck : ""),
    });
  }
}

function removeJob(id) {
  cards.get(id)?.remove();
  cards.delete(id);
  jobs.delete(id);
  frameCells.delete(id);
  frameLoads.delete(id);
}

// Why a job's attempts failed, grouped by reason; read again only when the count changes.
function showFailures(card, job) {
  const list = card.querySelector(".failures");
  if (card.dataset.attemptsFailed === String(job.attempts_failed)) return;
  card.dataset.attemptsFailed = String(job.attempts_failed);
  if (!job.attempts_failed) {
    list.hidden = true;
    list.replaceChildren();
    return;
  }
  get(`/jobs/${job.id}/failures`).then(({ groups }) => {
    list.replaceChildren(...groups.map((g) => el("li", null,
      `${g.attempts} failed attempt(s) of ${g.tasks} task(s) on ${g.workers.join(", ")}` +
      ` (${g.kind === "expired" ? "lease expired" : "reported"}): ${g.reason}`)));
    list.hidden = groups.length === 0;
  }).catch(showError);
}

// ---- frames ----

const frameCells = new Map();  // job id -> Map(frame number -> figure)
const frameLoads = new Map();  // job id -> the promise of its grid

// Fills a job's frame grid once; every caller gets the same promise.
function loadFrames(id) {
  if (!frameCells.has(id)) {
    frameCells.set(id, new Map());
    frameLoads.set(id, buildGrid(id).catch((e) => {
      frameCells.delete(id);
      frameLoads.delete(id);
      throw e;
    }));
  }
  return frameLoads.get(id);
}
async function buildGrid(id) {
  const { frames } = await get(`/jobs/${id}/frames`);
  const strip = cards.get(id)?.querySelector(".frames");
  if (!strip) return;
  const cells = frameCells.get(id);
  const fragment = document.createDocumentFragment();
  for (const f of frames) {
    const fig = el("figure");
    fig.dataset.frame = f.frame;
    fig.append(el("figcaption", null, pad4(f.frame)));
    cells.set(f.frame, fig);
    fragment.append(fig);
    frameCell(id, f);
  }
  strip.replaceChildren(fragment);
  const scrub = cards.get(id).querySelector(".flipbook input");
  scrub.max = Math.max(0, frames.length - 1);
  showFlip(id);
}

// ---- flipbook: the job's previews as an animation, at its fps ----

// The player above a job's frame grid: a picture, play/pause, a scrubber over the frames,
// what the shown frame is, and the job's MP4 once it is encoded.
function flipbook(jobId) {
  const book = el("div", "flipbook");
  const screen = el("div", "screen");
  const img = el("img");
  img.alt = "";
  screen.append(img, el("p", "pending"));
  const play = el("button", null, "Play");
  play.dataset.flip = "play";
  const scrub = el("input");
  scrub.type = "range";
  scrub.min = 0;
  scrub.max = 0;
  scrub.value = 0;
  scrub.addEventListener("input", () => showFlip(jobId));
  play.addEventListener("click", () => togglePlay(jobId));
  const video = el("a", "video", "Download MP4");
  video.hidden = true;
  video.download = `job-${jobId}.mp4`;
  book.append(screen, play, scrub, el("span", "flip-frame"), video);
  return book;
}

const players = new Map();  // job id -> interval of a playing flipbook

function togglePlay(jobId) {
  const book = cards.get(jobId)?.querySelector(".flipbook");
  if (!book) return;
  const button = book.querySelector("button");
  if (players.has(jobId)) {
    clearInterval(players.get(jobId));
    players.delete(jobId);
    button.textContent = "Play";
    return;
  }
  const fps = jobs.get(jobId)?.spec.fps || 24;
  const scrub = book.querySelector("input");
  players.set(jobId, setInterval(() => {
    scrub.value = Number(scrub.value) >= Number(scrub.max) ? 0 : Number(scrub.value) + 1;
    showFlip(jobId);
  }, 1000 / Math.min(fps, 60)));
  button.textContent = "Pause";
}

// Shows the scrubber's frame: its preview once it has one, else what it is waiting for.
function showFlip(jobId) {
  const book = cards.get(jobId)?.querySelector(".flipbook");
  const cells = frameCells.get(jobId);
  if (!book || !cells) return;
  const figures = [...cells.values()];
  const fig = figures[Number(book.querySelector("input").value)];
  if (!fig) return;
  const thumb = fig.querySelector("img");
  const img = book.querySelector(".screen img");
  const pending = book.querySelector(".pending");
  const caption = `frame ${pad4(fig.dataset.frame)} · ${fig.dataset.state}`;
  book.querySelector(".flip-frame").textContent = caption;
  book.dataset.frame = fig.dataset.frame;
  if (thumb) {
    if (img.getAttribute("src") !== thumb.getAttribute("src")) img.src = thumb.getAttribute("src");
    img.hidden = false;
    pending.hidden = true;
  } else {
    img.hidden = true;
    pending.hidden = false;
    pending.textContent = `frame ${pad4(fig.dataset.frame)}: not rendered yet (${fig.dataset.state})`;
  }
}

function frameCell(jobId, frame) {
  const fig = frameCells.get(jobId)?.get(frame.frame);
  if (!fig) return;
  fig.dataset.state = frame.state;
  fig.title = `frame ${frame.frame}: ${frame.state}` + (frame.failure ? ` (${frame.failure})` : "");
  // A thumbnail once a pass or the frame is in; it changes as passes land, and once more
  // when the frame is denoised.
  const assembled = frame.state === "done" || frame.state === "denoising";
  if (assembled || (frame.state === "rendering" && frame.tasks_done > 0)) {
    let img = fig.querySelector("img");
    if (!img) {
      img = el("img");
      img.alt = "frame " + frame.frame;
      img.loading = "lazy";
      fig.prepend(img);
    }
    const src = withToken(
      `${API}/jobs/${jobId}/frames/${frame.frame}/png?v=${frame.tasks_done}-${frame.state}`);
    if (img.getAttribute("src") !== src) img.src = src;
  }
  const book = cards.get(jobId)?.querySelector(".flipbook");
  if (book && book.dataset.frame === String(frame.frame)) showFlip(jobId);
}

// ---- workers ----

const rows = new Map();  // worker id -> row
const WORKER_COLUMNS = 9;

function workerRow(w) {
  let row = rows.get(w.id);
  if (!row) {
    row = el("tr");
    row.dataset.workerId = w.id;
    for (let i = 0; i < WORKER_COLUMNS; i++) row.append(el("td"));
    const clear = el("button", null, "Clear");
    clear.dataset.action = "clear";
    clear.title = "its machine is repaired: give it work again";
    clear.addEventListener("click", () => {
      call("POST", `/workers/${w.id}/clear`).then(workerRow, showError);
    });
    row.dataset.clear = "";
    row.lastChild.append(el("span"), clear);
    rows.set(w.id, row);
    document.querySelector("#workers tbody").append(row);
  }
  const cells = row.children;
  cells[0].textContent = w.name;
  cells[1].textContent = w.threads;
  // The steps after rendering it takes, after its version.
  const steps = [w.denoiser && "denoises", w.encoder && "encodes"].filter(Boolean);
  cells[2].textContent = [w.version, ...steps].join(" · ");
  cells[2].title = [w.denoiser, w.encoder].filter(Boolean).join("; ");
  cells[3].textContent = w.current_task
    ? `job ${w.current_job} · frame ${w.current_frame} · task ${w.current_task.task_id}`
    : "idle";
  cells[4].textContent = w.tasks_done;
  cells[5].textContent = w.samples_per_second ? rate(w.samples_per_second) + " samples/s" : "–";
  cells[6].textContent = w.recent_failures ? `${w.recent_failures}: ${w.last_failure}` : "–";
  cells[7].textContent = new Date(w.last_seen_ms).toLocaleTimeString();
  const status = w.quarantined ? "quarantined: " + w.quarantined : w.suspect ? "suspect" : "ok";
  cells[8].firstChild.textContent = status;
  cells[8].querySelector("button").hidden = !w.quarantined;
  row.className = (w.online ? "online" : "offline") + (w.quarantined ? " quarantined" : "");
  document.getElementById("no-workers").hidden = true;
}

// ---- loading and the live stream ----

async function loadAll() {
  const [{ jobs: list }, { workers }] = await Promise.all([get("/jobs"), get("/workers")]);
  for (const job of list.slice().reverse()) jobCard(job);
  for (const w of workers) workerRow(w);
  for (const id of [...cards.keys()]) {
    if (!list.some((j) => j.id === id)) removeJob(id);
  }
  // Loaded means the open grids too.
  await Promise.all([...cards].filter(([, card]) => card.querySelector(".frames-panel").open)
    .map(([id]) => loadFrames(id)));
}

let source = null;

function listen() {
  source?.close();
  const live = document.getElementById("live");
  source = new EventSource(withToken(API + "/events"));
  source.onopen = () => { live.textContent = "live"; live.className = "on"; };
  source.onerror = () => { live.textContent = "reconnecting"; live.className = "off"; };
  source.addEventListener("job", (e) => jobCard(JSON.parse(e.data).job));
  source.addEventListener("frame", (e) => {
    const d = JSON.parse(e.data);
    frameCell(d.job_id, d.frame);
  });
  source.addEventListener("worker", (e) => workerRow(JSON.parse(e.data).worker));
  source.addEventListener("job_deleted", (e) => removeJob(JSON.parse(e.data).job_id));
  // Missed events: read everything again, the open frame grids too.
  source.addEventListener("lagged", () => {
    loadAll().catch(showError);
    for (const [id, card] of cards) {
      if (card.querySelector(".frames-panel").open) {
        frameCells.delete(id);
        frameLoads.delete(id);
        loadFrames(id).catch(showError);
      }
    }
  });
}

function showError(err) {
  if (err instanceof Unauthorized) return;
  const p = document.getElementById("error");
  p.textContent = String(err.message || err);
  p.hidden = false;
  setTimeout(() => { p.hidden = true; }, 10000);
}

function start() {
  listen();
  loadAll().then(() => { document.body.dataset.loaded = "true"; }, showError);
}

start();
