// One recording's page (#/recording/<id>): what was recorded and how, its quality flags, the identified
// model (coefficients with standard errors and inclusion probabilities, physical parameters, validation,
// figures) and the discrepancy analysis (explanation). Uses dashboard.js's api, esc, say, when.
"use strict";
let openRecording = null;  // the id shown, and what it was rendered from
let recordingShown = "";
const CAPTIONS = {  // the report's figures; any other figure is shown under its file name
  "input.png": "Input: the table's acceleration over the recording.",
  "output.png": "Output: the mass's response.",
  "lambda_path.png": "Regularisation path: training and held-out error and the number of terms along the penalty; the chosen model marked.",
  "validation.png": "Validation: measured response and the model's free-run simulation; held-out samples shaded.",
  "candidates.png": "Candidate effects: how much of the gap each closes.",
  "gap.png": "Gap between the textbook model and the measurement, before and after the chosen effect.",
  "residual_state.png": "Residual over the state (displacement, velocity): where the textbook model misses.",
  "residual_time.png": "Residual over time and excitation frequency.",
};
//: figures with several panels or long time axes: shown at the page's width, so their text stays readable
const WIDE = new Set(["lambda_path.png", "validation.png", "residual_time.png"]);
//: the model's downloads (GET /api/recordings/{id}/model.<suffix>, server/routers/export.py): suffix, button
const EXPORTS = [["fmu", "FMU (FMI 2.0)"], ["c", "C"], ["py", "Python"], ["tex", "LaTeX"]];
const num = (x, digits = 4) => x == null ? "–" : Math.abs(x) >= 1e5 || (Math.abs(x) < 1e-3 && x !== 0) ? x.toExponential(digits - 1) : (+x.toPrecision(digits)).toString();

async function showRecording(id) {
  openRecording = id; recordingShown = "";
  $("recording").innerHTML = `<p><a href="#">← all recordings</a></p><h2>Recording ${id}</h2><div id="rec-body">loading…</div>`;
  await refreshRecording();
}
async function refreshRecording() {
  const id = openRecording;
  let r;
  try { r = await api("GET", `/api/dashboard/recordings/${id}`); }
  catch (e) { if (e.status === 404) $("rec-body").textContent = `no recording ${id}`; else fail("recording")(e); openRecording = null; return; }
  const key = JSON.stringify(r);
  if (key === recordingShown || id !== openRecording) return;  // nothing new: keep the figures as they are
  recordingShown = key;
  const [model, explanation] = await Promise.all([
    r.jobs.identify.state === "completed" ? api("GET", `/api/recordings/${id}/model`).catch(() => null) : null,
    r.jobs.explain.state === "completed" ? api("GET", `/api/recordings/${id}/explanation`).catch(() => null) : null]);
  if (id !== openRecording) return;
  $("rec-body").innerHTML = details(r) + qualitySection(r, model || explanation) +
    `<h3>Model</h3><div id="rec-model">${modelSection(r, model)}</div>` +
    (model ? `<h3>Frequency response <span class="hint">(the model's predicted response beside this sweep's)</span></h3><div id="rec-frf"></div>` : "") +
    `<h3>Explanation <span class="hint">(what the textbook Duffing model misses, and which effect closes the gap)</span></h3>` +
    `<div id="rec-explain">${explainSection(r, explanation)}</div>`;
  $("rec-body").querySelectorAll("button[data-job]").forEach(b => b.onclick = () =>
    api("POST", b.dataset.job === "explain" ? `/api/recordings/${id}/explain` : `/api/recordings/${id}/identify`,
        b.dataset.faulty ? {accept_faulty: true} : {}).then(() => { say(`${b.dataset.job} of ${id} queued`); refreshRecording(); })
      .catch(fail(`${b.dataset.job} refused`)));
  $("rec-body").querySelectorAll("a.report").forEach(a => a.onclick = ev => { ev.preventDefault(); openReport(id, a.dataset.kind); });
  const dl = $("rec-download");
  if (dl) dl.onclick = async () => {
    try { const a = document.createElement("a"); a.href = await blobUrl(`/api/recordings/${id}/file`); a.download = r.filename; a.click(); }
    catch (e) { fail("download")(e); }
  };
  $("rec-body").querySelectorAll("button[data-export]").forEach(b => b.onclick = async () => {
    const suffix = b.dataset.export;
    try { const a = document.createElement("a"); a.href = await blobUrl(`/api/recordings/${id}/model.${suffix}`); a.download = `model_${id}.${suffix}`; a.click(); }
    catch (e) { fail(`${b.textContent} export`)(e); }
  });
  if (model) await Promise.all([figures(id, "identify", "rec-model-figures"), recordingFrf(id)]);
  if (explanation) await figures(id, "explain", "rec-explain-figures");
}

