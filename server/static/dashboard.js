// The dashboard's main view: sign-in, messages, the rig, sweeps and their live plot, recordings, campaigns,
// upload. Plain JavaScript, no build step. Everything the page shows from the server is escaped (esc).
"use strict";
const $ = id => document.getElementById(id);
const esc = t => String(t ?? "").replace(/[&<>"']/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"})[c]);
const pct = x => (100 * x).toFixed(0) + " %";
const when = s => new Date(s * 1000).toLocaleString(undefined, {dateStyle: "short", timeStyle: "medium"});

// -- sign-in: a link http://host:8000/#token=... keeps the token (in this browser's storage) and removes it
// from the address bar; fragments never reach the server. The token is never shown again: the page shows
// the role and a fingerprint of it (GET /api/session).
const TOKEN_KEY = "shakeid-token";
function tokenFromLink() {  // on load, and when such a link is opened in a tab that shows the page already
  const t = new URLSearchParams(location.hash.slice(1)).get("token");
  if (t) { localStorage.setItem(TOKEN_KEY, t); history.replaceState(null, "", location.pathname); }
  return !!t;
}
tokenFromLink();
const tok = () => localStorage.getItem(TOKEN_KEY) || "";
let session = null;  // {role, fingerprint} once the token is accepted

class ApiError extends Error { constructor(status, msg) { super(msg); this.status = status; } }

async function api(method, path, body, raw) {
  const headers = {"Authorization": "Bearer " + tok()};
  if (body !== undefined && !raw) headers["Content-Type"] = "application/json";
  const r = await fetch(path, {method, headers, body: raw ? body : body === undefined ? undefined : JSON.stringify(body)});
  if (r.status === 401) { signOut("the token was refused: sign in again"); throw new ApiError(401, "not signed in"); }
  const data = r.headers.get("content-type")?.includes("json") ? await r.json() : await r.blob();
  if (!r.ok) throw new ApiError(r.status, problem(data, r.status));
  return data;
}
function problem(data, status) {  // an API error as one line: its detail, or each field's complaint
  const d = data && data.detail;
  if (typeof d === "string") return d;
  if (Array.isArray(d)) return d.map(e => `${(e.loc || []).slice(1).join(".")}: ${e.msg}`).join("; ");
  return `HTTP ${status}`;
}
/** An object URL for a file the API serves (figures, recordings): fetched with the token in a header,
 *  so no address in the page carries it. */
async function blobUrl(path) { return URL.createObjectURL(await api("GET", path)); }

// -- messages: kept until the operator dismisses them (the refresh loop never touches them)
function say(text, kind = "info") {
  const div = document.createElement("div");
  div.className = "msg " + kind;
  div.innerHTML = `<time>${new Date().toLocaleTimeString()}</time><span></span><button class="dismiss" title="dismiss">✕</button>`;
  div.querySelector("span").textContent = text;
  div.querySelector("button").onclick = () => { div.remove(); dismissAll(); };
  $("messages").prepend(div);
  dismissAll();
}
function dismissAll() {  // a "dismiss all" button once there are several messages
  const box = $("messages"), n = box.querySelectorAll(".msg").length;
  let all = $("dismiss-all");
  if (n < 2) { if (all) all.remove(); return; }
  if (!all) {
    all = document.createElement("button"); all.id = "dismiss-all"; all.textContent = "dismiss all messages";
    all.onclick = () => { box.innerHTML = ""; };
  }
  box.append(all);
}
// an API refusal as a message; its detail often names the action already ("sweep refused: ..."): no repeat
const fail = what => e => { if (e.status !== 401) say(e.message.startsWith(what) ? e.message : `${what}: ${e.message}`, "error"); };

