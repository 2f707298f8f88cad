// The station's page: signs in with a token, follows the daemon's live stream (/api/live),
// sends the operator's commands as the control socket's requests (/api/CLASS) with the
// session's CSRF token, shows the job queue (/api/queue-list) and lists the history
// (/api/scans). Every text from the daemon is
// set as text, never as markup.
"use strict";

const $ = (id) => document.getElementById(id);
const page = { csrf: null, role: null, source: null, retry: null, downSince: null, rows: new Map(), scan: null, status: null, queue: null, queueKey: null, queueTimer: null };

function text(id, value) { $(id).textContent = value; }

function setLink(state, words) {
  const l = $("link");
  l.dataset.state = state;
  l.textContent = words;
}

function fmtNum(v, digits) {
  return (v === null || v === undefined) ? "–" : Number(v).toPrecision(digits || 4);
}

function fmtTime(iso) {
  if (!iso) return "";
  const d = new Date(iso);
  return isNaN(d) ? iso : d.toLocaleString();
}

function fmtDuration(s) {
  if (s === null || s === undefined) return "–";
  s = Math.max(0, Math.round(s));
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = s % 60;
  return (h ? h + " h " : "") + (h || m ? m + " min " : "") + sec + " s";
}

async function api(path, options) {
  const o = Object.assign({ credentials: "same-origin", headers: {} }, options || {});
  if (o.method === "POST") {
    o.headers["content-type"] = "application/json";
    if (page.csrf) o.headers["x-csrf-token"] = page.csrf;
  }
  const r = await fetch(path, o);
  let body = null;
  try { body = await r.json(); } catch (e) { body = null; }
  return { status: r.status, body: body };
}

// Signing in and out.

function showLogin(message) {
  stopStream();
  if (page.queueTimer) { clearInterval(page.queueTimer); page.queueTimer = null; }
  $("main").hidden = true;
  $("logout").hidden = true;
  $("login").hidden = false;
  text("who", "");
  text("login-error", message || "");
  setLink("connecting", "signed out");
}

function signedIn(s) {
  page.csrf = s.csrf || null;
  page.role = s.role;
  $("login").hidden = true;
  $("main").hidden = false;
  $("logout").hidden = !page.csrf;
  text("who", s.user + (s.role === "view" ? " (view only)" : ""));
  $("controls").hidden = s.role !== "operate";
  document.body.classList.toggle("viewer", s.role !== "operate");
  connect();
  loadHistory();
  loadQueue();
  if (!page.queueTimer) page.queueTimer = setInterval(loadQueue, 10000);
}

async function checkSession() {
  try {
    const r = await api("/api/session");
    if (r.status === 200) { signedIn(r.body); return "in"; }
    if (r.status === 401) { showLogin(""); return "out"; }
    return "down";
  } catch (e) {
    return "down";
  }
}

$("login-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const token = $("token").value;
  $("token").value = "";
  try {
    const r = await api("/login", { method: "POST", body: JSON.stringify({ token: token }) });
    if (r.status === 200) signedIn(r.body);
    else text("login-error", (r.body && r.body.message) || ("sign-in failed (" + r.status + ")"));
  } catch (e) {
    text("login-error", "the station does not answer; try again when it is up");
  }
});

$("logout").addEventListener("click", async () => {
  await api("/logout", { method: "POST" }).catch(() => null);
  page.csrf = null;
  showLogin("signed out");
});

// The live stream, and what the page says while the daemon is away.

function stopStream() {
  if (page.source) { page.source.close(); page.source = null; }
  if (page.retry) { clearTimeout(page.retry); page.retry = null; }
}

function connect() {
  stopStream();
  const es = new EventSource("/api/live");
  page.source = es;
  es.onopen = () => {
    page.downSince = null;
    setLink("live", "live");
  };
  es.onerror = () => {
    es.close();
    if (page.source !== es) return;
    page.source = null;
    if (!page.downSince) page.downSince = new Date();
    setLink("down", "daemon not reachable since " + page.downSince.toLocaleTimeString() + "; retrying");
    page.retry = setTimeout(reconnect, 2000);
  };
  es.addEventListener("scan", (e) => onScan(JSON.parse(e.data)));
  es.addEventListener("rows", (e) => onRows(JSON.parse(e.data)));
  es.addEventListener("profile", (e) => drawProfile(JSON.parse(e.data)));
  es.addEventListener("result", (e) => onResult(JSON.parse(e.data)));
  es.addEventListener("status", (e) => onStatus(JSON.parse(e.data)));
}

async function reconnect() {
  page.retry = null;
  const s = await checkSession();
  if (s === "down") {
    setLink("down", "daemon not reachable since " + page.downSince.toLocaleTimeString() + "; retrying");
    page.retry = setTimeout(reconnect, 2000);
  }
}

// The status.

