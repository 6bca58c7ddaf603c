// maglev-match explore: the page. Vanilla JavaScript; figures by uPlot (vendored) and a
// small canvas drawing for the Hopf curve. Every computing request carries a sequence
// number; an answer older than what a panel shows is dropped.
"use strict";

const S = {
  preset: "turnout-soft", values: {}, controls: [], model: "unit",
  seq: 0, shown: { quick: 0, release: 0 }, sent: { quick: 0, release: 0 },
  job: null, jobTimer: null, hopf: null, plots: {},
};
const $ = (id) => document.getElementById(id);
// this page's name for the server: sequence numbers are compared within one page
const CLIENT = Math.random().toString(36).slice(2) + Date.now().toString(36);
const SLIDER_STEPS = 1000;

function fmt(v, d = 4) {
  if (v === null || v === undefined) return "–";
  if (typeof v !== "number") return String(v);
  return Number(v.toPrecision(d)).toString();
}

function fieldText(v) {
  // a typed field: six significant digits, large and small values with an exponent
  const x = Number(v.toPrecision(6));
  return x !== 0 && (Math.abs(x) >= 1e5 || Math.abs(x) < 1e-3) ? x.toExponential() : String(x);
}

// ----- state <-> URL ------------------------------------------------------------------
function stateFromLocation() {
  const q = new URLSearchParams(window.location.search);
  const values = {};
  for (const [k, v] of q.entries()) if (k !== "preset" && k !== "v") values[k] = v;
  return { preset: q.get("preset") || S.preset, values, v: q.get("v") || "0" };
}
function queryOf(preset, values) {
  const q = new URLSearchParams();
  q.set("preset", preset);
  for (const [k, v] of Object.entries(values)) q.set(k, String(v));
  return q.toString();
}
function hasSpeed() { return S.v !== undefined && S.v !== "" && S.v !== "0"; }
function currentQuery() { return queryOf(S.preset, S.values) + (hasSpeed() ? "&v=" + encodeURIComponent(S.v) : ""); }
function pushState() {
  const url = "?" + currentQuery();
  if (url !== window.location.search) history.pushState({}, "", url);
}

// ----- controls -----------------------------------------------------------------------
function toSlider(c, v) {
  const lo = c.low, hi = c.high;
  let f = c.log ? (Math.log(v) - Math.log(lo)) / (Math.log(hi) - Math.log(lo))
                : (v - lo) / (hi - lo);
  return Math.round(Math.min(1, Math.max(0, f)) * SLIDER_STEPS);
}
function fromSlider(c, k) {
  const f = k / SLIDER_STEPS;
  const v = c.log ? Math.exp(Math.log(c.low) + f * (Math.log(c.high) - Math.log(c.low)))
                  : c.low + f * (c.high - c.low);
  return Number(v.toPrecision(4));
}
function buildControls(controls) {
  const box = $("controls");
  box.innerHTML = "";
  for (const c of controls) {
    const div = document.createElement("div");
    div.className = "ctl";
    div.id = "ctl-" + c.name;
    div.innerHTML =
      `<label for="field-${c.name}">${c.label} (${c.name}, ${c.unit})</label>` +
      `<div class="row"><input type="range" id="slider-${c.name}" min="0" max="${SLIDER_STEPS}" step="1">` +
      `<input type="text" id="field-${c.name}" name="${c.name}" autocomplete="off">` +
      `<button type="button" id="reset-${c.name}" title="back to the preset">&#x21ba;</button></div>` +
      `<div class="err" id="err-${c.name}"></div>`;
    box.appendChild(div);
    const slider = div.querySelector("input[type=range]");
    const field = div.querySelector("input[type=text]");
    slider.addEventListener("input", () => {
      const v = fromSlider(c, Number(slider.value));
      field.value = String(v);
      clearFieldError(c.name);
      S.values[c.name] = v;
      S.moving = true;
      quick();
    });
    slider.addEventListener("change", () => {
      S.values[c.name] = fromSlider(c, Number(slider.value));
      S.moving = false;
      pushState();
      release();
    });
    field.addEventListener("change", () => typed(c.name, field.value.trim()));
    div.querySelector("button").addEventListener("click", () => {
      delete S.values[c.name];
      clearFieldError(c.name);
      pushState();
      quick();
      release();
    });
  }
}
function showControls(controls) {
  S.controls = controls;
  for (const c of controls) {
    const field = $("field-" + c.name), slider = $("slider-" + c.name);
    if (!field) continue;
    if (document.activeElement !== field) field.value = fieldText(c.value);
    if (document.activeElement !== slider) slider.value = toSlider(c, c.value);
    $("ctl-" + c.name).classList.toggle("explicit", !!c.explicit);
  }
}
function clearFieldError(name) { const e = $("err-" + name); if (e) e.textContent = ""; }
function showFieldErrors(errors) {
  for (const [name, msg] of Object.entries(errors)) {
    const e = $("err-" + name);
    if (e) e.textContent = msg;
    else { const g = $("field-errors"); g.textContent = msg; g.className = "err"; }
  }
}
async function typed(name, raw) {
  // a typed value is checked by the command line's rules first; refused: nothing changes
  clearFieldError(name);
  $("field-errors").textContent = "";
  const values = Object.assign({}, S.values, { [name]: raw });
  const seq = ++S.seq;
  const r = await getJSON("/api/quick?" + queryOf(S.preset, values) + "&seq=" + seq + "&client=" + CLIENT);
  if (!r) return;
  if (r.body.errors) { showFieldErrors(r.body.errors); setStatus("idle", "value refused"); return; }
  S.values = values;
  pushState();
  if (seq >= S.shown.quick) showQuick(r.body, seq);
  release();
}

