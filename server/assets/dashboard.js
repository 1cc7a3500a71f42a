// Tessera dashboard: jobs with progress bars, frame thumbnails as they finish, workers and
// their current task; kept live by server-sent events. No framework, no CDN.
"use strict";

const API = "/api/v1";
// A client token, when the server needs one: open the page as /#token=SECRET once.
const token = (() => {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) localStorage.setItem("tessera-token", decodeURIComponent(m[1]));
  return localStorage.getItem("tessera-token") || "";
})();
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "access_token=" + encodeURIComponent(token) : url;

async function get(path) {
  const res = await fetch(API + path, { headers: token ? { Authorization: "Bearer " + token } : {} });
  if (!res.ok) throw new Error(path + ": " + res.status + " " + (await res.text()));
  return res.json();
}

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

function jobCard(job) {
  let card = document.querySelector(`.job[data-job-id="${job.id}"]`);
  if (!card) {
    card = el("article", "job");
    card.dataset.jobId = job.id;
    const title = el("div", "title");
    title.append(el("span", "name"), el("span", "state"), el("span", "stats"));
    const bar = el("div", "bar");
    bar.append(el("div"));
    const stuck = el("p", "stuck");
    stuck.hidden = true;
    const failures = el("ul", "failures");
    failures.hidden = true;
    card.append(title, bar, stuck, failures, el("div", "frames"));
    const jobs = document.getElementById("jobs");
    jobs.prepend(card);
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
  const stuck = card.querySelector(".stuck");
  stuck.hidden = !job.stuck;
  stuck.textContent = job.stuck ? "Stuck: " + job.stuck : "";
  showFailures(card, job);
  document.getElementById("no-jobs").hidden = true;
  return card;
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

function frameThumb(jobId, frame) {
  const card = document.querySelector(`.job[data-job-id="${jobId}"]`);
  if (!card) return;
  const strip = card.querySelector(".frames");
  let fig = strip.querySelector(`figure[data-frame="${frame.frame}"]`);
  if (frame.state !== "done" && !fig) return;
  if (!fig) {
    fig = el("figure");
    fig.dataset.frame = frame.frame;
    const img = el("img");
    img.alt = "frame " + frame.frame;
    fig.append(img, el("figcaption", null, pad4(frame.frame)));
    // Keep thumbnails in frame order.
    const after = [...strip.children].find((f) => Number(f.dataset.frame) > frame.frame);
    strip.insertBefore(fig, after || null);
  }
  fig.dataset.state = frame.state;
  fig.querySelector("img").src = withToken(`${API}/jobs/${jobId}/frames/${frame.frame}/png?v=${frame.tasks_done}`);
}

function workerRow(w) {
  const body = document.querySelector("#workers tbody");
  let row = body.querySelector(`tr[data-worker-id="${w.id}"]`);
  if (!row) {
    row = el("tr");
    row.dataset.workerId = w.id;
    for (let i = 0; i < 6; i++) row.append(el("td"));
    body.append(row);
  }
  const cells = row.children;
  cells[0].textContent = w.name;
  cells[1].textContent = w.threads;
  cells[2].textContent = w.version;
  cells[3].textContent = w.current_task
    ? `job ${w.current_job} · frame ${w.current_frame} · task ${w.current_task.task_id}`
    : "idle";
  cells[4].textContent = w.tasks_done;
  cells[5].textContent = new Date(w.last_seen_ms).toLocaleTimeString();
  row.className = w.online ? "online" : "offline";
  document.getElementById("no-workers").hidden = true;
}

async function loadAll() {
  const [{ jobs }, { workers }] = await Promise.all([get("/jobs"), get("/workers")]);
  for (const job of jobs.slice().reverse()) jobCard(job);
  for (const w of workers) workerRow(w);
  await Promise.all(jobs.map(async (job) => {
    const { frames } = await get(`/jobs/${job.id}/frames`);
    for (const f of frames) frameThumb(job.id, f);
  }));
}

function listen() {
  const live = document.getElementById("live");
  const source = new EventSource(withToken(API + "/events"));
  source.onopen = () => { live.textContent = "live"; live.className = "on"; };
  source.onerror = () => { live.textContent = "reconnecting"; live.className = "off"; };
  source.addEventListener("job", (e) => jobCard(JSON.parse(e.data).job));
  source.addEventListener("frame", (e) => {
    const d = JSON.parse(e.data);
    frameThumb(d.job_id, d.frame);
  });
  source.addEventListener("worker", (e) => workerRow(JSON.parse(e.data).worker));
  source.addEventListener("job_deleted", (e) => {
    const id = JSON.parse(e.data).job_id;
    document.querySelector(`.job[data-job-id="${id}"]`)?.remove();
  });
  // Missed events: read everything again.
  source.addEventListener("lagged", () => loadAll().catch(showError));
}

function showError(err) {
  const p = document.getElementById("error");
  p.textContent = String(err);
  p.hidden = false;
}

listen();
loadAll().then(() => { document.body.dataset.loaded = "true"; }, showError);