function onStatus(v) {
  const s = v.status;
  page.status = s;
  const st = $("state");
  st.textContent = s.state;
  st.dataset.state = s.state;
  text("since", v.since ? "since " + fmtTime(v.since) : "");
  text("reason", s.reason || "");
  text("scan-id", s.scan_id || "–");
  const running = s.scan_id !== null && s.scan_id !== undefined;
  const k = running ? (s.current_line || Math.min(s.lines_done + 1, s.lines_total)) : null;
  text("line", running ? "line " + k + " of " + s.lines_total : "–");
  $("line").dataset.k = running ? k : "";
  $("line").dataset.n = running ? s.lines_total : "";
  text("lines-done", running ? "(" + s.lines_done + " on disk)" : "");
  $("lines-done").dataset.done = running ? s.lines_done : "";
  const p = $("progress");
  p.max = Math.max(1, s.lines_total);
  p.value = running ? s.lines_done : 0;
  if (s.eta_s !== null && s.eta_s !== undefined && running) {
    const end = new Date(Date.now() + s.eta_s * 1000);
    text("eta", fmtDuration(s.eta_s) + " (done about " + end.toLocaleTimeString() + ")");
  } else {
    text("eta", "–");
  }
  text("instrument", s.instrument);
  text("stage", s.stage);
  text("fault", v.last_fault ? v.last_fault.reason + " (" + fmtTime(v.last_fault.at) + ")" : "none");
  text("last-stop", s.last_stop ? (s.last_stop.scan_id || "start") + ": " + s.last_stop.status + " — " + s.last_stop.reason : "–");
  showJob();
  const key = JSON.stringify([s.queue || null, s.state, s.scan_id || null]);
  if (key !== page.queueKey) { page.queueKey = key; loadQueue(); }
  const paused = s.state === "paused" || s.state === "pausing";
  $("pause").disabled = !(s.state === "scanning" || s.state === "suspended" || s.state === "starting");
  $("resume").disabled = !paused;
  $("abort").disabled = s.state === "idle" || s.state === "waiting";
  if ($("abort").disabled) $("abort-confirm").hidden = true;
}

// Commands: the control socket's requests.

async function command(cls, body, replyId) {
  const reply = $(replyId || "reply");
  reply.dataset.class = "pending";
  reply.textContent = cls + "…";
  try {
    const r = await api("/api/" + cls, { method: "POST", body: JSON.stringify(body || {}) });
    const m = r.body || {};
    reply.dataset.class = m.class || "error";
    reply.dataset.command = cls;
    reply.textContent = m.class === "ack" ? cls + ": " + m.detail : cls + " refused: " + (m.message || ("status " + r.status));
    if (r.status === 401) showLogin(m.message);
  } catch (e) {
    reply.dataset.class = "error";
    reply.textContent = cls + " not sent: the daemon is not reachable";
  }
  if (cls.startsWith("queue") || cls === "ready") loadQueue();
}

$("pause").addEventListener("click", () => command("pause"));
$("resume").addEventListener("click", () => command("resume"));
$("abort").addEventListener("click", () => { $("abort-confirm").hidden = false; });
$("abort-no").addEventListener("click", () => { $("abort-confirm").hidden = true; });
$("abort-yes").addEventListener("click", () => { $("abort-confirm").hidden = true; command("abort"); });
$("start-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const body = {
    specimen: $("specimen").value, operator: $("operator").value,
    notes: $("notes").value, mode: $("mode").value,
  };
  const recipe = $("start-recipe").value.trim();
  if (recipe) body.recipe = recipe;
  command("start", body);
});

// The job queue: the jobs waiting, the one running and the last ones finished.

const FINISHED_SHOWN = 10;

function who(peer) {
  if (!peer) return "–";
  if (peer.web) return peer.web.user;
  return "uid " + peer.uid + " (control socket)";
}

function jobState(j) {
  if (j.state === "queued") {
    if (!j.needs_loading) return "waiting its turn";
    return j.loaded ? "waiting its turn, specimen loaded" : "waits for its specimen to be loaded";
  }
  if (j.state === "running") return "running" + (j.scan_id ? ": " + j.scan_id : "");
  return j.outcome + (j.verdict ? ", " + j.verdict : "") + (j.scan_id ? " (" + j.scan_id + ")" : "") + " — " + j.reason;
}

function jobButton(label, id, cls, onClick) {
  const b = document.createElement("button");
  b.textContent = label;
  b.id = id;
  b.className = "operate" + (cls ? " " + cls : "");
  b.addEventListener("click", onClick);
  return b;
}