// ----- requests -----------------------------------------------------------------------
async function getJSON(url, opts) {
  try {
    const resp = await fetch(url, opts);
    const body = await resp.json();
    return { status: resp.status, body };
  } catch (e) {
    showError("the server did not answer: " + e);
    return null;
  }
}
function setStatus(state, text) { const s = $("status"); s.dataset.state = state; s.textContent = text; }
function showError(msg) { const e = $("error"); e.hidden = !msg; e.textContent = msg || ""; }

async function quick() {
  const seq = ++S.seq;
  S.sent.quick = seq;
  $("chi-mark").textContent = S.shown.release ? "at the last released design (release to recompute)" : "";
  const r = await getJSON("/api/quick?" + currentQuery() + "&seq=" + seq + "&client=" + CLIENT);
  if (!r || r.body.stale || seq < S.shown.quick) return;
  if (r.body.errors) { showFieldErrors(r.body.errors); return; }
  if (r.body.error) { showError(r.body.error); return; }
  showQuick(r.body, seq);
}
function showQuick(b, seq) {
  S.shown.quick = seq;
  $("verdict").textContent = b.stable ? "stable" : "unstable";
  $("margin").textContent = fmt(b.margin) + " 1/s (max Re λ = " + fmt(b.max_real_part) + ")";
  $("modal").textContent = fmt(b.omega1, 5) + " rad/s, " + fmt(b.sigma) + " 1/kg";
  S.modal = { omega1: b.omega1, sigma: b.sigma };
  showInterp();
  $("w0").textContent = fmt(b.w0 * 1e3) + " mm";
  showControls(b.controls);
  markHopf();
}

