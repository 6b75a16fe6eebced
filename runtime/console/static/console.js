// omnijax operator's console: polls GET /api/status, reloads the live images, and sends the
// operator's requests with the token of the page's address (Authorization: Bearer TOKEN).
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token");
const $ = (id) => document.getElementById(id);
const state = { mode: "select", status: null, zones: [], drawing: [], calibration: null, zonesVersion: -1, views: 1 };
const COLOURS = { ignore: "rgba(255, 80, 80, %)", priority: "rgba(80, 220, 80, %)" };

function say(text, ok = false) {
  const m = $("message");
  m.textContent = text;
  m.className = ok ? "ok" : "";
}

async function api(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (TOKEN) headers["Authorization"] = "Bearer " + TOKEN;
  const res = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  let data = null;
  try { data = await res.json(); } catch (e) { data = null; }
  if (!res.ok) {
    const why = data && data.error ? data.error : res.status + " " + res.statusText;
    say(why);
    throw new Error(why);
  }
  return data;
}
const post = (path, body) => api("POST", path, body === undefined ? {} : body);

// -- live images ------------------------------------------------------------------------

function live(img, name, every) {
  let n = 0;
  const next = () => setTimeout(() => { img.src = "/api/view/" + name + ".jpg?n=" + (n++); }, every);
  img.addEventListener("load", () => { if (name === "omni") sizeOverlay(); next(); });
  img.addEventListener("error", () => setTimeout(next, 500));
  next();
}

// every PTZ after the first gets a view of its own (GET /api/view/ptzK.jpg), made once the status says how many
function moreViews(cameras) {
  if (cameras.length <= state.views) return;
  for (let k = state.views; k < cameras.length; k++) {
    const box = document.createElement("div"), img = document.createElement("img"), label = document.createElement("div");
    box.className = "view";
    img.id = "ptz" + k;
    img.alt = "PTZ " + k + "'s view";
    label.className = "view-label";
    label.id = "ptz-label" + k;
    box.append(img, label);
    $("more-views").appendChild(box);
    live(img, "ptz" + k, 300);
  }
  const pick = $("camera");
  pick.innerHTML = "";
  cameras.forEach((c) => {
    const o = document.createElement("option");
    o.value = c.id;
    o.textContent = c.id;
    pick.appendChild(o);
  });
  $("camera-pick").hidden = false;
  $("cameras-row").hidden = false;
  state.views = cameras.length;
}

const camera = () => (state.views > 1 ? { camera: Number($("camera").value) } : {});

function sizeOverlay() {
  const img = $("omni"), c = $("overlay");
  if (img.naturalWidth && (c.width !== img.naturalWidth || c.height !== img.naturalHeight)) {
    c.width = img.naturalWidth;
    c.height = img.naturalHeight;
    draw();
  }
}

function imagePoint(ev) {
  const c = $("overlay"), r = c.getBoundingClientRect();
  return [(ev.clientX - r.left) * c.width / r.width, (ev.clientY - r.top) * c.height / r.height];
}

// -- status -----------------------------------------------------------------------------

const fmt = (v, d = 1) => (v === null || v === undefined ? "-" : Number(v).toFixed(d));

