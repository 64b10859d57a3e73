// The rig history: c, k, k3 and b of every identified recording, oldest left, each with error bars of
// ± 2 standard errors (from the model's physical parameters): is the rig drifting? An SVG drawn here.
"use strict";
let historyShown = "";
async function refreshHistory(recs) {
  // refetched only when some recording's identification changed (the list is polled every second)
  const key = JSON.stringify(recs.map(r => [r.id, r.jobs.identify.state, r.jobs.identify.id]));
  if (key === historyShown) return;
  historyShown = key;
  drawHistory(await api("GET", "/api/dashboard/history"));
}
const tick = (v, digits) => Math.abs(v) >= 1e5 || (v !== 0 && Math.abs(v) < 1e-2) ? v.toExponential(digits - 1) : v.toPrecision(digits);
const faultyToggle = (on, n) => !n ? "" :
  `<label class="hint"><input type="checkbox" id="history-faulty"${on ? " checked" : ""}> show the ${n} fit(s) of data refused at first</label>`;
/** The first and last recording's date under the axis (the rest are in each point's tooltip). */
function xLabels(pts, X, y) {
  const d0 = new Date(pts[0].created * 1000), d1 = new Date(pts[pts.length - 1].created * 1000);
  const sameDay = d0.toDateString() === d1.toDateString();  // then times of day, else dates
  const short = t => new Date(t * 1000).toLocaleString(undefined, sameDay ? {hour: "2-digit", minute: "2-digit"} : {month: "numeric", day: "numeric"});
  const first = `<text x="${X(0)}" y="${y}" text-anchor="start" fill="#777">${short(pts[0].created)}</text>`;
  return pts.length < 2 ? first : first + `<text x="${X(pts.length - 1)}" y="${y}" text-anchor="end" fill="#777">${short(pts[pts.length - 1].created)}</text>`;
}
let lastHistory = null;
function drawHistory(h) {
  lastHistory = h;
  // fits of data refused at first (an aborted sweep) are far less certain and would set the scale: shown on request
  const withFaulty = $("history-faulty") && $("history-faulty").checked;
  const hidden = h.points.filter(p => p.accepted_faulty.length).length;
  const pts = withFaulty ? h.points : h.points.filter(p => !p.accepted_faulty.length);
  if (!pts.length) {
    $("history").innerHTML = `<p class="muted">no identified recordings yet</p>` + faultyToggle(withFaulty, hidden);
    if ($("history-faulty")) $("history-faulty").onchange = () => drawHistory(lastHistory);
    return;
  }
  const W = 270, H = 210, L = 74, R = 12, T = 22, B = 38, PAD = 10;  // px; PAD keeps end points off the axes
  const panels = Object.entries(h.parameters).map(([key, {symbol, unit, scale = 1}]) => {
    // drawn in the unit shown (scale: from the model's SI value); data-value / data-se stay SI, as in model.json
    const shown = v => v && v.value != null ? {value: v.value * scale, std_error: v.std_error == null ? null : v.std_error * scale} : null;
    const vals = pts.map(p => shown(p[key])).filter(v => v);
    if (!vals.length) return `<svg width="${W}" height="${H}"><text x="${L}" y="${T}">${symbol}: none</text></svg>`;
    const lo = Math.min(...vals.map(v => v.value - 2 * (v.std_error || 0))), hi = Math.max(...vals.map(v => v.value + 2 * (v.std_error || 0)));
    const pad = (hi - lo) * 0.1 || Math.abs(hi) * 0.01 || 1;
    const y0 = lo - pad, y1 = hi + pad;
    const X = i => L + PAD + (pts.length === 1 ? (W - L - R - 2 * PAD) / 2 : i * (W - L - R - 2 * PAD) / (pts.length - 1));
    const Y = v => T + (y1 - v) / (y1 - y0) * (H - T - B);
    const marks = pts.map((p, i) => {
      const v = shown(p[key]), raw = p[key];
      if (!v) return "";
      const faulty = p.accepted_faulty.length > 0;
      const se = v.std_error || 0, tip = `${p.recording_id} · ${when(p.created)}` + (p.amplitude_mm ? ` · ${p.amplitude_mm} mm` : "") +
        `\n${symbol} = ${v.value.toPrecision(5)} ± ${se.toPrecision(2)} ${unit} (1 SE)` +
        (faulty ? `\nidentified from faulty data: ${p.accepted_faulty.join("; ")}` : "");
      return `<g class="point" data-rec="${p.recording_id}" data-value="${raw.value}" data-se="${raw.std_error ?? ""}"><title>${esc(tip)}</title>` +
        `<line class="bar" x1="${X(i)}" x2="${X(i)}" y1="${Y(v.value - 2 * se)}" y2="${Y(v.value + 2 * se)}"/>` +
        `<line class="bar" x1="${X(i) - 3}" x2="${X(i) + 3}" y1="${Y(v.value - 2 * se)}" y2="${Y(v.value - 2 * se)}"/>` +
        `<line class="bar" x1="${X(i) - 3}" x2="${X(i) + 3}" y1="${Y(v.value + 2 * se)}" y2="${Y(v.value + 2 * se)}"/>` +
        `<circle class="${p.origin}${faulty ? " faulty" : ""}" cx="${X(i)}" cy="${Y(v.value)}" r="3"/></g>`;
    }).join("");
    // enough significant digits that the three tick labels differ (the spread may be 1e-4 of the value)
    const digits = Math.min(8, Math.max(3, 2 + Math.ceil(Math.log10(Math.max(Math.abs(y0), Math.abs(y1)) / (hi - lo + pad)))));
    const ticks = [y0 + pad, (y0 + y1) / 2, y1 - pad].map(v => `<text x="${L - 4}" y="${Y(v) + 4}" text-anchor="end">${tick(v, digits)}</text>` +
      `<line class="axis" x1="${L - 2}" x2="${L}" y1="${Y(v)}" y2="${Y(v)}"/>`).join("");
    return `<svg width="${W}" height="${H}" data-parameter="${key}"><text x="${L}" y="14" font-weight="600">${symbol}, ${unit}</text>` +
      `<line class="axis" x1="${L}" x2="${L}" y1="${T}" y2="${H - B}"/><line class="axis" x1="${L}" x2="${W - R}" y1="${H - B}" y2="${H - B}"/>` +
      ticks + marks + xLabels(pts, X, H - B + 12) +
      `<text x="${(L + W - R) / 2}" y="${H - 4}" text-anchor="middle" fill="#777">recording (oldest → newest)</text></svg>`;
  });
  $("history").innerHTML = panels.join("") + `<p class="hint">${pts.length} identified recording(s), ` +
    `${when(pts[0].created)} to ${when(pts[pts.length - 1].created)}; blue: sweeps, orange: uploads; hollow: identified from data refused at first (an aborted sweep, say). Hover a point for its recording.</p>` +
    faultyToggle(withFaulty, hidden);
  if ($("history-faulty")) $("history-faulty").onchange = () => drawHistory(lastHistory);
}