async function release() {
  const seq = ++S.seq;
  S.sent.release = seq;
  setStatus("busy", "computing the index ...");
  const q = currentQuery();
  const r = await getJSON("/api/release?" + q + "&seq=" + seq + "&client=" + CLIENT);
  if (!r) return;
  if (r.body.stale || seq < S.shown.release) return;  // a newer answer is shown or coming
  if (r.body.errors) { showFieldErrors(r.body.errors); setStatus("idle", "value refused"); return; }
  if (r.body.error) {
    showError("the computation failed: " + r.body.error);
    if (seq === S.sent.release) setStatus("error", "computation failed");
    return;
  }
  showError("");
  S.shown.release = seq;
  showRelease(r.body);
  showExports(q);
  if (seq === S.sent.release) setStatus("idle", "up to date");
  if (curveKey(S.preset, S.values) !== S.jobKey) startJob("hopf_curve");
  if (!S.tileRefused && !tileCovers() && tileKey(S.preset, S.values) !== S.tileKey) startJob("tile");
  if (hasSpeed() && speedKey() !== S.speedKey) startJob("speed");
}
function showRelease(b) {
  const ix = b.index;
  $("chi").textContent = S.chiText = ix.chi === null ? "nan" : ix.chi.toFixed(3);
  $("chi").dataset.state = "exact";
  $("chi").dataset.value = ix.chi === null ? "" : String(ix.chi);
  $("chi").dataset.query = b.state ? new URLSearchParams(b.state).toString() : "";
  $("chi-mark").textContent = "";
  S.modal = { omega1: ix.omega1, sigma: ix.sigma };
  showInterp();
  $("chi-paper").textContent = fmt(ix.chi_paper) + " (h = " + fmt(ix.h * 1e3) + " mm, " + ix.case + ")";
  $("chi-sim").textContent = ix.chi_simulation === null ? "not computed" : fmt(ix.chi_simulation);
  $("basis").textContent = ix.headline;
  $("reading").textContent = ix.reading;
  $("warm").textContent = b.warm_start;
  $("hopf-nearest").textContent = ix.hopf_param
    ? `${ix.hopf_param} = ${fmt(ix.hopf_value, 6)}` + (ix.hopf_distance !== null ? ` (${fmt(100 * ix.hopf_distance, 3)} % away)` : "")
      + (ix.l1 ? (ix.l1 > 0 ? ", subcritical" : ", supercritical") + ` l1 = ${fmt(ix.l1, 3)}` : "")
    : "none found";
  $("warnings").textContent = (ix.warnings || []).map((w) => "⚠ " + w).join("\n");
  showControls(b.controls);
  drawCycle(b.cycle);
  drawRun(b.run, b.limits);
}
function showExports(q) {
  getText("/api/export/command?" + q).then((t) => { if (t !== null) $("cmdline").textContent = t; });
  $("x-toml").href = "/api/export/toml?" + q;
  $("x-cycle-csv").href = "/api/export/csv?what=cycle&" + q;
  $("x-run-csv").href = "/api/export/csv?what=run&" + q;
  for (const w of ["index", "run"]) for (const f of ["png", "svg"])
    $(`x-${w}-${f}`).href = `/api/export/${f}?what=${w}&` + q;
}
async function getText(url) {
  try { const r = await fetch(url); return r.ok ? await r.text() : null; } catch (e) { return null; }
}