function showStatus(s) {
  state.status = s;
  $("conn").textContent = s.starting ? "starting (learning the background, compiling)" : "live";
  if (s.starting) return;
  $("status-frames").textContent = s.frames;
  $("status-fps").textContent = fmt(s.fps);
  $("status-latency").textContent = "p50 " + fmt(s.latency_ms.p50, 2) + " ms, p99 " + fmt(s.latency_ms.p99, 2) + " ms";
  $("status-tracks").textContent = s.tracks.length + (s.tracks.length ? ": " + s.tracks.map(
    (t) => "#" + t.id + (t.trusted ? "" : "?") + (t.captured ? " (face)" : "")).join(", ") : "");
  $("status-target").textContent = s.manual ? "manual" : (s.target === null ? "none" : String(s.target));
  const cams = s.cameras || [];
  moreViews(cams);
  if (cams.length > 1) {
    $("status-cameras").textContent = cams.map((c) => c.id + ": " + (c.manual ? "manual" : c.target === null
      ? (c.held || "none") : "#" + c.target + " x" + fmt(c.zoom, 1))).join(", ");
    cams.slice(1).forEach((c) => { const l = $("ptz-label" + c.id); if (l) l.textContent = c.view || ""; });
  }
  $("status-held").textContent = s.held || "-";
  $("ptz-label").textContent = s.ptz_view || "";
  const p = s.ptz || {};
  $("status-zoom").textContent = "x" + fmt(p.zoom, 2) + " (" + p.zoom_rule + ", p_contain " + p.p_contain +
    (p.probability !== undefined && p.probability !== null ? ", predicted " + fmt(p.probability, 3) : "") + ")";
  $("status-ptz").textContent = "pan " + fmt(p.pan_deg) + " deg, tilt " + fmt(p.tilt_deg) + " deg" +
    (p.sd_pan_deg !== undefined ? ", sd " + fmt(p.sd_pan_deg, 2) + " / " + fmt(p.sd_tilt_deg, 2) + " deg" : "");
  const l = p.link;
  $("status-link").textContent = l ? (l.connected ? "online" : "OFFLINE") + ", " + l.commands + " commands, " +
    l.errors + " errors, " + l.reconnects + " reconnects" : "no PTZ";
  const f = s.faults;
  $("status-faults").textContent = "broken " + f.broken + ", wrong size " + f.wrong_size + ", stale " + f.stale +
    ", dropped " + f.dropped;
  const o = s.operator;
  $("status-operator").textContent = !o ? "-" : [o.paused ? "paused" : "automatic",
    o.target !== null ? "chose #" + o.target : "", o.point ? "manual for " + fmt(o.point.remaining_s, 0) + " s" : ""]
    .filter(Boolean).join(", ");
  $("zones-state").textContent = s.zones_pending ? "(applying...)" : "";
  draw();
}

async function pollStatus() {
  try {
    showStatus(await (await fetch("/api/status")).json());
  } catch (e) {
    $("conn").textContent = "disconnected";
  }
  setTimeout(pollStatus, 250);
}

async function pollSlow() {
  try {
    const ev = await (await fetch("/api/events")).json();
    $("events").innerHTML = "";
    for (const e of ev.events.slice().reverse()) {
      const li = document.createElement("li");
      li.textContent = e.time.slice(11, 19) + " " + e.event.replace("_", " ") + " #" + e.track +
        " at (" + e.xy.map((v) => v.toFixed(1)).join(", ") + ") m";
      $("events").appendChild(li);
    }
    const faces = await (await fetch("/api/faces")).json();
    $("faces").innerHTML = "";
    for (const f of faces.faces.slice().reverse()) {
      const img = document.createElement("img");
      img.src = f.image;
      img.title = "#" + f.track + " " + f.time;
      $("faces").appendChild(img);
    }
    const z = await (await fetch("/api/zones")).json();
    if (z.version !== state.zonesVersion) {
      state.zonesVersion = z.version;
      state.zones = z.zones;
      listZones();
    }
    if (z.error) say(z.error);
  } catch (e) { /* the next poll tries again */ }
  setTimeout(pollSlow, 1000);
}

// -- drawing the overlay ----------------------------------------------------------------

function polygon(ctx, pts, kind, closed) {
  if (!pts.length) return;
  ctx.beginPath();
  ctx.moveTo(pts[0][0], pts[0][1]);
  for (const p of pts.slice(1)) ctx.lineTo(p[0], p[1]);
  if (closed) {
    ctx.closePath();
    ctx.fillStyle = COLOURS[kind].replace("%", "0.18");
    ctx.fill();
  }
  ctx.strokeStyle = COLOURS[kind].replace("%", "0.9");
  ctx.lineWidth = 2;
  ctx.stroke();
  for (const p of pts) ctx.fillRect(p[0] - 2, p[1] - 2, 4, 4);
}

