// The recordings list: pages of RECS_PER_PAGE ("1–50 of 65"), filters (date, origin, status, campaign),
// a search, and archiving for operators (after a confirmation; the file is moved to the archive folder,
// never deleted, and "archived" lists it again with a restore button). Uses dashboard.js's api, esc, say,
// when, fail, session, refresh.
"use strict";
const RECS_PER_PAGE = 50;
const list = {offset: 0};

/** The list's address: the filters as the API's query parameters (dates as local days, the end inclusive). */
function listQuery() {
  const p = new URLSearchParams({offset: list.offset, limit: RECS_PER_PAGE});
  const day = (id, next) => {
    if (!$(id).value) return;
    const d = new Date($(id).value + "T00:00");
    if (next) d.setDate(d.getDate() + 1);
    p.set(id.slice(2), d.getTime() / 1000);
  };
  day("f-since", false); day("f-until", true);
  for (const key of ["origin", "status", "campaign", "q"]) if ($("f-" + key).value.trim()) p.set(key, $("f-" + key).value.trim());
  if ($("f-archived").checked) p.set("archived", "true");
  return "/api/dashboard/recordings?" + p;
}
function filtersChanged() { list.offset = 0; recsShown = ""; refresh(); }
for (const id of ["f-since", "f-until", "f-origin", "f-status", "f-campaign", "f-archived"]) $(id).addEventListener("change", filtersChanged);
$("f-q").addEventListener("input", filtersChanged);
$("recs-filter").onsubmit = ev => { ev.preventDefault(); filtersChanged(); };
$("recs-prev").onclick = () => { list.offset = Math.max(0, list.offset - RECS_PER_PAGE); refresh(); };
$("recs-next").onclick = () => { list.offset += RECS_PER_PAGE; refresh(); };

/** The campaign filter's choices, from the campaigns shown below the list (the choice kept). */
function campaignChoices(cs) {
  const sel = $("f-campaign"), keep = sel.value;
  sel.innerHTML = `<option value="">any</option>` + cs.map(c => `<option value="${c.id}">${esc(c.name)} (${when(c.created)})</option>`).join("");
  sel.value = keep;
}

function params(r) {
  const s = r.info.sweep;
  if (s) return `${s.f_start_hz}–${s.f_end_hz} Hz · ${s.duration_s} s · ${s.amplitude_mm} mm`;
  const o = r.info.read_options || {};
  return esc(r.filename) + (o.layout && o.layout !== "base" ? ` · ${esc(o.layout)} layout` : "");
}
function statusCell(r) {
  const reason = r.info.reason || (r.sweep && r.sweep.error) || "";
  const cls = r.status === "complete" || r.status === "running" ? "" : "bad";
  const prog = r.sweep && r.status !== "complete" ? ` at ${pct(r.sweep.progress)}` : "";
  return `<span class="${cls}">${esc(r.status)}${prog}</span>` + (reason ? `<br><span class="muted">${esc(reason)}</span>` : "") +
    (r.archived ? `<br><span class="muted">archived ${when(r.archived)}</span>` : "");
}
/** The quality verdict as the server gives it: an aborted or failed recording is unusable, whatever its signals. */
function qualityCell(q) {
  if (!q) return `<span class="muted">not assessed</span>`;
  if (q.usable_for_identification === false) return `<span class="bad">unusable: ${esc((q.reasons || []).join("; "))}</span>`;
  const flagged = q.flagged || [];
  return q.flags ? `<span class="warn">${q.flags} flag(s)</span>: ${esc(flagged.join(", "))}` : `<span class="good">clean</span>`;
}
/** The fit: "not yet" (with an identify button for a complete recording), "not identified" for an aborted or
 *  faulty one (its page offers "identify anyway"), queued, running, failed (with why), or the held-out fit. */