// ----- figures ------------------------------------------------------------------------
function plotInto(id, opts, data) {
  if (S.plots[id]) { S.plots[id].destroy(); delete S.plots[id]; }
  const box = $(id);
  box.innerHTML = "";
  if (!data) { box.textContent = "none"; return; }
  S.plots[id] = new uPlot(opts, data, box);
}
function drawCycle(c) {
  if (!c) { plotInto("cycle", null, null); $("cycle").textContent = "no cycle bounds the basin here"; return; }
  const dash = c.stable ? [] : [6, 4];
  plotInto("cycle", {
    width: 480, height: 260,
    scales: { x: { time: false } },
    axes: [{ label: "t (s)" }, { label: "gap deviation (mm)" }],
    series: [{ label: "t" }, { label: `point ${c.point} (${c.stable ? "stable" : "unstable"})`, stroke: "#c62828", dash, width: 2 }],
  }, [c.t, c.gap_deviation.map((v) => v * 1e3)]);
}
function drawRun(r, lim) {
  if (!r) { plotInto("run", null, null); $("run-info").textContent = "no critical disturbance was solved"; return; }
  $("run-info").textContent = `${r.direction}: size ${fmt(r.size * 1e3)} mm (just below the critical ${fmt(r.critical_size * 1e3, 6)} mm, ${r.mechanism}); ${runOutcome(r)}`;
  const n = r.t.length;
  plotInto("run", {
    width: 480, height: 260,
    scales: { x: { time: false }, gap: {}, i: {} },
    axes: [{ label: "t (s)" }, { scale: "gap", label: "gap (mm)" }, { scale: "i", side: 1, label: "current (A)", grid: { show: false } }],
    series: [{ label: "t" },
      { label: "gap", scale: "gap", stroke: "#1565c0", width: 2 },
      { label: "gap_min", scale: "gap", stroke: "#999", dash: [4, 4] },
      { label: "gap_max", scale: "gap", stroke: "#999", dash: [4, 4] },
      { label: "current", scale: "i", stroke: "#2e7d32", width: 1 }],
  }, [r.t, r.gap.map((v) => v * 1e3), new Array(n).fill(lim.gap_min * 1e3), new Array(n).fill(lim.gap_max * 1e3), r.current]);
}
function runOutcome(r) {
  // a run shown over a short window has usually not settled yet: say what it shows
  if (r.outcome === "running")
    return `no contact within the ${fmt(r.t[r.t.length - 1], 3)} s shown (the index's search found that this size returns)`;
  return `outcome: ${r.outcome}`;
}
function drawHopf() {
  const cv = $("hopf"), ctx = cv.getContext("2d");
  ctx.clearRect(0, 0, cv.width, cv.height);
  const t = S.tile && !S.tileRefused && (!S.hopf || S.hopf.names.join() === t_names(S.tile)) ? S.tile : null;
  const h = S.hopf && S.hopf.branches.length ? S.hopf : (t ? { names: t.names, branches: [] } : null);
  if (!h) { ctx.fillText(S.hopf ? "no Hopf curve in the plane" : "", 20, 20); return; }
  const xs = [], ys = [];
  for (const b of h.branches) { xs.push(...b.x); ys.push(...b.y); }
  const half = (a) => (a[a.length - 1] - a[0]) / (2 * (a.length - 1));
  if (t) {
    xs.push(t.x[0] - half(t.x), t.x[t.x.length - 1] + half(t.x));
    ys.push(t.y[0] - half(t.y), t.y[t.y.length - 1] + half(t.y));
  }
  const cur = currentDesign(h.names);
  if (cur) { xs.push(cur[0]); ys.push(cur[1]); }
  const pad = 50, W = cv.width, H = cv.height;
  // the data's range with 5 % room on each side, so that neither the curve nor the design
  // sits on the frame
  const room = (lo, hi) => { const d = (hi - lo) || Math.abs(hi) || 1; return [lo - 0.05 * d, hi + 0.05 * d]; };
  let [x0, x1] = room(Math.min(...xs), Math.max(...xs)), [y0, y1] = room(Math.min(...ys), Math.max(...ys));
  if (t && S.zoom) {
    // zoomed on the tile: 2.5 times its width around it (the curve clipped to the frame)
    const mx = (t.x[0] + t.x[t.x.length - 1]) / 2, my = (t.y[0] + t.y[t.y.length - 1]) / 2;
    const rx = 2.5 * (t.x[t.x.length - 1] - t.x[0] + 2 * half(t.x)) / 2, ry = 2.5 * (t.y[t.y.length - 1] - t.y[0] + 2 * half(t.y)) / 2;
    [x0, x1, y0, y1] = [mx - rx, mx + rx, my - ry, my + ry];
  }
  const sx = (x) => pad + (x - x0) / ((x1 - x0) || 1) * (W - 1.5 * pad);
  const sy = (y) => H - pad + -(y - y0) / ((y1 - y0) || 1) * (H - 1.5 * pad);
  ctx.strokeStyle = "#444"; ctx.fillStyle = "#222"; ctx.lineWidth = 1; ctx.setLineDash([]);
  ctx.strokeRect(pad, pad / 2, W - 1.5 * pad, H - 1.5 * pad);
  ctx.font = "11px sans-serif";
  // five ticks on each axis, labelled with the parameter's value
  for (let k = 0; k <= 4; k++) {
    const xv = x0 + (k / 4) * (x1 - x0), yv = y0 + (k / 4) * (y1 - y0);
    ctx.beginPath(); ctx.moveTo(sx(xv), H - pad); ctx.lineTo(sx(xv), H - pad + 4); ctx.stroke();
    ctx.fillText(fmt(xv, 4), sx(xv) - 14, H - pad + 15);
    ctx.beginPath(); ctx.moveTo(pad, sy(yv)); ctx.lineTo(pad - 4, sy(yv)); ctx.stroke();
    ctx.save(); ctx.translate(pad - 7, sy(yv) + 14); ctx.rotate(-Math.PI / 2);
    ctx.fillText(fmt(yv, 3), 0, 0); ctx.restore();
  }
  if (t) drawTile(ctx, t, sx, sy, half);
  ctx.fillStyle = "#222";
  ctx.fillText(h.names[0], pad + (W - 1.5 * pad) / 2, H - pad + 30);
  ctx.save(); ctx.translate(12, H / 2); ctx.rotate(-Math.PI / 2);
  ctx.fillText(h.names[1], 0, 0); ctx.restore();
  ctx.save();
  ctx.beginPath(); ctx.rect(pad, pad / 2, W - 1.5 * pad, H - 1.5 * pad); ctx.clip();
  for (const b of h.branches) {
    // one path per run of points with the same sign of l1 (a dash pattern restarts with
    // every path, so segments shorter than a dash drawn one by one would all look solid)
    ctx.strokeStyle = "#283593"; ctx.lineWidth = 2;
    let i = 1;
    while (i < b.x.length) {
      const sub = b.l1[i] > 0;
      ctx.beginPath();
      ctx.setLineDash(sub ? [6, 4] : []);
      ctx.moveTo(sx(b.x[i - 1]), sy(b.y[i - 1]));
      while (i < b.x.length && (b.l1[i] > 0) === sub) { ctx.lineTo(sx(b.x[i]), sy(b.y[i])); i++; }
      ctx.stroke();
    }
    ctx.setLineDash([]);
    for (const p of b.special) {
      ctx.fillStyle = "#c62828"; ctx.beginPath(); ctx.arc(sx(p.x), sy(p.y), 4, 0, 2 * Math.PI); ctx.fill();
      ctx.fillText(p.label, sx(p.x) + 5, sy(p.y) - 5);
    }
  }
  ctx.restore();
  if (cur) {
    ctx.fillStyle = "#000"; ctx.beginPath(); ctx.arc(sx(cur[0]), sy(cur[1]), 5, 0, 2 * Math.PI); ctx.fill();
    ctx.fillText("this design", sx(cur[0]) + 7, sy(cur[1]) + 4);
  }
}
function t_names(t) { return t.names.join(); }
function drawBranch() {
  // the cycles' largest gap deviation against omega1: solid where stable, dashed where
  // not, the special points with their AUTO labels, H at the Hopf point, the design's omega1
  const cv = $("branch"), ctx = cv.getContext("2d"), b = S.branch;
  ctx.clearRect(0, 0, cv.width, cv.height);
  ctx.font = "11px sans-serif"; ctx.fillStyle = "#222";
  if (!b || !b.points.length) { ctx.fillText(b ? b.message || "no cycles" : "", 20, 20); return; }
  const xs = b.points.map((p) => p.x).concat([b.design]), ys = b.points.map((p) => p.size * 1e3).concat([0]);
  const W = cv.width, H = cv.height, pad = 50;
  const room = (lo, hi) => { const d = (hi - lo) || Math.abs(hi) || 1; return [lo - 0.05 * d, hi + 0.05 * d]; };
  const [x0, x1] = room(Math.min(...xs), Math.max(...xs)), [y0, y1] = room(Math.min(...ys), Math.max(...ys));
  const sx = (x) => pad + (x - x0) / (x1 - x0) * (W - 1.5 * pad), sy = (y) => H - pad - (y - y0) / (y1 - y0) * (H - 1.5 * pad);
  ctx.strokeStyle = "#444"; ctx.lineWidth = 1; ctx.setLineDash([]);
  ctx.strokeRect(pad, pad / 2, W - 1.5 * pad, H - 1.5 * pad);
  for (let k = 0; k <= 4; k++) {
    const xv = x0 + (k / 4) * (x1 - x0), yv = y0 + (k / 4) * (y1 - y0);
    ctx.fillText(fmt(xv, 4), sx(xv) - 14, H - pad + 15);
    ctx.fillText(fmt(yv, 3), 4, sy(yv) + 4);
  }
  ctx.fillText("omega1 (rad/s)", pad + (W - 1.5 * pad) / 2 - 30, H - pad + 30);
  ctx.fillText("max |gap - c0| (mm)", pad + 4, pad / 2 + 12);
  ctx.strokeStyle = "#999"; ctx.setLineDash([2, 3]);
  ctx.beginPath(); ctx.moveTo(sx(b.design), pad / 2); ctx.lineTo(sx(b.design), H - pad); ctx.stroke();
  ctx.fillText("this design", sx(b.design) + 3, H - pad - 4);
  ctx.strokeStyle = "#c62828"; ctx.lineWidth = 2;
  const P = b.points;
  let i = 1;
  while (i < P.length) {
    const st = P[i].stable;
    ctx.beginPath(); ctx.setLineDash(st ? [] : [6, 4]);
    ctx.moveTo(sx(P[i - 1].x), sy(P[i - 1].size * 1e3));
    while (i < P.length && P[i].stable === st) { ctx.lineTo(sx(P[i].x), sy(P[i].size * 1e3)); i++; }
    ctx.stroke();
  }
  ctx.setLineDash([]); ctx.fillStyle = "#283593";
  const mark = (x, y, label) => { ctx.beginPath(); ctx.arc(sx(x), sy(y), 4, 0, 2 * Math.PI); ctx.fill(); ctx.fillText(label, sx(x) + 5, sy(y) - 5); };
  if (b.hopf) mark(b.hopf.x, 0, b.hopf.label);
  for (const p of b.special) mark(p.x, p.size * 1e3, p.label);
}
function drawTile(ctx, t, sx, sy, half) {
  // the headline chi on the tile: one cell per point (colour from the tile's smallest to
  // its largest chi, its value written in it; grey: unstable or unresolved)
  const vals = t.chi.flat().filter((v) => v !== null);
  const lo = Math.min(...vals), hi = Math.max(...vals);
  const hx = half(t.x), hy = half(t.y);
  ctx.save();
  ctx.font = "10px sans-serif";
  t.y.forEach((y, r) => t.x.forEach((x, c) => {
    const v = t.chi[r][c];
    const f = v === null ? null : (hi > lo ? (v - lo) / (hi - lo) : 0.5);
    ctx.fillStyle = f === null ? "#ddd" : `hsl(${240 - 190 * f}, 70%, ${82 - 22 * f}%)`;
    const x0 = sx(x - hx), x1 = sx(x + hx), y0 = sy(y + hy), y1 = sy(y - hy);
    ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
    ctx.fillStyle = "#333";
    ctx.fillText(v === null ? "–" : v.toFixed(2), (x0 + x1) / 2 - 10, (y0 + y1) / 2 + 3);
  }));
  ctx.restore();
}
function currentDesign(names) {
  const byName = Object.fromEntries(S.controls.map((c) => [c.name, c.value]));
  const v = names.map((n) => byName[n]);
  return v.every((x) => typeof x === "number") ? v : null;
}
function markHopf() { if (S.hopf) drawHopf(); }

