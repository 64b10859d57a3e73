// The predicted frequency response beside the measured sweeps (server/routers/frf.py): a recording's
// section (its latest identification) and a campaign's page (#/campaign/<id>: its sweeps and its joint
// model's response at every table amplitude, and its explanation over every sweep together). Uses dashboard.js's
// api, blobUrl, esc, when, fail, session, $ and recording.js's explanationSummary.
"use strict";
const FRF_FIGURE = "frf_overlay.png";  // reports.frf_overlay.OVERLAY_FIGURE
let openCampaign = null;

/** The section's HTML for a side-by-side document: why there is none, or the flags and the jump table. */
function frfHtml(doc, prefix) {
  if (!doc) return `<p class="muted">no frequency response</p>`;
  if (doc.status !== "ok") return `<p class="muted" id="${prefix}-frf-none">no frequency response: ${esc(doc.reason || doc.status)}</p>`;
  const f = x => x == null ? "–" : x.toFixed(3);
  const flags = doc.flags.length ? doc.flags.map(t => `<p class="bad">flagged: ${esc(t)}</p>`).join("") :
    `<p>the ${esc(doc.judged)} model's jumps agree with every sweep's within the sweep-rate bias and the measurement's uncertainty</p>`;
  const rows = doc.jumps.flatMap(j => Object.entries(j.predicted).map(([label, p]) =>
    `<tr><td>${esc(j.source)}, ${esc(j.direction)}</td><td class="num">${j.amplitude_mm.toPrecision(3)}</td>` +
    `<td class="num">${j.measured_hz == null ? "none" : `${f(j.measured_hz)} ± ${f(j.uncertainty_hz)}`}</td><td>${esc(label)}</td>` +
    `<td class="num">${f(p.fold_hz)}</td><td class="num">${p.bias_hz == null ? "–" : (p.bias_hz >= 0 ? "+" : "") + f(p.bias_hz)}</td>` +
    `<td class="num">${f(p.miss_hz)}</td><td class="${p.agrees === false ? "bad" : ""}">${p.agrees == null ? "–" : p.agrees ? "agrees" : "misses"}</td></tr>`));
  return `<div id="${prefix}-frf-flags">${flags}</div><table class="data" id="${prefix}-frf-jumps"><tr><th>sweep</th><th class="num">table mm</th>` +
    `<th class="num">measured jump, Hz</th><th>model</th><th class="num">fold, Hz</th><th class="num">sweep-rate bias, Hz</th>` +
    `<th class="num">miss, Hz</th><th>verdict</th></tr>${rows.join("")}</table>` +
    `<figure class="wide" id="${prefix}-frf-figure"><img alt="${FRF_FIGURE}"><figcaption>Per table amplitude: the predicted steady-state ` +
    `response (stable solid, unstable dashed, folds circled; shaded from the fold to the fold + sweep-rate bias), the measured ` +
    `response per table cycle (triangles: the sweep's direction) and the measured jump (red x ± its uncertainty).</figcaption></figure>` +
    `<p><a href="#" id="${prefix}-frf-json">frf.json</a> <span class="hint">(branches, stability, envelopes, jumps; opens in a new tab)</span></p>`;
}
/** Fill `box` with the document at `docUrl`, its figure from `figUrl`; the JSON link opens it from memory. */
async function frfInto(box, prefix, docUrl, figUrl) {
  let doc;
  try { doc = await api("GET", docUrl); }
  catch (e) { box.innerHTML = `<p class="muted" id="${prefix}-frf-none">${esc(e.message)}</p>`; return; }
  box.innerHTML = frfHtml(doc, prefix);
  const img = box.querySelector("img");
  if (img) blobUrl(figUrl).then(u => img.src = u).catch(() => {});
  const link = $(`${prefix}-frf-json`);
  if (link) link.onclick = async ev => {
    ev.preventDefault();
    const tab = window.open("", "_blank");  // the document as fetched now, from memory: no address carries the token
    try {
      const u = URL.createObjectURL(new Blob([JSON.stringify(await api("GET", docUrl), null, 1)], {type: "application/json"}));
      if (tab) tab.location = u; else location.assign(u);
    } catch (e) { if (tab) tab.close(); fail("frf.json")(e); }
  };
}
function recordingFrf(id) {
  const box = $("rec-frf");
  if (box) return frfInto(box, "rec", `/api/recordings/${id}/frf`, `/api/recordings/${id}/plots/${FRF_FIGURE}?kind=identify`);
}