async function signIn() {
  try { session = await api("GET", "/api/session"); }
  catch (e) { if (e.status !== 401) say("cannot reach the service: " + e.message, "error"); return; }
  $("session").innerHTML = `signed in as <b>${esc(session.role)}</b> <span class="muted">(token ${esc(session.fingerprint)}…)</span> <a href="#" id="signout">sign out</a>`;
  $("signout").onclick = ev => { ev.preventDefault(); signOut("signed out"); };
  document.body.classList.toggle("viewer", session.role !== "operator");
  $("login").hidden = true;
  route();
}
function signOut(why) {
  localStorage.removeItem(TOKEN_KEY); session = null;
  $("session").textContent = ""; $("rig").textContent = "not signed in"; $("rig").className = "rig"; $("login").hidden = false; $("home").hidden = $("recording").hidden = $("campaign").hidden = true;
  if (why) say(why, "error");
}
$("login-form").onsubmit = ev => {
  ev.preventDefault(); localStorage.setItem(TOKEN_KEY, $("token").value.trim()); $("token").value = ""; signIn();
};

// -- pages: # is the main view, #/recording/<id> one recording's page, #/campaign/<id> a campaign's (frf.js)
function route() {
  if (!session) return;
  const m = location.hash.match(/^#\/recording\/([0-9a-f]{12})$/), c = location.hash.match(/^#\/campaign\/([0-9a-f]{12})$/);
  $("home").hidden = !!(m || c); $("recording").hidden = !m; $("campaign").hidden = !c;
  if (!c) openCampaign = null;
  if (m) showRecording(m[1]); else if (c) { openRecording = null; showCampaign(c[1]); } else { openRecording = null; refresh(); }
}
window.addEventListener("hashchange", () => tokenFromLink() ? signIn() : route());

// -- the rig: its state line is rewritten by every refresh, so it never shows a stale state
// The stop goes first to the rig controller's stop listener (GET /api/health's stop_url: a port of its own,
// where no viewer traffic waits), and to this server's own route when that does not answer in time or refuses.
let stopUrl = null;
const STOP_LISTENER_TIMEOUT_MS = 2000;
const learnStopUrl = () => fetch("/api/health").then(r => r.json()).then(h => { stopUrl = h.stop_url || null; }).catch(() => {});
learnStopUrl();
async function emergencyStop() {
  if (stopUrl) {
    try {
      const r = await fetch(stopUrl, {method: "POST", headers: {"Authorization": "Bearer " + tok()},
                                      signal: AbortSignal.timeout(STOP_LISTENER_TIMEOUT_MS)});
      if (r.ok) return await r.json();
    } catch (e) { /* not reached: the web server's route below */ }
  } else learnStopUrl();  // a rig controller attached after the page loaded: its listener for the next press
  return api("POST", "/api/rig/estop");
}
$("estop").onclick = () => emergencyStop()
  .then(r => say("EMERGENCY STOP sent" + (r.aborted_sweep ? `: sweep ${r.aborted_sweep} aborted` : ""), "error"))
  .catch(fail("emergency stop NOT confirmed (use the hardware stop)")).finally(refresh);
$("reset").onclick = () => api("POST", "/api/rig/reset").then(r => say(`rig reset: ${r.state}`))
  .catch(fail("reset refused")).finally(refresh);
function showRig(r) {
  const el = $("rig");
  if (!r) { el.textContent = "rig controller not reachable"; el.className = "rig down"; return; }
  const p = r.plc;
  el.className = "rig " + (p.reachable ? p.state : "down");
  el.textContent = !p.reachable ? "PLC not reachable" :
    `PLC ${p.state}${p.fault && p.fault !== "none" ? " (" + p.fault + ")" : ""} · ${p.frequency_hz.toFixed(2)} Hz · table ${p.position_mm.toFixed(2)} mm` +
    (r.simulated ? " · simulated rig" : "");
}

// -- sweeps
let sweep = null;  // the sweep whose state and live plot are shown
$("start").onclick = async () => {
  const body = {f_start_hz: +$("f0").value, f_end_hz: +$("f1").value, duration_s: +$("dur").value, amplitude_mm: +$("amp").value};
  try {
    const s = await api("POST", "/api/sweeps", body); say(`sweep ${s.id} started`); follow(s.id);
    ((s.preflight || {}).warnings || []).forEach(w => say(`sweep ${s.id}: preflight warning: ${w}`, "warn"));
  }
  catch (e) { fail("sweep refused")(e); }  // nothing to follow: no live plot of a sweep that did not start
};
$("abort").onclick = () => sweep ? api("POST", `/api/sweeps/${sweep.id}/abort`).then(() => say(`sweep ${sweep.id} aborting`))
  .catch(fail("abort refused")) : say("no sweep to abort", "error");
function sweepLine(s) {
  const base = `sweep ${s.id}: ${s.state}`;
  const warned = ((s.request || {}).preflight || {}).warnings || [];  // the prediction near a limit (daq/preflight.py)
  if (warned.length) return `${sweepLine({...s, request: {}})} · preflight warning: ${warned.join("; ")}`;
  if (s.state === "completed") return base;
  if (s.state === "aborted" || s.state === "failed") return `${base} at ${pct(s.progress)}` + (s.error ? ` (${s.error})` : "");
  return `${base} · ${pct(s.progress)}`;
}

// -- live plot: server-sent events of the followed sweep's recording (never before it has one). The samples'
// t is the time into the sweep (s since its recording started), so the axis reads 0 at the start.
const LIVE_WINDOW_S = 10;
let source = null, points = [], missed = 0;
function follow(id) {
  if (sweep && sweep.id === id) return;
  if (source) { source.close(); source = null; }
  sweep = {id, state: "queued", progress: 0}; points = []; missed = 0; draw();
}
function listen(rec_id) {
  if (source || !rec_id) return;
  // EventSource cannot send headers: this address carries the token, but it is never shown in the page
  source = new EventSource(`/api/recordings/${rec_id}/live?access_token=${encodeURIComponent(tok())}`);
  source.addEventListener("samples", e => {
    const d = JSON.parse(e.data);
    if (!d.t || !d.t.length) return;
    const last = points.length ? points[points.length - 1][0] : -Infinity;
    d.t.forEach((t, i) => { if (t > last) points.push([t, d.table_acc[i], d.mass_acc[i]]); });
    const t_end = points[points.length - 1][0];
    points = points.filter(p => p[0] > t_end - LIVE_WINDOW_S); draw();
  });
  source.addEventListener("missed", e => { missed += JSON.parse(e.data).missed_samples; });  // this browser fell behind
  source.addEventListener("end", () => { source.close(); draw(); });
}
/** Round tick steps (1, 2, 5 x 10^n) for a span. */
function niceStep(span, n) {
  const raw = span / n, p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map(k => k * p).find(s => s >= raw);
}
function draw() {
  const c = $("live"), g = c.getContext("2d"), W = c.width, H = c.height;
  const L = 70, R = 12, T = 12, B = 38, w = W - L - R, h = H - T - B;  // the plot area inside the axes
  g.clearRect(0, 0, W, H);
  c.dataset.points = points.length;
  const ended = !sweep || ["completed", "aborted", "failed"].includes(sweep.state);
  const state = ended ? (points.length ? "ended" : "idle") : points.length ? "live" : "waiting";
  c.dataset.state = state;
  const t1 = points.length ? Math.max(points[points.length - 1][0], LIVE_WINDOW_S) : LIVE_WINDOW_S, t0 = t1 - LIVE_WINDOW_S;
  const m = points.length ? Math.max(1e-6, ...points.map(p => Math.max(Math.abs(p[1]), Math.abs(p[2])))) : 1;
  const ystep = niceStep(2 * m, 4), ymax = Math.ceil(m / ystep) * ystep;
  const X = t => L + (t - t0) / LIVE_WINDOW_S * w, Y = v => T + h / 2 - v / ymax * h / 2;
  g.font = "13px system-ui"; g.fillStyle = "#555"; g.strokeStyle = "#e4e4e4"; g.lineWidth = 1;
  for (let v = -ymax; v <= ymax + 1e-9 * ymax; v += ystep) {  // y grid and labels, m/s²
    g.beginPath(); g.moveTo(L, Y(v)); g.lineTo(L + w, Y(v)); g.stroke();
    g.textAlign = "right"; g.fillText(+v.toPrecision(3) + "", L - 6, Y(v) + 4);
  }
  for (let t = Math.ceil(t0); t <= t1 + 1e-9; t += 1) {  // x grid each second, labels every 2 s
    g.beginPath(); g.moveTo(X(t), T); g.lineTo(X(t), T + h); g.stroke();
    if (Math.round(t) % 2 === 0) { g.textAlign = "center"; g.fillText(`${Math.round(t)}`, X(t), T + h + 16); }
  }
  g.strokeStyle = "#999"; g.strokeRect(L, T, w, h);
  g.textAlign = "center"; g.fillText("time into the sweep, s", L + w / 2, H - 4);
  g.save(); g.translate(14, T + h / 2); g.rotate(-Math.PI / 2); g.fillText("acceleration, m/s²", 0, 0); g.restore();
  const text = {idle: "no sweep running: the next sweep's table and mass acceleration appear here",
                waiting: `sweep ${sweep && sweep.id}: waiting for its first samples…`,
                live: `sweep ${sweep && sweep.id}: ${t1.toFixed(1)} s into the sweep` + (missed ? ` (${missed} samples skipped: this browser fell behind)` : ""),
                ended: `sweep ${sweep && sweep.id} ${sweep && sweep.state} (its last ${LIVE_WINDOW_S} s shown); no sweep running now`}[state];
  $("live-state").textContent = text;
  if (!points.length) { g.fillStyle = "#999"; g.font = "15px system-ui"; g.fillText(text, L + w / 2, T + h / 2 - 8); return; }
  g.lineWidth = 1.2;
  [[1, "#888"], [2, "#06c"]].forEach(([k, col]) => {
    g.strokeStyle = col; g.beginPath();
    points.forEach((p, i) => g[i ? "lineTo" : "moveTo"](X(p[0]), Y(p[k])));
    g.stroke();
  });
}

// -- campaigns: a builder (amplitudes, directions, settle) and their state
function campaignPlan() {
  const dirs = [["up", $("c-up").checked], ["down", $("c-down").checked]].filter(d => d[1]).map(d => d[0]);
  return {name: $("c-name").value.trim(), repeats: +$("c-repeats").value, rest_between_s: +$("c-rest").value, directions: dirs,
          amplitudes_mm: $("c-amps").value.split(/[,\s]+/).filter(Boolean).map(Number),
          sweep: {f_start_hz: +$("c-f0").value, f_end_hz: +$("c-f1").value, duration_s: +$("c-dur").value, settle_s: +$("c-settle").value}};
}
function planHint() {
  const p = campaignPlan(), n = p.amplitudes_mm.length * p.directions.length * p.repeats;
  $("c-plan").textContent = `${n} sweep(s), about ${Math.round(n * (p.sweep.duration_s + p.sweep.settle_s) / 60)} min of rig time`;
}
document.querySelectorAll("fieldset input[id^=c-]").forEach(i => i.addEventListener("input", planHint));
$("c-start").onclick = async () => {
  try {
    const c = await api("POST", "/api/campaigns", campaignPlan()); say(`campaign ${c.id} started`); refresh();
    Object.entries((c.preflight || {}).warnings || {}).forEach(([label, ws]) =>
      ws.forEach(w => say(`campaign ${c.id}, ${label}: preflight warning: ${w}`, "warn")));
  }
  catch (e) { fail("campaign refused")(e); }
};
let campaignsShown = "";
function showCampaigns(cs) {
  const key = JSON.stringify(cs);
  if (key === campaignsShown) return;
  campaignsShown = key;
  campaignChoices(cs);
  const actions = c => session.role !== "operator" ? "" :
    (c.state === "running" ? `<button data-act="pause" data-id="${c.id}">pause</button> ` : "") +
    (c.state === "paused" ? `<button data-act="resume" data-id="${c.id}">resume</button> ` : "") +
    (["running", "pausing", "paused"].includes(c.state) ? `<button data-act="abort" data-id="${c.id}">abort</button>` : "");
  $("campaigns").innerHTML = `<tr><th>date</th><th>name</th><th>state</th><th>progress</th><th>sweeps (amplitude, direction)</th><th></th></tr>` +
    (cs.length ? cs.map(c => `<tr data-id="${c.id}"><td>${when(c.created)}</td><td><a href="#/campaign/${c.id}">${esc(c.name)}</a></td>
      <td class="state">${esc(c.state)}${c.reason ? `<br><span class="muted">${esc(c.reason)}</span>` : ""}</td>
      <td class="progress">${c.progress.done}/${c.progress.total}${c.joint_identification ?
        `<br><span class="muted joint" title="${esc(c.joint_identification.error || "")}">joint model: ${esc(c.joint_identification.state)}` +
        `${c.joint_identification.error ? " (" + esc(c.joint_identification.error.slice(0, 80)) + ")" : ""}</span>` : ""}</td>
      <td>${c.sweeps.map(s => `<span class="chip ${s.status}" title="${esc(s.status + (s.reason ? ": " + s.reason : ""))}">` +
        (s.recording_id ? `<a href="#/recording/${s.recording_id}">${s.amplitude_mm} mm ${s.direction}</a>` : `${s.amplitude_mm} mm ${s.direction}`) + `</span>`).join("")}</td>
      <td>${actions(c)}</td></tr>`).join("") : `<tr><td colspan="6" class="muted">no campaigns yet</td></tr>`);
  $("campaigns").querySelectorAll("button[data-act]").forEach(b => b.onclick = () =>
    api("POST", `/api/campaigns/${b.dataset.id}/${b.dataset.act}`).then(() => say(`campaign ${b.dataset.id}: ${b.dataset.act}`))
      .catch(fail(`campaign ${b.dataset.act} refused`)).finally(refresh));
}

// -- upload: the file's bytes as the request body, its name and layout as query parameters
$("up-send").onclick = async () => {
  const f = $("up-file").files[0];
  if (!f) { say("choose a file to upload first", "error"); return; }
  try {
    const r = await api("POST", `/api/recordings?filename=${encodeURIComponent(f.name)}&layout=${$("up-layout").value}`, f, true);
    say(`uploaded ${f.name} as recording ${r.id}`); $("up-file").value = ""; refresh();
  } catch (e) { fail(`upload of ${f.name} refused`)(e); }
};

// -- the refresh loop: once a second, the rig, the followed sweep, recordings, campaigns, history
let busy = false;
async function refresh() {
  if (!session || busy) return;
  busy = true;
  try {
    let rig = null;
    try { rig = await api("GET", "/api/rig"); } catch (e) { if (e.status === 401) return; }
    showRig(rig);
    if (!$("home").hidden) await refreshHome(rig);
    else if (openRecording) await refreshRecording();
  } catch (e) { if (e.status !== 401) $("rig").textContent = "service not reachable: " + e.message; }
  finally { busy = false; }
}
async function refreshHome(rig) {
  if (rig && rig.active_sweep) follow(rig.active_sweep);
  if (sweep) {
    sweep = await api("GET", `/api/sweeps/${sweep.id}`);
    $("sweep-status").textContent = sweepLine(sweep);
    $("sweep-status").className = "status " + (["aborted", "failed"].includes(sweep.state) ? "bad" : "");
    if (sweep.state === "running") listen(sweep.recording_id);
    draw();  // its state line follows the sweep's
  }
  const [recs, cs] = await Promise.all([api("GET", listQuery()), api("GET", "/api/campaigns?limit=20")]);
  showRecordings(recs); showCampaigns(cs);
  await refreshHistory(recs.items);
}
// start once every script has run: recording.js and history.js load after this file, and an early refresh
// (a timer or a quick sign-in while they were still loading) read their names before they existed
// ("openRecording is not defined", seen under load in tests/server/test_dashboard.py)
window.addEventListener("DOMContentLoaded", () => {
  planHint(); draw();
  setInterval(refresh, 1000);
  if (tok()) signIn(); else { $("login").hidden = false; }
});
