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
  $("session").textContent = ""; $("rig").textContent = "not signed in"; $("rig").className = "rig"; $("login").hidden = false; $("home").hidden = $("recording").hidden = true;
  if (why) say(why, "error");
}
$("login-form").onsubmit = ev => {
  ev.preventDefault(); localStorage.setItem(TOKEN_KEY, $("token").value.trim()); $("token").value = ""; signIn();
};

// -- pages: # is the main view, #/recording/<id> one recording's page
function route() {
  if (!session) return;
  const m = location.hash.match(/^#\/recording\/([0-9a-f]{12})$/);
  $("home").hidden = !!m; $("recording").hidden = !m;
  if (m) showRecording(m[1]); else { openRecording = null; refresh(); }
}
window.addEventListener("hashchange", () => tokenFromLink() ? signIn() : route());

// -- the rig: its state line is rewritten by every refresh, so it never shows a stale state
$("estop").onclick = () => api("POST", "/api/rig/estop")
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
  try { const s = await api("POST", "/api/sweeps", body); say(`sweep ${s.id} started`); follow(s.id); }
  catch (e) { fail("sweep refused")(e); }  // nothing to follow: no live plot of a sweep that did not start
};
$("abort").onclick = () => sweep ? api("POST", `/api/sweeps/${sweep.id}/abort`).then(() => say(`sweep ${sweep.id} aborting`))
  .catch(fail("abort refused")) : say("no sweep to abort", "error");
function sweepLine(s) {
  const base = `sweep ${s.id}: ${s.state}`;
  if (s.state === "completed") return base;
  if (s.state === "aborted" || s.state === "failed") return `${base} at ${pct(s.progress)}` + (s.error ? ` (${s.error})` : "");
  return `${base} · ${pct(s.progress)}`;
}

// -- live plot: server-sent events of the followed sweep's recording (never before it has one)
let source = null, points = [];
function follow(id) {
  if (sweep && sweep.id === id) return;
  if (source) { source.close(); source = null; }
  sweep = {id, state: "queued", progress: 0}; points = []; draw();
}
function listen(rec_id) {
  if (source || !rec_id) return;
  // EventSource cannot send headers: this address carries the token, but it is never shown in the page
  source = new EventSource(`/api/recordings/${rec_id}/live?access_token=${encodeURIComponent(tok())}`);
  source.addEventListener("samples", e => {
    const d = JSON.parse(e.data);
    if (!d.t || !d.t.length) return;
    d.t.forEach((t, i) => points.push([t, d.table_acc[i], d.mass_acc[i]]));
    const t_end = points[points.length - 1][0];
    points = points.filter(p => p[0] > t_end - 10); draw();
  });
  source.addEventListener("end", () => { source.close(); });
}
function draw() {
  const c = $("live"), g = c.getContext("2d"), W = c.width, H = c.height;
  g.clearRect(0, 0, W, H);
  c.dataset.points = points.length;
  g.strokeStyle = "#ddd"; g.beginPath(); g.moveTo(0, H / 2); g.lineTo(W, H / 2); g.stroke();
  if (!points.length) {
    g.fillStyle = "#999"; g.font = "14px system-ui";
    g.fillText(sweep ? "waiting for samples…" : "no sweep running", W / 2 - 60, H / 2 - 8); return;
  }
  const m = Math.max(1e-6, ...points.map(p => Math.max(Math.abs(p[1]), Math.abs(p[2]))));
  const t1 = points[points.length - 1][0], t0 = t1 - 10;
  g.fillStyle = "#555"; g.font = "12px system-ui";
  g.fillText(`±${m.toPrecision(3)} m/s²`, 6, 14); g.fillText(`t = ${t1.toFixed(1)} s`, W - 80, H - 6);
  [[1, "#888"], [2, "#06c"]].forEach(([k, col]) => {
    g.strokeStyle = col; g.beginPath();
    points.forEach((p, i) => g[i ? "lineTo" : "moveTo"]((p[0] - t0) / 10 * W, H / 2 - p[k] / m * H / 2.2));
    g.stroke();
  });
}