// ----- background jobs --------------------------------------------------------------
// each kind has its buttons and status line (prefix) and the key of what its result
// depends on; a job of another kind running makes a new one wait ("queued")
const JOBS = {
  hopf_curve: { prefix: "job" },
  tile: { prefix: "tile" },
  speed: { prefix: "speed" },
  cycle_branch: { prefix: "branch" },
};
function speedKey() { return curveKey(S.preset, S.values) + "|" + PLANE_KEY() + "|v=" + S.v; }
function PLANE_KEY() { return ["omega1", "sigma", "L", "EI", "mbar"].map((n) => S.values[n]).join(","); }
// the beam data enter model A only through omega1 and sigma
const PLANE = new Set(["omega1", "sigma", "L", "EI", "mbar"]);
function curveKey(preset, values) {
  // what the Hopf curve depends on: not the plane's own two parameters and, in the
  // (omega1, sigma) plane, not the beam data L, EI, mbar (they enter through omega1, sigma)
  const skip = new Set(S.hopf ? S.hopf.names : []);
  if (skip.has("omega1") && skip.has("sigma")) for (const n of ["L", "EI", "mbar"]) skip.add(n);
  return preset + "|" + Object.keys(values).filter((k) => !skip.has(k)).sort()
    .map((k) => k + "=" + values[k]).join("&");
}
function tileKey(preset, values) {
  // what the tile depends on besides its plane: the preset and every other value
  return preset + "|" + Object.keys(values).filter((k) => !PLANE.has(k)).sort()
    .map((k) => k + "=" + values[k]).join("&");
}
async function startJob(kind = "hopf_curve") {
  const seq = ++S.seq;
  const preset = S.preset, values = Object.assign({}, S.values);
  if (kind === "hopf_curve") S.jobKey = curveKey(preset, values);
  if (kind === "tile") S.tileKey = tileKey(preset, values);
  if (kind === "speed") S.speedKey = speedKey();
  const extra = kind === "speed" ? "&v=" + encodeURIComponent(S.v) : "";
  const r = await getJSON(`/api/job?kind=${kind}&seq=${seq}&` + queryOf(preset, values) + extra, { method: "POST" });
  if (!r) return;
  if (r.body.errors) { showFieldErrors(r.body.errors); return; }
  if (r.body.error) return;
  r.body.preset = preset; r.body.values = values;
  JOBS[kind].job = r.body;
  showJob(kind, r.body);
  pollJob(kind, r.body.id);
}
function pollJob(kind, id) {
  const J = JOBS[kind];
  clearTimeout(J.timer);
  J.timer = setTimeout(async () => {
    if (!J.job || J.job.id !== id) return;
    const r = await getJSON("/api/job/" + id);
    if (!r || !J.job || J.job.id !== id) return;
    Object.assign(J.job, r.body);
    showJob(kind, J.job);
    if (r.body.status === "running" || r.body.status === "queued") pollJob(kind, id);
  }, 300);
}
function showJob(kind, j) {
  const p = JOBS[kind].prefix;
  $(p + "-cancel").disabled = !(j.status === "running" || j.status === "queued");
  const last = j.progress.length ? j.progress[j.progress.length - 1] : "";
  $(p + "-status").textContent = j.status === "running" ? "running: " + (last || "starting the worker ...")
    : j.status === "queued" ? "queued: waits for the running background job"
    : j.status === "error" ? "failed: " + j.error : j.status;
  $(p + "-status").dataset.status = j.status;
  if (j.status === "done" && j.result) DONE[kind](j);
  if (kind === "tile" && j.status === "error") { S.tileRefused = j.error; S.tile = null; showInterp(); drawHopf(); }
}
const DONE = {
  speed(j) {
    const r = j.result;
    $("chi-v").textContent = r.chi_v === null ? "not found" : r.chi_v.toFixed(3) + ` at ${fmt(r.v)} km/h`;
    $("chi-v").dataset.value = r.chi_v === null ? "" : String(r.chi_v);
    $("chi-0").textContent = r.standstill_chi === null ? "–" : r.standstill_chi.toFixed(3);
    $("daf-v").textContent = fmt(r.daf_v) + (r.stable_v === false ? " (periodic response unstable)" : "");
    $("wz-v").textContent = fmt(r.wz_v, 3);
    plotInto("speed-plot", {
      width: 320, height: 180, scales: { x: { time: false }, daf: {}, wz: {} },
      axes: [{ label: "v (km/h)" }, { scale: "daf", label: "DAF" }, { scale: "wz", side: 1, label: "Wz", grid: { show: false } }],
      series: [{ label: "v" }, { label: "DAF", scale: "daf", stroke: "#1565c0", width: 2 },
        { label: "Wz", scale: "wz", stroke: "#ef6c00", width: 2 }],
    }, [r.kmh, r.daf, r.wz]);
  },
  cycle_branch(j) { S.branch = j.result; drawBranch(); },
  hopf_curve(j) {
    S.hopf = j.result;
    if (j.values) S.jobKey = curveKey(j.preset, j.values);  // now that the plane is known
    drawHopf();
    const rows = ["branch,l1," + j.result.names.join(",")];
    j.result.branches.forEach((b, k) => b.x.forEach((x, i) => rows.push(`${k + 1},${b.l1[i]},${x},${b.y[i]}`)));
    $("x-hopf-csv").href = "data:text/csv;charset=utf-8," + encodeURIComponent(rows.join("\n") + "\n");
  },
  tile(j) {
    S.tile = j.result;
    S.tile.key = tileKey(j.preset, j.values);
    showInterp();
    drawHopf();
    const rows = ["omega1,sigma,chi"];
    j.result.y.forEach((y, r) => j.result.x.forEach((x, c) => rows.push(`${x},${y},${j.result.chi[r][c] ?? "nan"}`)));
    $("x-tile-csv").href = "data:text/csv;charset=utf-8," + encodeURIComponent(rows.join("\n") + "\n");
  },
};
async function cancelJob(kind = "hopf_curve") {
  const J = JOBS[kind];
  if (!J.job) return;
  const r = await getJSON("/api/job/" + J.job.id + "/cancel", { method: "POST" });
  if (r) {
    Object.assign(J.job, r.body); showJob(kind, J.job);
    if (kind === "hopf_curve") S.jobKey = null;
    if (kind === "tile") S.tileKey = null;
  }
}