function draw() {
  const c = $("overlay"), ctx = c.getContext("2d");
  ctx.clearRect(0, 0, c.width, c.height);
  for (const z of state.zones) polygon(ctx, z.points, z.kind, true);
  if (state.mode === "ignore" || state.mode === "priority") polygon(ctx, state.drawing, state.mode, false);
  if (state.calibration) {
    ctx.strokeStyle = "#ffd54a";
    for (const [x, y] of state.calibration.pixels) {
      ctx.beginPath();
      ctx.arc(x, y, 6, 0, 2 * Math.PI);
      ctx.stroke();
    }
  }
}

function listZones() {
  const ul = $("zones-list");
  ul.innerHTML = "";
  state.zones.forEach((z, k) => {
    const li = document.createElement("li");
    li.className = z.kind;
    li.textContent = z.kind + (z.name ? " '" + z.name + "'" : "") + ", " + z.points.length + " points ";
    const del = document.createElement("button");
    del.textContent = "remove";
    del.onclick = () => saveZones(state.zones.filter((_, j) => j !== k));
    li.appendChild(del);
    ul.appendChild(li);
  });
  draw();
}

async function saveZones(zones) {
  const r = await post("/api/zones", { zones });
  state.zones = r.zones;
  state.zonesVersion = r.version;
  listZones();
  say("zones saved" + (r.saved ? " in " + r.saved : "") + "; the detector takes them in at once", true);
}

// -- modes and clicks -------------------------------------------------------------------

const HINTS = {
  select: "Click a person to make them the target; click the floor to point the PTZ there (until 'End manual' or 30 s).",
  ignore: "Click the corners of the region to ignore (a screen, a window, a door), then 'Finish zone'.",
  priority: "Click the corners of the region whose people are targeted first, then 'Finish zone'.",
  calibrate: "Arrow keys drive the PTZ (Shift: fine; + / -: zoom). Crosshair on the mark: click the mark's foot.",
};

function setMode(mode) {
  state.mode = mode;
  state.drawing = [];
  for (const b of document.querySelectorAll("#modes button[data-mode]")) b.classList.toggle("on", b.dataset.mode === mode);
  $("draw-tools").hidden = !(mode === "ignore" || mode === "priority");
  $("hint").textContent = HINTS[mode];
  if (mode === "calibrate") { $("calibration").open = true; $("overlay").focus(); refreshCalibration(); }
  draw();
}

async function click(ev) {
  const [x, y] = imagePoint(ev);
  if (state.mode === "ignore" || state.mode === "priority") {
    state.drawing.push([Math.round(x * 10) / 10, Math.round(y * 10) / 10]);
    draw();
    return;
  }
  if (state.mode === "calibrate") {
    const h = parseFloat($("cal-height").value || "0");
    say("recording: waiting for the PTZ to stand still ...", true);
    showCalibration(await post("/api/calibration/mark", { x, y, height_m: h }));
    say("recorded", true);
    return;
  }
  const s = state.status;
  if (!s || s.starting) return;
  let best = null, bestD = 30;
  for (const t of s.tracks) {
    const d = Math.hypot(t.px[0] - x, t.px[1] - y);
    if (d < bestD) { best = t; bestD = d; }
  }
  if (best) {
    await post("/api/target", { track: best.id });
    say("target: #" + best.id, true);
  } else {
    const r = await post("/api/point", { x, y, ...camera() });
    say("PTZ pointed at the floor there: pan " + r.pan_deg.toFixed(1) + ", tilt " + r.tilt_deg.toFixed(1), true);
  }
}

async function finishZone() {
  if (state.drawing.length < 3) { say("a zone needs 3 corners at least"); return; }
  const zone = { kind: state.mode, points: state.drawing };
  const name = $("zone-name").value.trim();
  if (name) zone.name = name;
  await saveZones(state.zones.concat([zone]));
  state.drawing = [];
  $("zone-name").value = "";
  draw();
}