// -- recordings: date, origin, parameters, status and why, quality flags, where the fit stands
function params(r) {
  const s = r.info.sweep;
  if (s) return `${s.f_start_hz}–${s.f_end_hz} Hz · ${s.duration_s} s · ${s.amplitude_mm} mm`;
  const o = r.info.read_options || {};
  return esc(r.filename) + (o.layout && o.layout !== "base" ? ` · ${esc(o.layout)} layout` : "");
}
function statusCell(r) {
  const reason = r.info.reason || (r.sweep && r.sweep.error) || "";
  const cls = r.status === "complete" ? "" : r.status === "running" ? "" : "bad";
  const prog = r.sweep && r.status !== "complete" ? ` at ${pct(r.sweep.progress)}` : "";
  return `<span class="${cls}">${esc(r.status)}${prog}</span>` + (reason ? `<br><span class="muted">${esc(reason)}</span>` : "");
}
function qualityCell(q) {
  if (!q) return `<span class="muted">not assessed</span>`;
  if (q.usable_for_identification === false) return `<span class="bad">unusable: ${esc((q.reasons || []).join("; "))}</span>`;
  const flagged = q.flagged || [];
  return q.flags ? `<span class="warn">${q.flags} flag(s)</span>: ${esc(flagged.join(", "))}` : `<span class="good">clean</span>`;
}
/** The fit: "not yet" (no identification), queued, running, failed (with why), or the held-out fit. */
function fitCell(r) {
  const j = r.jobs.identify;
  if (j.state === "none") return `<span class="muted">not yet</span>` +
    (session.role === "operator" && r.status !== "running" ? ` <button class="identify" data-id="${r.id}">identify</button>` : "");
  if (j.state === "queued" || j.state === "running") return `<span class="muted">${j.state}…</span>`;
  if (j.state === "failed") return `<span class="bad" title="${esc(j.error)}">failed</span>: <span class="muted">${esc(shorten(j.error, 60))}</span>`;
  const f = (r.info.identify || {}).fit_percent;
  if (f == null) return `<span class="bad">diverged</span>`;
  const cls = f >= 90 ? "good" : f >= 50 ? "warn" : "bad";
  return `<span class="${cls}">${f.toFixed(1)} %</span>` + (f < 50 ? ` <span class="bad">(poor)</span>` : "");
}
const shorten = (t, n) => (t = String(t ?? "")).length > n ? t.slice(0, n - 1) + "…" : t;
async function identify(id) {
  try { await api("POST", `/api/recordings/${id}/identify`, {}); say(`identification of ${id} queued`); refresh(); }
  catch (e) { fail("identification refused")(e); }
}
let recsShown = "";
function showRecordings(recs) {
  const key = JSON.stringify([recs, session.role]);
  if (key === recsShown) return;  // unchanged: leave the rows (and any button under the mouse) alone
  recsShown = key;
  $("recs").innerHTML = `<tr><th>date</th><th>id</th><th>origin</th><th>parameters</th><th>status</th><th>data quality</th><th>held-out fit</th></tr>` +
    (recs.length ? recs.map(r => `<tr data-id="${r.id}"><td class="date">${when(r.created)}</td><td><a href="#/recording/${r.id}">${r.id}</a></td>
      <td>${esc(r.origin)}</td><td class="date">${params(r)}</td><td>${statusCell(r)}</td><td>${qualityCell(r.info.quality)}</td>
      <td class="fit">${fitCell(r)}</td></tr>`).join("") : `<tr><td colspan="7" class="muted">no recordings yet</td></tr>`);
  $("recs").querySelectorAll("button.identify").forEach(b => b.onclick = () => identify(b.dataset.id));
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
  try { const c = await api("POST", "/api/campaigns", campaignPlan()); say(`campaign ${c.id} started`); refresh(); }
  catch (e) { fail("campaign refused")(e); }
};
let campaignsShown = "";
function showCampaigns(cs) {
  const key = JSON.stringify(cs);
  if (key === campaignsShown) return;
  campaignsShown = key;
  const actions = c => session.role !== "operator" ? "" :
    (c.state === "running" ? `<button data-act="pause" data-id="${c.id}">pause</button> ` : "") +
    (c.state === "paused" ? `<button data-act="resume" data-id="${c.id}">resume</button> ` : "") +
    (["running", "pausing", "paused"].includes(c.state) ? `<button data-act="abort" data-id="${c.id}">abort</button>` : "");
  $("campaigns").innerHTML = `<tr><th>date</th><th>name</th><th>state</th><th>progress</th><th>sweeps (amplitude, direction)</th><th></th></tr>` +
    (cs.length ? cs.map(c => `<tr data-id="${c.id}"><td>${when(c.created)}</td><td>${esc(c.name)}</td>
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
  }
  const [recs, cs] = await Promise.all([api("GET", "/api/dashboard/recordings?limit=50"), api("GET", "/api/campaigns?limit=20")]);
  showRecordings(recs); showCampaigns(cs);
  await refreshHistory(recs);
}
// start once every script has run: recording.js and history.js load after this file, and an early refresh
// (a timer or a quick sign-in while they were still loading) read their names before they existed
// ("openRecording is not defined", seen under load in tests/server/test_dashboard.py)
window.addEventListener("DOMContentLoaded", () => {
  planHint();
  setInterval(refresh, 1000);
  if (tok()) signIn(); else { $("login").hidden = false; }
});