// ----- chi interpolated from the map tile (while a slider moves) --------------------
function interpolated() {
  // the headline chi at the shown design, bilinear in (omega1, sigma) between the tile's
  // four points around it; a reason instead of a number outside the tile, for a change
  // of anything but the plane's parameters, or next to an unresolved point
  const t = S.tile;
  if (S.tileRefused) return { text: "no tile: " + S.tileRefused };
  if (!t) return { text: "no tile yet" };
  if (t.key !== tileKey(S.preset, S.values)) return { text: "no tile here (a value off the tile's plane changed)" };
  const w = S.modal && S.modal.omega1, sg = S.modal && S.modal.sigma;
  const X = t.x, Y = t.y;
  if (!(w >= X[0] && w <= X[X.length - 1] && sg >= Y[0] && sg <= Y[Y.length - 1]))
    return { text: "no tile here (outside the tile)" };
  let i = 0, j = 0;
  while (i < X.length - 2 && w > X[i + 1]) i++;
  while (j < Y.length - 2 && sg > Y[j + 1]) j++;
  const u = (w - X[i]) / (X[i + 1] - X[i]), v = (sg - Y[j]) / (Y[j + 1] - Y[j]);
  const c = [t.chi[j][i], t.chi[j][i + 1], t.chi[j + 1][i], t.chi[j + 1][i + 1]];
  if (c.some((z) => z === null)) return { text: "no tile here (an unresolved or unstable point next to it)" };
  const chi = (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + (1 - u) * v * c[2] + u * v * c[3];
  return { chi, text: chi.toFixed(3) + " (interpolated)" };
}
function showInterp() {
  const r = interpolated(), e = $("chi-interp");
  e.textContent = r.text;
  e.dataset.state = r.chi === undefined ? "none" : "interpolated";
  e.dataset.value = r.chi === undefined ? "" : String(r.chi);
  // while a slider moves, the big number is the interpolated one, marked as such
  if (S.moving && r.chi !== undefined) {
    $("chi").textContent = r.chi.toFixed(3);
    $("chi").dataset.state = "interpolated";
    $("chi-mark").textContent = "interpolated from the map tile (release for the exact index)";
  } else if (S.moving && S.chiText !== undefined && $("chi").dataset.state === "interpolated") {
    $("chi").textContent = S.chiText;  // off the tile: the last released index, marked
    $("chi").dataset.state = "released";
    $("chi-mark").textContent = "at the last released design (release to recompute)";
  }
}
function tileCovers() {
  const t = S.tile, w = S.modal && S.modal.omega1, sg = S.modal && S.modal.sigma;
  return t && t.key === tileKey(S.preset, S.values) && w >= t.x[0] && w <= t.x[t.x.length - 1]
    && sg >= t.y[0] && sg <= t.y[t.y.length - 1];
}

// ----- start --------------------------------------------------------------------------
async function load(fromHistory) {
  const st = stateFromLocation();
  S.preset = st.preset;
  S.values = {};
  S.v = st.v;
  $("field-v").value = st.v; $("slider-v").value = Number(st.v) || 0;
  for (const el of document.querySelectorAll(".err")) el.textContent = "";
  const r = await getJSON("/api/init?" + queryOf(st.preset, st.values));
  if (!r) return;
  const b = r.body;
  S.model = b.model;
  $("model-label").textContent = "model " + b.model;
  if (!S.controls.length) buildControls(b.controls);
  const sel = $("preset");
  if (!sel.options.length) for (const p of b.presets) sel.add(new Option(p, p));
  S.preset = b.state.preset;
  sel.value = S.preset;
  for (const [k, v] of Object.entries(b.state)) if (k !== "preset") S.values[k] = Number(v);
  showControls(b.controls);
  if (Object.keys(b.errors).length) {
    showFieldErrors(b.errors);
    setStatus("idle", "value refused");
    return;  // a refused URL value: nothing is computed
  }
  quick();
  release();
}
window.addEventListener("popstate", () => load(true));
document.addEventListener("DOMContentLoaded", () => {
  $("preset").addEventListener("change", () => {
    S.preset = $("preset").value;
    S.values = {};
    history.pushState({}, "", "?" + currentQuery());
    load(false);
  });
  const speedTo = (raw) => {
    clearFieldError("v");
    S.v = raw;
    $("field-v").value = raw;
    pushState();
    if (hasSpeed()) startJob("speed");
    else { $("speed-status").textContent = "v = 0: standstill"; $("speed-status").dataset.status = ""; }
  };
  $("slider-v").addEventListener("input", () => { $("field-v").value = $("slider-v").value; });
  $("slider-v").addEventListener("change", () => speedTo($("slider-v").value));
  $("field-v").addEventListener("change", () => speedTo($("field-v").value.trim()));
  for (const kind of Object.keys(JOBS)) {
    $(JOBS[kind].prefix + "-start").addEventListener("click", () => startJob(kind));
    $(JOBS[kind].prefix + "-cancel").addEventListener("click", () => cancelJob(kind));
  }
  S.zoom = true;
  $("zoom").addEventListener("change", () => { S.zoom = $("zoom").checked; drawHopf(); });
  load(false);
});