function details(r) {
  const s = r.info.sweep, who = (r.sweep && r.sweep.operator) || r.info.uploaded_by;
  const rows = [["date", when(r.created)], ["origin", esc(r.origin) + (who ? ` <span class="muted">by ${esc(who)}</span>` : "")],
    ["parameters", params(r)], ["status", statusCell(r)],
    ["samples", r.info.samples != null ? `${r.info.samples}` + (r.info.gaps ? ` <span class="bad">(${r.info.gaps} gap(s))</span>` : "") : "–"],
    ["file", `${esc(r.filename)} ` + (r.status !== "running" ? `<button id="rec-download">download</button>` : "")]];
  if (s && s.note) rows.push(["note", esc(s.note)]);
  return `<dl class="details">${rows.map(([k, v]) => `<dt>${k}</dt><dd>${v}</dd>`).join("")}</dl>`;
}
function qualitySection(r, result) {
  const q = r.info.quality, dq = result && result.data_quality;
  let html = `<h3>Data quality</h3><p id="rec-quality">${qualityCell(q)}</p>`;
  if (dq) {
    const flags = dq.flags || [];
    html += `<p class="hint">flags ${esc(dq.assessed || "")}: ` + (flags.length ? flags.map(f => `<span class="chip">${esc(typeof f === "string" ? f : JSON.stringify(f))}</span>`).join("") : "no flags") +
      (dq.mass_table_rms_ratio != null ? ` · mass/table RMS ratio ${num(dq.mass_table_rms_ratio, 3)}` : "") + `</p>`;
  }
  return html;
}

function jobState(r, kind, label) {
  const j = r.jobs[kind], op = session.role === "operator" && !r.archived;
  // an aborted or faulty recording is refused as it is: the operator may go on anyway, and the result says so
  const run = !op || r.status === "running" ? "" : r.status === "complete" ? ` <button data-job="${kind}">${label}</button>` :
    ` <button data-job="${kind}" data-faulty="1">${label} anyway</button>`;
  if (j.state === "none") return r.status === "complete" || r.status === "running" ? `<p class="muted">not yet${run}</p>` :
    `<p class="bad">not ${kind === "identify" ? "identified" : "explained"}: the recording is ${esc(r.status)}${run}</p>`;
  if (j.state === "queued" || j.state === "running") return `<p class="muted">${j.state}…</p>`;
  // refused for the data's state or quality: the operator may go on anyway, and the result will say so
  const anyway = session.role === "operator" && /accept_faulty/.test(j.error || "") ? ` <button data-job="${kind}" data-faulty="1">${label} anyway</button>` : run;
  if (j.state === "failed") return `<p class="bad">failed: ${esc(j.error)}${anyway}</p>`;
  return null;
}
function modelSection(r, m) {
  const pending = jobState(r, "identify", "identify");
  if (pending) return pending;
  if (!m) return `<p class="bad">the result could not be read</p>`;
  const se = m.standard_errors || {}, ip = m.inclusion_probability || {};
  const exact = (m.uncertainty || {}).exact || {};  // equations that hold by construction (q2_dot = q1)
  const seCell = (eq, t) => exact[eq] && (se[eq] || {})[t] === 0 ? "exact" : num((se[eq] || {})[t], 2);
  const rows = Object.entries(m.model).flatMap(([eq, terms]) => Object.entries(terms).map(([t, c]) =>
    `<tr><td>${esc(eq)}</td><td>${esc(t)}</td><td class="num">${num(c)}</td><td class="num">${seCell(eq, t)}</td>` +
    `<td class="num">${(ip[eq] || {})[t] == null ? "–" : (ip[eq][t]).toFixed(2)}</td></tr>`));
  const faulty = m.accepted_faulty && m.accepted_faulty.length ?
    `<p class="bad" id="rec-faulty">identified although refused at first (accept_faulty): ${esc(m.accepted_faulty.join("; "))}; read it with care</p>` : "";
  let html = faulty + `<p>${m.status === "ok" ? "" : `<b>${esc(m.status)}</b>: `}${esc(m.reason || "")}</p>` +
    `<table class="data" id="rec-terms"><tr><th>equation</th><th>term</th><th class="num">coefficient</th><th class="num">standard error</th>` +
    `<th class="num">inclusion probability</th></tr>${rows.join("")}</table>` + uncertainTerms(m) +
    `<p id="rec-export">the model as a file: ${EXPORTS.map(([s, label]) => `<button data-export="${s}">${label}</button>`).join(" ")} ` +
    `<span class="hint">(as <code>shakeid export</code> writes it, docs/export.md)</span></p>`;
  const p = m.physical;
  if (p) {
    // scale: from the model's SI value to the unit shown (b in mm, as the CLI and the report print it)
    const row = (label, key, unit, scale = 1) => p[key] ? `<tr><td>${label}</td><td class="num">${num(p[key].value == null ? null : scale * p[key].value)}</td>` +
      `<td class="num">${num(p[key].std_error == null ? null : scale * p[key].std_error, 2)}</td><td>${unit}</td></tr>` : "";
    html += `<h4>Physical parameters <span class="hint">(mass ${p.mass_kg} kg)</span></h4><table class="data" id="rec-physical">` +
      `<tr><th>parameter</th><th class="num">value</th><th class="num">standard error</th><th>unit</th></tr>` +
      row("damping c", "damping_ns_per_m", "N s/m") + row("stiffness k", "stiffness_n_per_m", "N/m") +
      row("cubic stiffness k3", "cubic_stiffness_n_per_m3", "N/m³") + row("pre-stress b", "prestress_b_m", "mm", 1e3) +
      row("input gain", "input_gain", "") + `</table>` +
      (p.design ? `<p class="hint">For comparison, the design value of k3 from the rig's drawing (4 k_l a²) is ${num(p.design.cubic_stiffness_n_per_m3)} N/m³; ` +
        `it is not measured, and a difference says how far the built rig is from its drawing.</p>` : "");
  }
  const v = (m.validation || {}).heldout || {};
  if (Object.keys(v).length) html += `<h4>Validation on held-out data</h4><table class="data" id="rec-validation"><tr><th>signal</th><th class="num">fit</th><th class="num">NRMSE</th></tr>` +
    Object.entries(v).map(([k, x]) => `<tr><td>${esc(k)}</td><td class="num">${x.fit_percent == null ? "diverged" : x.fit_percent.toFixed(2) + " %"}</td><td class="num">${num(x.nrmse, 3)}</td></tr>`).join("") + `</table>`;
  return html + `<p><a href="#" class="report" data-kind="identify" id="rec-report">the whole report (index.html)</a> <span class="hint">opens in a new tab</span></p>` +
    `<div class="figures" id="rec-model-figures"></div>`;
}
// kept terms within SIGNIFICANT_Z standard errors of zero: left out of the model and said apart with the bound
// model.json states (uncertainty.term_rules; docs/identification.md, "Uncertain terms")
function uncertainTerms(m) {
  const said = Object.entries(m.uncertain_terms || {}).flatMap(([eq, terms]) => Object.entries(terms).map(([t, u]) =>
    `${esc(t)} (${esc(eq)}) ${num(u.coefficient)} ± ${num(u.standard_error, 2)}` +
    (u.inclusion_probability == null ? "" : `, P(kept) ${u.inclusion_probability.toFixed(2)}`)));
  const rules = (m.uncertainty || {}).term_rules;
  const why = rules ? `within ${rules.significant_z} standard errors of zero` : "within a few standard errors of zero";
  return said.length ? `<p class="hint" id="rec-uncertain">uncertain terms, left out of the model (${esc(why)}): ${said.join("; ")}</p>` : "";
}
function explainSection(r, x) {
  const pending = jobState(r, "explain", "explain");
  if (pending) return pending;
  if (!x) return `<p class="bad">the result could not be read</p>`;
  return explanationSummary(x, "rec") +
    `<p><a href="#" class="report" data-kind="explain" id="rec-explain-report">the whole report (index.html)</a> <span class="hint">opens in a new tab</span></p>` +
    `<div class="figures" id="rec-explain-figures"></div>`;
}
/** An explanation's answer (explain.json, of one recording or several together): the effect named and the gap
 *  before and after; the recording's page and a campaign's page show it alike. */