async function loadQueue() {
  let r;
  try { r = await api("/api/queue-list"); } catch (e) { return; }
  const card = $("queue-card");
  if (r.status !== 200 || !r.body || r.body.class !== "queue") { card.hidden = true; page.queue = null; showJob(); return; }
  card.hidden = false;
  const q = r.body;
  page.queue = q;
  $("queue-held").hidden = !q.held;
  text("queue-held-why", q.held ? "The queue is stopped: " + q.held + " " : "");
  const open = q.jobs.filter((j) => j.state !== "finished");
  const done = q.jobs.filter((j) => j.state === "finished").slice(-FINISHED_SHOWN).reverse();
  const body = $("queue").tBodies[0];
  body.textContent = "";
  for (const j of open.concat(done)) {
    const tr = document.createElement("tr");
    tr.dataset.job = j.id;
    tr.dataset.state = j.state;
    const cell = (t) => { const td = document.createElement("td"); td.textContent = t; tr.append(td); return td; };
    cell(String(j.id));
    cell(j.recipe.name);
    cell(j.specimen || "–");
    const st = cell(jobState(j));
    st.className = "job-state";
    if (j.verdict) st.dataset.verdict = j.verdict;
    cell(who(j.added_by));
    const act = cell("");
    if (j.state === "queued") {
      if (j.needs_loading && !j.loaded) act.append(jobButton("Specimen loaded", "ready-" + j.id, "", () => command("ready", { job: j.id }, "queue-reply")));
      act.append(jobButton("Remove", "remove-" + j.id, "danger", () => command("queue-remove", { job: j.id }, "queue-reply")));
    }
    body.append(tr);
  }
  $("queue-empty").hidden = open.length > 0;
  showJob();
}

function showJob() {
  const s = page.status, q = page.queue;
  const running = s && s.queue && s.queue.running;
  const j = running && q ? q.jobs.find((x) => x.id === running) : null;
  let t = running ? "job " + running + (j ? ": recipe " + j.recipe.name + ", specimen " + (j.specimen || "–") : "") : "none";
  if (s && s.queue) {
    t += "; " + s.queue.queued + " waiting";
    if (s.queue.held) t += "; the queue is stopped";
  }
  text("job", t);
  $("job").dataset.job = running || "";
}

$("queue-continue").addEventListener("click", () => command("queue-continue", {}, "queue-reply"));
$("queue-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const body = {
    recipe: $("queue-recipe").value.trim(), specimen: $("queue-specimen").value,
    operator: $("queue-operator").value, notes: $("queue-notes").value,
    needs_loading: $("queue-loading").checked,
  };
  const y = $("queue-y").value;
  if (y !== "") body.y_start_mm = Number(y);
  command("queue-add", body, "queue-reply");
});

// The last line's profile: the envelope of its heights.

function drawProfile(p) {
  const c = $("profile"), g = c.getContext("2d");
  const W = c.width, H = c.height, L = 50, R = 10, T = 10, B = 30;
  g.clearRect(0, 0, W, H);
  const lo = p.min_um.filter((v) => v !== null), hi = p.max_um.filter((v) => v !== null);
  if (!lo.length) return;
  const zmin = Math.min(...lo), zmax = Math.max(...hi), span = (zmax - zmin) || 1;
  const n = p.min_um.length;
  const x = (i) => L + (W - L - R) * (n > 1 ? i / (n - 1) : 0.5);
  const y = (z) => T + (H - T - B) * (1 - (z - zmin) / span);
  g.fillStyle = "#1d4ed8";
  g.strokeStyle = "#1d4ed8";
  g.beginPath();
  for (let i = 0; i < n; i++) {
    if (p.max_um[i] === null) continue;
    g.moveTo(x(i), y(p.max_um[i]));
    g.lineTo(x(i), y(p.min_um[i]) + 0.5);
  }
  g.stroke();
  g.fillStyle = "#333";
  g.font = "12px sans-serif";
  g.fillText(zmax.toPrecision(3) + " µm", 2, T + 10);
  g.fillText(zmin.toPrecision(3) + " µm", 2, H - B);
  g.fillText("0", L, H - 10);
  g.fillText(fmtNum(p.length_mm, 3) + " mm", W - R - 60, H - 10);
  c.dataset.index = p.index;
  text("profile-caption", "line " + (p.index + 1) + " at y = " + fmtNum(p.y_mm, 6) + " mm, " + p.points + " points (the band spans each pixel's lowest and highest point)");
}

// The height map, a row per committed line.

function onScan(h) {
  page.scan = h;
  page.rows = new Map();
  drawMap();
}

function onRows(rows) {
  for (const r of rows) page.rows.set(r.index, r);
  drawMap();
}

function colour(t) {
  // Dark blue through teal to yellow.
  const stops = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  const f = Math.min(0.9999, Math.max(0, t)) * (stops.length - 1), i = Math.floor(f), u = f - i;
  const a = stops[i], b = stops[i + 1];
  return [0, 1, 2].map((k) => Math.round(a[k] + (b[k] - a[k]) * u));
}