function fitCell(r) {
  const j = r.jobs.identify;
  if (j.state === "none" && r.status !== "complete" && r.status !== "running")
    return `<span class="bad">not identified (${esc(r.status)})</span>`;
  if (j.state === "none") return `<span class="muted">not yet</span>` +
    (session.role === "operator" && r.status === "complete" && !r.archived ? ` <button class="identify" data-id="${r.id}">identify</button>` : "");
  if (j.state === "queued" || j.state === "running") return `<span class="muted">${j.state}…</span>`;
  if (j.state === "failed") return `<span class="bad" title="${esc(j.error)}">failed</span>: <span class="muted">${esc(shorten(j.error, 60))}</span>`;
  const f = (r.info.identify || {}).fit_percent;
  if (f == null) return `<span class="bad">diverged</span>`;
  const cls = f >= 90 ? "good" : f >= 50 ? "warn" : "bad";
  return `<span class="${cls}">${f.toFixed(1)} %</span>` + (f < 50 ? ` <span class="bad">(poor)</span>` : "");
}
function actionCell(r) {
  if (session.role !== "operator") return "";
  if (r.archived) return `<button class="restore" data-id="${r.id}">restore</button>`;
  const busy = r.status === "running" || ["queued", "running"].includes(r.jobs.identify.state) || ["queued", "running"].includes(r.jobs.explain.state);
  return busy ? "" : `<button class="archive" data-id="${r.id}" title="move its file to the archive folder (nothing is deleted)">archive</button>`;
}
const shorten = (t, n) => (t = String(t ?? "")).length > n ? t.slice(0, n - 1) + "…" : t;
async function identify(id) {
  try { await api("POST", `/api/recordings/${id}/identify`, {}); say(`identification of ${id} queued`); refresh(); }
  catch (e) { fail("identification refused")(e); }
}
async function archive(id) {
  if (!confirm(`Archive recording ${id}?\n\nIts file moves to the archive folder of the data directory (nothing is deleted) ` +
               `and it leaves this list; tick "archived" to see it again and restore it.`)) return;
  try { const r = await api("POST", `/api/recordings/${id}/archive`); say(`recording ${id} archived (${r.file})`); refresh(); }
  catch (e) { fail(`archiving ${id} refused`)(e); }
}
async function restore(id) {
  try { await api("POST", `/api/recordings/${id}/restore`); say(`recording ${id} restored`); refresh(); }
  catch (e) { fail(`restoring ${id} refused`)(e); }
}

let recsShown = "";
function showRecordings(pg) {
  const key = JSON.stringify([pg, session.role]);
  if (key === recsShown) return;  // unchanged: leave the rows (and any button under the mouse) alone
  recsShown = key;
  const recs = pg.items, first = pg.total ? pg.offset + 1 : 0, last = pg.offset + recs.length;
  $("recs-range").textContent = `${first}–${last} of ${pg.total}`;
  $("recs-prev").disabled = pg.offset === 0; $("recs-next").disabled = last >= pg.total;
  $("recs").innerHTML = `<tr><th>date</th><th>id</th><th>origin</th><th>parameters</th><th>status</th><th>data quality</th><th>held-out fit</th><th></th></tr>` +
    (recs.length ? recs.map(r => `<tr data-id="${r.id}" data-status="${esc(r.status)}"><td class="date">${when(r.created)}</td><td><a href="#/recording/${r.id}">${r.id}</a></td>
      <td>${esc(r.origin)}</td><td class="date">${params(r)}</td><td>${statusCell(r)}</td><td class="quality">${qualityCell(r.info.quality)}</td>
      <td class="fit">${fitCell(r)}</td><td>${actionCell(r)}</td></tr>`).join("") :
      `<tr><td colspan="8" class="muted">${pg.total || list.offset ? "no recordings on this page" : "no recordings match"}</td></tr>`);
  $("recs").querySelectorAll("button.identify").forEach(b => b.onclick = () => identify(b.dataset.id));
  $("recs").querySelectorAll("button.archive").forEach(b => b.onclick = () => archive(b.dataset.id));
  $("recs").querySelectorAll("button.restore").forEach(b => b.onclick = () => restore(b.dataset.id));
}