async function showCampaign(id) {
  openCampaign = id;
  $("campaign").innerHTML = `<p><a href="#">← all recordings</a></p><h2>Campaign ${id}</h2><div id="camp-body">loading…</div>`;
  let c;
  try { c = await api("GET", `/api/campaigns/${id}`); }
  catch (e) { $("camp-body").textContent = e.status === 404 ? `no campaign ${id}` : e.message; return; }
  if (id !== openCampaign) return;
  const j = c.joint_identification, x = c.explanation;
  const busy = x && ["queued", "running"].includes(x.state);
  const ask = session.role === "operator" && c.state === "completed" && !busy ?
    ` <button id="camp-explain-go">${x ? "explain again" : "explain its sweeps together"}</button>` : "";
  $("camp-body").innerHTML = `<dl class="details"><dt>name</dt><dd>${esc(c.name)}</dd><dt>date</dt><dd>${when(c.created)}</dd>` +
    `<dt>state</dt><dd>${esc(c.state)}${c.reason ? ` <span class="muted">${esc(c.reason)}</span>` : ""}</dd>` +
    `<dt>joint model</dt><dd id="camp-joint">${j ? esc(j.state) + (j.error ? `: ${esc(j.error)}` : "") : "not yet (queued when the campaign completes)"}</dd>` +
    `<dt>explanation</dt><dd id="camp-explain-state">${x ? esc(x.state) + (x.error ? `: ${esc(x.error)}` : "") :
      c.state === "completed" ? "not asked for" : "once the campaign completes"}${ask}</dd></dl>` +
    `<div id="camp-explain"></div>` +
    `<table class="data" id="camp-sweeps"><tr><th>sweep</th><th class="num">amplitude, mm</th><th>direction</th><th>status</th></tr>` +
    c.sweeps.map((s, i) => `<tr><td>${s.recording_id ? `<a href="#/recording/${s.recording_id}">${i + 1}</a>` : i + 1}</td>` +
      `<td class="num">${s.amplitude_mm}</td><td>${esc(s.direction)}</td><td>${esc(s.status)}</td></tr>`).join("") + `</table>` +
    `<h3>Frequency response <span class="hint">(the joint model beside every sweep, per table amplitude)</span></h3><div id="camp-frf"></div>`;
  const go = $("camp-explain-go");
  if (go) go.onclick = () => api("POST", `/api/campaigns/${id}/explain`, {}).then(() => showCampaign(id)).catch(fail("not explained"));
  if (x && x.state === "completed") {
    api("GET", `/api/campaigns/${id}/explanation`).then(doc => { if (openCampaign === id) $("camp-explain").innerHTML = explanationSummary(doc, "camp"); })
      .catch(e => { if (openCampaign === id) $("camp-explain").innerHTML = `<p class="muted">${esc(e.message)}</p>`; });
  }
  const later = () => setTimeout(() => { if (openCampaign === id && location.hash === `#/campaign/${id}`) showCampaign(id); }, 2000);
  if (j && j.state === "completed") await frfInto($("camp-frf"), "camp", `/api/campaigns/${id}/frf`, `/api/campaigns/${id}/frf.png`);
  else {
    $("camp-frf").innerHTML = `<p class="muted" id="camp-frf-none">after the joint identification</p>`;
    later();
  }
  if (busy && j && j.state === "completed") later();  // the explanation's state, until it is done
}

// -- the campaign builder's proposal: amplitudes and band from the rig model's predicted folds (daq.plan)
$("c-propose").onclick = async () => {
  try {
    const name = $("c-name").value.trim();  // none: the service's default (daq.plan.PROPOSAL_NAME)
    const ask = () => api("POST", "/api/campaigns/proposal", name ? {name} : {});
    let p = await ask();
    if (!p.plan) say(p.detail);  // 202: computing (seconds); the same request answers once it is done
    while (!p.plan) { await new Promise(r => setTimeout(r, 2000)); p = await ask(); }
    const s = p.plan.sweep;
    $("c-amps").value = p.plan.amplitudes_mm.join(", ");
    $("c-f0").value = s.f_start_hz; $("c-f1").value = s.f_end_hz; $("c-dur").value = s.duration_s; $("c-settle").value = s.settle_s;
    $("c-up").checked = p.plan.directions.includes("up"); $("c-down").checked = p.plan.directions.includes("down");
    $("c-rest").value = p.plan.rest_between_s;
    planHint();
    say(`proposed from ${p.model_source}: the jump from ${p.onset_mm.toFixed(2)} mm, up to ${p.largest_mm.toFixed(2)} mm inside the rig's limits; ` +
        `band ${s.f_start_hz}-${s.f_end_hz} Hz brackets every predicted jump`);
  } catch (e) { fail("no campaign proposed")(e); }
};