function drawMap() {
  const c = $("map"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const total = Math.max(page.scan ? page.scan.lines_total : 0, page.rows.size, 1);
  c.dataset.rows = page.rows.size;
  c.dataset.scan = page.scan ? page.scan.scan_id : "";
  let zmin = Infinity, zmax = -Infinity;
  for (const r of page.rows.values()) for (const v of r.values) if (v !== null) { zmin = Math.min(zmin, v); zmax = Math.max(zmax, v); }
  if (page.rows.size && zmax > zmin) {
    const cols = Math.max(...Array.from(page.rows.values(), (r) => r.values.length));
    const img = g.createImageData(cols, total);
    for (const r of page.rows.values()) {
      if (r.index >= total) continue;
      r.values.forEach((v, j) => {
        const o = (r.index * cols + j) * 4;
        if (v === null) return;
        const [R, G, B] = colour((v - zmin) / (zmax - zmin));
        img.data[o] = R; img.data[o + 1] = G; img.data[o + 2] = B; img.data[o + 3] = 255;
      });
    }
    const off = document.createElement("canvas");
    off.width = cols; off.height = total;
    off.getContext("2d").putImageData(img, 0, 0);
    g.imageSmoothingEnabled = false;
    g.drawImage(off, 0, 0, c.width, c.height);
  }
  const id = page.scan ? page.scan.scan_id : "";
  text("map-caption", page.rows.size
    ? id + ": " + page.rows.size + " of " + total + " lines, heights " + zmin.toPrecision(3) + " to " + zmax.toPrecision(3) + " µm (x across, lines down)"
    : (id ? id + ": no line yet" : "no scan yet"));
}

// The last scan's result.

function onResult(r) {
  const box = $("result");
  box.textContent = "";
  const head = document.createElement("div");
  const v = document.createElement("span");
  v.id = "verdict";
  v.className = "verdict";
  v.dataset.verdict = r.verdict || "";
  v.textContent = r.verdict ? r.verdict : "no specification given, no verdict";
  const job = (r.recipe ? ", recipe " + r.recipe : "") + (r.job ? ", job " + r.job : "");
  head.append(r.scan_id + " (" + r.state + ", " + r.lines_done + " of " + r.lines_planned + " lines" + job + "): ", v);
  box.append(head);
  if (r.verdict_summary) {
    const s = document.createElement("div");
    s.textContent = r.verdict_summary;
    box.append(s);
  }
  const m = document.createElement("div");
  m.textContent = "Ra (mean of the lines) " + fmtNum(r.ra_mean_um) + " µm, Sa " + fmtNum(r.sa_um) + " µm";
  box.append(m);
  if (r.report_html) {
    const a = document.createElement("a");
    a.href = "/scans/" + encodeURIComponent(r.scan_id) + "/report.html";
    a.target = "_blank";
    a.textContent = "report";
    box.append(a);
  }
  const ul = $("warnings");
  ul.textContent = "";
  for (const w of (r.warning_texts || [])) {
    const li = document.createElement("li");
    li.textContent = w;
    ul.append(li);
  }
  box.dataset.scan = r.scan_id;
  loadHistory();
}

// The history.

async function loadHistory() {
  let r;
  try { r = await api("/api/scans"); } catch (e) { return; }
  if (r.status !== 200) return;
  const body = $("history").tBodies[0];
  body.textContent = "";
  text("history-notes", r.body.notes.join(" ") + (r.body.total > r.body.scans.length ? " The newest " + r.body.scans.length + " of " + r.body.total + " scans." : ""));
  for (const s of r.body.scans) {
    const tr = document.createElement("tr");
    const cell = (t, cls) => { const td = document.createElement("td"); td.textContent = t; if (cls) td.className = cls; tr.append(td); return td; };
    cell(s.scan_id);
    cell(s.state + (s.lines_done === s.lines_planned ? "" : " " + s.lines_done + "/" + s.lines_planned));
    cell(s.recipe || "–");
    cell(s.specimen || "–");
    cell(s.verdict || "–");
    cell(fmtNum(s.ra_mean_um), "num");
    cell(fmtNum(s.sa_um), "num");
    cell(s.warnings === null || s.warnings === undefined ? "–" : String(s.warnings), "num");
    const files = cell("");
    for (const f of s.files) {
      const a = document.createElement("a");
      a.href = "/scans/" + encodeURIComponent(s.scan_id) + "/" + encodeURIComponent(f.name);
      a.textContent = f.name;
      if (f.name.endsWith(".html")) a.target = "_blank";
      files.append(a, " ");
    }
    body.append(tr);
  }
}

checkSession().then((s) => {
  if (s === "down") {
    page.downSince = new Date();
    showLogin("");
    setLink("down", "daemon not reachable; retrying");
    page.retry = setTimeout(reconnect, 2000);
  }
});