function explanationSummary(x, prefix) {
  const eff = x.effect ? `<b>${esc(String(x.effect).replace(/_/g, " "))}</b> (terms ${esc((x.terms || []).join(", "))}, confidence ${(x.confidence ?? 0).toFixed(3)})` : "<b>no effect found</b>";
  const over = (x.recordings || []).length > 1 ? ` <span class="hint">(over ${x.recordings.length} recordings together: ${esc(x.recordings.map(r => r.source).join(", "))})</span>` : "";
  return `<p id="${prefix}-effect">Effect: ${eff}.${over}</p><p>Gap (${esc(x.metric || "")}): ${num(x.gap_before, 3)} before, ${num(x.gap_after, 3)} after` +
    (x.gap_closed != null ? ` (${pct(x.gap_closed)} closed)` : "") + (x.noise_floor != null ? `; noise floor ${num(x.noise_floor, 3)}` : "") + `.</p>`;
}
async function figures(id, kind, into) {
  let names = [];
  try { names = await api("GET", `/api/recordings/${id}/plots?kind=${kind}`); } catch (e) { return; }
  const box = $(into);
  if (!box) return;
  for (const name of names.filter(n => n !== FRF_FIGURE)) {  // the overlay: in its own section (frf.js)
    const fig = document.createElement("figure");
    fig.innerHTML = `<img alt="${esc(name)}"><figcaption>${esc(CAPTIONS[name] || name)}</figcaption>`;
    if (WIDE.has(name)) fig.className = "wide";
    box.append(fig);
    blobUrl(`/api/recordings/${id}/plots/${name}?kind=${kind}`).then(u => fig.querySelector("img").src = u).catch(() => {});
  }
}
/** The report's page (its figures inlined by the server), fetched with the token in a header and opened
 *  from memory in a new tab: no address carries the token. */
async function openReport(id, kind) {
  const tab = window.open("", "_blank");
  try { const url = await blobUrl(`/api/recordings/${id}/report?kind=${kind}`); if (tab) tab.location = url; else location.assign(url); }
  catch (e) { if (tab) tab.close(); fail(`the ${kind} report`)(e); }
}