async function key(ev) {
  if (state.mode !== "calibrate") return;
  const step = ev.shiftKey ? 0.1 : 1.0;
  const moves = { ArrowLeft: { dpan_deg: -step }, ArrowRight: { dpan_deg: step }, ArrowUp: { dtilt_deg: step },
    ArrowDown: { dtilt_deg: -step }, "+": { zoom_factor: 1.25 }, "=": { zoom_factor: 1.25 }, "-": { zoom_factor: 0.8 } };
  const move = moves[ev.key];
  if (!move) return;
  ev.preventDefault();
  const r = await post("/api/ptz", { ...move, seconds: 600, ...camera() });
  say("PTZ pan " + r.pan_deg.toFixed(2) + ", tilt " + r.tilt_deg.toFixed(2) + ", zoom x" + r.zoom.toFixed(2), true);
}

// -- calibration ------------------------------------------------------------------------

async function refreshCalibration() {
  showCalibration(await (await fetch("/api/calibration")).json());
}

function showCalibration(c) {
  state.calibration = c;
  const t = $("cal-table");
  t.innerHTML = "<tr><th>position</th><th>r_f px</th><th>theta_f</th><th>aims (height m: pan, tilt deg)</th></tr>";
  for (const p of c.observations) {
    const tr = document.createElement("tr");
    tr.innerHTML = "<td>" + p.label + "</td><td>" + p.r_f.toFixed(1) + "</td><td>" + p.theta_f.toFixed(3) + "</td><td>" +
      p.aims.map((a) => a.height_m + ": " + a.pan_deg.toFixed(2) + ", " + a.tilt_deg.toFixed(2)).join("; ") + "</td>";
    t.appendChild(tr);
  }
  $("cal-fit").disabled = !c.ready || c.running;
  const out = $("cal-result");
  if (c.error) out.textContent = "fit refused: " + c.error;
  else if (c.result) {
    const rows = Object.entries(c.result.params).map(([n, p]) => "<tr><td>" + n + "</td><td>" +
      Number(p.value).toPrecision(6) + "</td><td>" + Number(p.sigma).toPrecision(3) + "</td><td>" + (p.unit || "") +
      "</td></tr>").join("");
    out.innerHTML = "<table><tr><th>parameter</th><th>value</th><th>sigma</th><th>unit</th></tr>" + rows + "</table>" +
      "<p>residuals rms " + c.result.rms_residual_deg.toFixed(3) + " deg (pan " +
      c.result.residuals_deg.pan.map((v) => v.toFixed(2)).join(", ") + "; tilt " +
      c.result.residuals_deg.tilt.map((v) => v.toFixed(2)).join(", ") + "); written to " + c.result.folder + "</p>";
  } else out.textContent = c.running ? "fitting ..." : "";
  draw();
}

// -- wiring -----------------------------------------------------------------------------

function wire() {
  if (!TOKEN) say("read-only: open the address printed at start (with ?token=...) to control the system");
  for (const b of document.querySelectorAll("#modes button[data-mode]")) b.onclick = () => setMode(b.dataset.mode);
  $("overlay").addEventListener("click", (ev) => click(ev).catch(() => {}));
  document.addEventListener("keydown", (ev) => key(ev).catch(() => {}));
  $("zone-finish").onclick = () => finishZone().catch(() => {});
  $("zone-undo").onclick = () => { state.drawing.pop(); draw(); };
  $("zone-cancel").onclick = () => setMode("select");
  $("auto").onclick = () => post("/api/target", { track: null }).then(() => say("automatic target", true)).catch(() => {});
  $("pause").onclick = () => post("/api/pause", { paused: true }).then(() => say("paused", true)).catch(() => {});
  $("resume").onclick = () => post("/api/pause", { paused: false }).then(() => say("resumed", true)).catch(() => {});
  $("home").onclick = () => post("/api/home", camera()).then(() => say("PTZ sent home", true)).catch(() => {});
  $("release").onclick = () => post("/api/release").then(() => say("manual pointing ended", true)).catch(() => {});
  $("cal-fit").onclick = () => {
    $("cal-result").textContent = "fitting ...";
    post("/api/calibration/fit").then(showCalibration).catch(() => refreshCalibration());
  };
  $("cal-clear").onclick = () => post("/api/calibration/clear").then(showCalibration).catch(() => {});
  setMode("select");
  live($("omni"), "omni", 80);
  live($("ptz"), "ptz", 150);
  pollStatus();
  pollSlow();
}

wire();
