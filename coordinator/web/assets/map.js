// The live map of an idmesh deployment. Plain JavaScript, no library:
// Server-Sent Events from the gateway (the same paths as its REST API,
// `Accept: text/event-stream`) feed one state object, and every change
// redraws the canvas and the panels.
//
// Tracks sit at their last known position (query/positions) coloured by
// P(red) from query/marginals, ringed in the colour of the leader that
// surveils them; on identity streams each is labelled with its most likely
// identity and that probability (query/identity). Leaders are diamonds at
// the centre of their regions, the regions shaded (the rectangles the
// answer gives under fitted cells; otherwise the points nearer to a
// leader than to any other). Labels are elements over the canvas, placed
// by labels.js so that none covers another or a marker; a track whose
// label finds no room shows it while the pointer is on it, and the
// selected track (click it, or its row) always shows its own.
// `degraded` names who is missing: the coordinator's own error, and the
// leaders of the stream that query/stats did not hear from.
//
// The charts plot the last minutes: the gateway's own history (/history)
// on load, then what the streams say.
"use strict";

const PREFIX = document.querySelector('meta[name="idmesh-prefix"]').content;
const API = "/" + PREFIX + "/query/";
const LEADER_COLOURS = ["#d69e2e", "#38a169", "#805ad5", "#dd6b20", "#319795", "#d53f8c", "#2c5282", "#718096"];
const RADIUS = 8;
// Half-sizes of the markers' boxes, which no label may cover: a track's
// ring, a leader's diamond with the cross of a missing one.
const TRACK_BOX = RADIUS + 2, LEADER_BOX = 13;
// `?placement=off` draws every label at its first spot, overlaps and all:
// the map before placement, for the tests that prove overlaps are seen.
const PLACEMENT = new URLSearchParams(location.search).get("placement") !== "off";

const state = {
  marginals: null, identity: null, positions: null, stats: null,
  identityStream: null, // unknown until the coordinator says
  failures: {}, connected: false,
  // Chart series: {t: ms on this page's clock, v: value or null (a gap)}.
  rates: [], latencies: [], span: 300000, last: null,
  bounds: null, regions: null, drawn: [], firstMapMs: null,
  selected: null, hover: null, spots: new Map(), markers: [],
};

// P(red) 0 → blue, 1 → red, linear in RGB (the legend's ramp).
function colourOf(p) {
  const q = Math.min(1, Math.max(0, p));
  return [Math.round(49 + 180 * q), Math.round(130 - 68 * q), Math.round(206 - 144 * q)];
}
const rgb = (c) => `rgb(${c[0]},${c[1]},${c[2]})`;
const eventsOf = (w) => Object.values(w || {}).reduce((a, b) => a + b, 0);
// The owner of a track no leader surveils yet (before its first event).
const UNHELD = 65535;
const leaderColour = (i) => (i === UNHELD ? "#cbd5e0" : LEADER_COLOURS[i % LEADER_COLOURS.length]);
const leaderName = (p, i) => (i === UNHELD ? "none yet" : p.leaders[i].name);
const escape = (s) => String(s).replace(/[&<>"']/g, (c) => "&#" + c.charCodeAt(0) + ";");

// A point of a chart, and the points older than the chart's span dropped.
function push(series, t, v) {
  series.push({ t, v });
  while (series.length && series[0].t < t - state.span) series.shift();
}

function listen(question, interval, onAnswer, onFailure) {
  const source = new EventSource(API + question + "?interval=" + interval);
  source.addEventListener("answer", (e) => {
    state.failures[question] = null;
    state.connected = true;
    onAnswer(JSON.parse(e.data));
    schedule();
  });
  source.addEventListener("failure", (e) => {
    let message = e.data;
    try { message = JSON.parse(e.data).error; } catch (_) { /* not JSON: as it came */ }
    state.connected = true;
    if (!(onFailure && onFailure(message, source))) state.failures[question] = message;
    schedule();
  });
  if (question === "marginals") {
    source.addEventListener("latency", (e) => {
      const l = JSON.parse(e.data);
      push(state.latencies, Date.now(), l.status === 200 ? l.ms : null);
    });
  }
  source.onerror = () => { state.connected = false; schedule(); };
  return source;
}

// The gateway's last minutes, before the streams' first answers: its
// clock shifted onto this page's, each sample a point of both charts.
async function loadHistory() {
  try {
    const h = await (await fetch("/history")).json();
    const shift = Date.now() - h.now_ms;
    state.span = Math.max(state.span, h.every_ms * h.capacity);
    const rates = [], latencies = [];
    for (const s of h.samples) {
      rates.push({ t: s.at_ms + shift, v: s.rate });
      latencies.push({ t: s.at_ms + shift, v: s.latency_ms });
    }
    // Whatever the streams said meanwhile comes after.
    state.rates = rates.concat(state.rates);
    state.latencies = latencies.concat(state.latencies);
    schedule();
  } catch (e) {
    console.warn("no history from the gateway:", e);
  }
}

function start() {
  loadHistory();
  listen("marginals", 500, (a) => {
    const now = performance.now(), events = eventsOf(a.watermark);
    if (state.last && now > state.last.t && events >= state.last.events) {
      push(state.rates, Date.now(), (events - state.last.events) / ((now - state.last.t) / 1000));
    }
    state.last = { t: now, events };
    state.marginals = a;
  });
  listen("positions", 500, (a) => { state.positions = a; });
  listen("stats", 1000, (a) => { state.stats = a; });
  listen("identity", 1000, (a) => { state.identityStream = true; state.identity = a; }, (message, source) => {
    if (message.includes("carries no identities")) {
      state.identityStream = false;
      source.close();
      return true;
    }
    return false;
  });
  listenToPointer();
}

let pending = false;
function schedule() {
  if (!pending) { pending = true; requestAnimationFrame(flush); }
}
// A render asked for and not yet drawn, drawn now: the next frame's, or a
// snapshot's, which must show the state it reports (a busy or hidden
// page can hold its frames back for seconds).
function flush() {
  if (pending) { pending = false; render(); }
}

// Who is missing: leaders of the stream that query/stats did not hear from.
function missingLeaders() {
  if (!state.positions || !state.stats) return [];
  const answering = new Set(state.stats.leaders.map((l) => l.leader));
  return state.positions.leaders.map((l) => l.name).filter((n) => !answering.has(n));
}

function render() {
  const missing = missingLeaders();
  renderStatus(missing);
  renderFigures();
  drawMap(missing);
  drawChart("chart-rate", state.rates, "#2c5282");
  drawChart("chart-latency", state.latencies, "#c05621");
  renderLeaders(missing);
  renderSensors();
  renderTracks();
}

function renderStatus(missing) {
  const problems = Object.entries(state.failures).filter(([, m]) => m).map(([q, m]) => `${q}: ${m}`);
  const degraded = missing.length > 0 || problems.some((p) => p.includes("degraded"));
  const status = document.getElementById("status");
  if (!state.connected) {
    status.className = "status offline";
    status.textContent = "gateway unreachable";
  } else if (degraded) {
    status.className = "status degraded";
    status.textContent = "degraded" + (missing.length ? ": " + missing.join(", ") + " missing" : "");
  } else {
    status.className = "status live";
    status.textContent = state.marginals && state.marginals.finished ? "live · stream over" : "live";
  }
  const banner = document.getElementById("problem");
  const lines = problems.slice();
  if (missing.length) lines.unshift(`leaders not answering: ${missing.join(", ")}`);
  banner.hidden = lines.length === 0;
  banner.innerHTML = lines.map(escape).join("<br>");
}

// The last value of a series that is not a gap.
const latest = (series) => { for (let i = series.length - 1; i >= 0; i--) if (series[i].v !== null) return series[i].v; };

function renderFigures() {
  const m = state.marginals;
  document.getElementById("watermark").textContent = m ? `${eventsOf(m.watermark)} events` : "–";
  document.getElementById("watermark").dataset.events = m ? eventsOf(m.watermark) : "";
  const rate = latest(state.rates);
  document.getElementById("rate").textContent = rate === undefined ? "–" : rate.toFixed(0);
  const latency = latest(state.latencies);
  document.getElementById("latency").textContent = latency === undefined ? "–" : latency.toFixed(1) + " ms";
  document.getElementById("sets").textContent = m ? `${m.coefficients} on ${m.leaders} leaders` : "–";
  const p = state.positions;
  document.getElementById("positions-at").textContent = p ? `positions at ${eventsOf(p.watermark)} events` : "";
}

// A canvas sized for the screen's pixel ratio, drawn in CSS pixels.
function context(id) {
  const canvas = document.getElementById(id);
  const ratio = window.devicePixelRatio || 1;
  const w = Number(canvas.getAttribute("width")), h = Number(canvas.getAttribute("height"));
  if (!canvas.dataset.w) {
    canvas.dataset.w = w; canvas.dataset.h = h;
    canvas.style.width = w + "px"; canvas.style.height = h + "px";
    canvas.width = w * ratio; canvas.height = h * ratio;
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  return { ctx, w: Number(canvas.dataset.w), h: Number(canvas.dataset.h) };
}

// The field's extent, only ever growing (so the map does not jump): the
// tracks, the leaders and their regions.
function bounds(p) {
  const points = p.positions.filter(Boolean).concat(p.leaders.map((l) => l.at).filter(Boolean));
  for (const l of p.leaders) if (l.region) points.push([l.region[0], l.region[1]], [l.region[2], l.region[3]]);
  if (points.length === 0) return null;
  let b = state.bounds ? state.bounds.slice() : [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of points) b = [Math.min(b[0], x), Math.min(b[1], y), Math.max(b[2], x), Math.max(b[3], y)];
  if (b[2] - b[0] < 1e-9) { b[0] -= 1; b[2] += 1; }
  if (b[3] - b[1] < 1e-9) { b[1] -= 1; b[3] += 1; }
  state.bounds = b;
  return b;
}

// How the field maps onto the canvas: `at` takes a field point to canvas
// pixels (y grows upwards in the field, downwards on the canvas).
function view(p, w, h) {
  const b = bounds(p);
  const strip = 34; // unplaced tracks wait in a strip along the bottom
  const pad = 24, fw = w - 2 * pad, fh = h - 2 * pad - strip;
  const scale = b ? Math.min(fw / (b[2] - b[0]), fh / (b[3] - b[1])) : 1;
  const ox = b ? pad + (fw - scale * (b[2] - b[0])) / 2 : pad, oy = b ? pad + (fh - scale * (b[3] - b[1])) / 2 : pad;
  const at = ([x, y]) => [ox + (x - b[0]) * scale, oy + (b[3] - y) * scale];
  return { b, strip, pad, fw, fh, scale, ox, oy, at, w, h };
}

function drawMap(missing) {
  const { ctx, w, h } = context("map");
  ctx.clearRect(0, 0, w, h);
  const p = state.positions;
  state.drawn = [];
  if (!p) {
    ctx.fillStyle = "#718096"; ctx.fillText("waiting for positions…", 20, 24);
    renderLabels([], []);
    return;
  }
  const v = view(p, w, h);
  if (v.b && p.leaders.every((l) => l.at)) drawRegions(ctx, v, p.leaders);
  ctx.strokeStyle = "#cbd5e0"; ctx.lineWidth = 1; ctx.strokeRect(v.pad - 6, v.pad - 6, v.fw + 12, v.fh + 12);
  const leaders = drawLeaders(ctx, v, p, missing);
  const tracks = drawTracks(ctx, v, p);
  const markers = leaders.markers.concat(tracks.markers);
  state.markers = markers;
  renderLabels(labelOrder(leaders.items, tracks.items), markers);
  if (state.drawn.some((d) => d.p_red !== null) && state.firstMapMs === null) {
    state.firstMapMs = performance.now();
    document.body.dataset.firstMapMs = state.firstMapMs.toFixed(1);
  }
}

// The most wanted labels first: the selected track's, the leaders', then
// the tracks' in order.
function labelOrder(leaders, tracks) {
  const selected = tracks.filter((i) => i.forced);
  return selected.concat(leaders, tracks.filter((i) => !i.forced));
}

function drawLeaders(ctx, v, p, missing) {
  const markers = [], items = [];
  p.leaders.forEach((l, i) => {
    if (!l.at || !v.b) return;
    const [x, y] = v.at(l.at);
    ctx.beginPath(); ctx.moveTo(x, y - 11); ctx.lineTo(x + 11, y); ctx.lineTo(x, y + 11); ctx.lineTo(x - 11, y); ctx.closePath();
    ctx.fillStyle = leaderColour(i); ctx.fill(); ctx.strokeStyle = "#1a202c"; ctx.lineWidth = 1.5; ctx.stroke();
    const gone = missing.includes(l.name);
    if (gone) {
      ctx.strokeStyle = "#c53030"; ctx.lineWidth = 3;
      ctx.beginPath(); ctx.moveTo(x - 13, y - 13); ctx.lineTo(x + 13, y + 13); ctx.moveTo(x + 13, y - 13); ctx.lineTo(x - 13, y + 13); ctx.stroke();
    }
    markers.push({ key: "leader " + l.name, ...Labels.markerBox(x, y, LEADER_BOX) });
    items.push({ key: "leader " + l.name, kind: "leader", x, y, r: LEADER_BOX,
      text: gone ? `${l.name} · missing` : l.name, missing: gone });
  });
  return { markers, items };
}

function drawTracks(ctx, v, p) {
  const m = state.marginals;
  const ident = state.identityStream && state.identity && state.identity.tracks === p.tracks ? state.identity : null;
  const values = m && m.tracks === p.tracks ? m.p_red : null;
  const markers = [], items = [];
  let unplaced = 0;
  for (let t = 0; t < p.tracks; t++) {
    let x, y;
    if (p.positions[t] && v.b) [x, y] = v.at(p.positions[t]);
    else { x = v.pad + RADIUS + (unplaced++) * 2.5 * RADIUS; y = v.h - v.strip / 2; }
    const value = values ? values[t] : null;
    const colour = value === null ? [160, 174, 192] : colourOf(value);
    ctx.beginPath(); ctx.arc(x, y, RADIUS + 2, 0, 2 * Math.PI);
    ctx.fillStyle = leaderColour(p.owners[t]); ctx.fill();
    ctx.beginPath(); ctx.arc(x, y, RADIUS - 1, 0, 2 * Math.PI);
    ctx.fillStyle = rgb(colour); ctx.fill();
    if (t === state.selected) {
      ctx.beginPath(); ctx.arc(x, y, RADIUS + 4, 0, 2 * Math.PI);
      ctx.strokeStyle = "#1a202c"; ctx.lineWidth = 2; ctx.stroke();
    }
    let text = String(t);
    if (ident) {
      const i = ident.predicted_identity[t];
      text += ` · id ${i} ${probabilityOf(ident.p_identity[t], i).toFixed(2)}`;
    }
    markers.push({ key: "track " + t, ...Labels.markerBox(x, y, TRACK_BOX) });
    items.push({ key: "track " + t, kind: "track", track: t, x, y, r: TRACK_BOX, text, forced: t === state.selected });
    state.drawn.push({ track: t, x, y, p_red: value, colour, owner: leaderName(p, p.owners[t]),
      identity: ident ? ident.predicted_identity[t] : null });
  }
  return { markers, items };
}

// The labels as elements over the canvas: written hidden, measured in one
// layout, placed, then shown where they found room.
function renderLabels(items, markers) {
  const layer = document.getElementById("labels");
  layer.innerHTML = items.map((i) =>
    `<span class="label ${i.kind}${i.missing ? " missing" : ""}${i.forced ? " selected" : ""}" data-key="${escape(i.key)}">${escape(i.text)}</span>`).join("");
  const spans = Array.from(layer.children);
  spans.forEach((span, n) => {
    const r = span.getBoundingClientRect();
    items[n].width = r.width; items[n].height = r.height;
  });
  const canvas = document.getElementById("map");
  const area = { left: 0, top: 0, width: Number(canvas.dataset.w), height: Number(canvas.dataset.h) };
  const where = PLACEMENT ? Labels.place(items, markers, area, state.spots) : Labels.unplaced(items);
  state.spots = new Map([...where].filter(([, s]) => s).map(([k, s]) => [k, s.spot]));
  spans.forEach((span, n) => {
    const item = items[n], spot = where.get(item.key);
    // A hidden label shows while the pointer is on its marker, at its
    // first spot, over whatever is there.
    const hovered = item.key === "track " + state.hover;
    const box = spot ? spot.box : hovered ? Labels.spots(item.x, item.y, item.r, item.width, item.height)[0] : null;
    if (!box) { span.hidden = true; return; }
    if (!spot) span.classList.add("hover");
    span.style.left = box.left + "px"; span.style.top = box.top + "px";
    span.style.visibility = "visible";
  });
}

// Shades each leader's region: the rectangle its answer gives (fitted
// cells), or else the canvas cells coloured by their nearest leader,
// computed once per extent and kept.
function drawRegions(ctx, v, leaders) {
  ctx.save(); ctx.globalAlpha = 0.13;
  if (leaders.every((l) => l.region)) {
    leaders.forEach((l, i) => {
      const [x0, y0] = v.at([l.region[0], l.region[3]]), [x1, y1] = v.at([l.region[2], l.region[1]]);
      ctx.fillStyle = leaderColour(i); ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
    });
    ctx.globalAlpha = 0.5; ctx.strokeStyle = "#718096"; ctx.lineWidth = 1;
    leaders.forEach((l) => {
      const [x0, y0] = v.at([l.region[0], l.region[3]]), [x1, y1] = v.at([l.region[2], l.region[1]]);
      ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
    });
  } else {
    ctx.drawImage(nearestCells(v, leaders), 0, 0, v.w, v.h - v.strip);
  }
  ctx.restore();
}

function nearestCells(v, leaders) {
  const { w, b, scale, ox, oy } = v, h = v.h - v.strip;
  const key = [w, h, ...b, ...leaders.flatMap((l) => l.at)].join(",");
  if (!state.regions || state.regions.key !== key) {
    const off = document.createElement("canvas");
    off.width = w; off.height = h;
    const o = off.getContext("2d");
    const cell = 6;
    for (let cy = 0; cy < h; cy += cell) {
      for (let cx = 0; cx < w; cx += cell) {
        const fx = b[0] + (cx + cell / 2 - ox) / scale, fy = b[3] - (cy + cell / 2 - oy) / scale;
        let best = 0, bd = Infinity;
        leaders.forEach((l, i) => { const d = (l.at[0] - fx) ** 2 + (l.at[1] - fy) ** 2; if (d < bd) { bd = d; best = i; } });
        o.fillStyle = leaderColour(best); o.fillRect(cx, cy, cell, cell);
      }
    }
    state.regions = { key, canvas: off };
  }
  return state.regions.canvas;
}

// A chart of the last `state.span` ms: time along, gaps left open.
function drawChart(id, series, colour) {
  const { ctx, w, h } = context(id);
  ctx.clearRect(0, 0, w, h);
  const values = series.filter((s) => s.v !== null).map((s) => s.v);
  if (values.length < 2) return;
  const top = Math.max(...values) * 1.1 || 1, now = Date.now();
  ctx.strokeStyle = colour; ctx.lineWidth = 1.5; ctx.beginPath();
  let drawing = false;
  for (const s of series) {
    if (s.v === null) { drawing = false; continue; }
    const x = w - 4 - (w - 8) * (now - s.t) / state.span, y = h - 4 - (h - 16) * s.v / top;
    if (drawing) ctx.lineTo(x, y); else ctx.moveTo(x, y);
    drawing = true;
  }
  ctx.stroke();
  ctx.fillStyle = "#4a5568"; ctx.font = "10px system-ui, sans-serif";
  ctx.fillText(`max ${(top / 1.1).toFixed(top < 10 ? 1 : 0)} · last ${Math.round(state.span / 60000)} min`, 6, 11);
}

function renderLeaders(missing) {
  const names = state.positions ? state.positions.leaders.map((l) => l.name) : [];
  const stats = new Map((state.stats ? state.stats.leaders : []).map((l) => [l.leader, l]));
  for (const n of stats.keys()) if (!names.includes(n)) names.push(n);
  const number = (v) => (v === undefined ? "–" : Number(v).toLocaleString("en"));
  document.getElementById("leaders").innerHTML = names.map((name, i) => {
    const s = stats.get(name);
    const gone = missing.includes(name);
    const host = s && s.host && s.host !== name ? ` <small>on ${escape(s.host)}</small>` : "";
    const fields = s ? [["items", s.items], ["mixes", s.mixes], ["observes", s.observations], ["handovers", s.handovers],
      ["sets", s.coefficients], ["bytes in", s.bytes_received], ["bytes out", s.bytes_sent], ["rejected", s.rejected],
      ["tracks", s.tracks_owned], ["reads", s.identifies], ["recoveries", s.recoveries], ["omp runs", s.omp_runs]] : [];
    return `<div class="panel${gone ? " missing" : ""}" style="--leader:${leaderColour(i)}" data-leader="${escape(name)}">
      <h3>${escape(name)}${host}${gone ? " — not answering" : ""}</h3>
      <dl>${fields.map(([k, v]) => `<dt>${k}</dt><dd>${number(v)}</dd>`).join("")}</dl></div>`;
  }).join("");
}

function renderSensors() {
  const sensors = state.stats ? state.stats.sensors : [];
  const events = state.positions ? state.positions.watermark : {};
  const names = [...new Set([...sensors.map((s) => s.sensor), ...Object.keys(events)])];
  document.getElementById("sensors").innerHTML = names.map((name) => {
    const s = sensors.find((x) => x.sensor === name);
    return `<div class="panel"><h3>${escape(name)}</h3><dl><dt>events</dt><dd>${events[name] ?? "–"}</dd>
      <dt>rejected</dt><dd>${s ? s.rejected : "–"}</dd></dl></div>`;
  }).join("");
}

// P(the track of `row` carries identity i): an answer lists a track's
// likely identities and gives one probability (`rest`) for all others.
function probabilityOf(row, i) {
  const hit = row.listed.find(([j]) => j === i);
  return hit ? hit[1] : row.rest;
}

function renderTracks() {
  document.querySelector("#tracks tbody").innerHTML = state.drawn.map((d) => {
    const ident = d.identity === null ? "" : `${d.identity} (${probabilityOf(state.identity.p_identity[d.track], d.identity).toFixed(2)})`;
    const selected = d.track === state.selected ? ' class="selected"' : "";
    return `<tr data-track="${d.track}"${selected}><td>${d.track}</td><td style="color:${rgb(d.colour)}">${d.p_red === null ? "–" : d.p_red.toFixed(3)}</td>
      <td>${escape(d.owner)}</td><td>${ident}</td></tr>`;
  }).join("");
}

// The track under the pointer (within its ring), or null.
function trackAt(event) {
  const canvas = document.getElementById("map");
  const r = canvas.getBoundingClientRect();
  const x = event.clientX - r.left - canvas.clientLeft, y = event.clientY - r.top - canvas.clientTop;
  let best = null, bd = TRACK_BOX * TRACK_BOX;
  for (const d of state.drawn) {
    const dd = (d.x - x) ** 2 + (d.y - y) ** 2;
    if (dd <= bd) { bd = dd; best = d.track; }
  }
  return best;
}

function select(track) {
  state.selected = track === state.selected ? null : track;
  schedule();
}

// Hover shows a hidden label; a click on a track or its row selects it.
function listenToPointer() {
  const canvas = document.getElementById("map");
  canvas.addEventListener("mousemove", (e) => {
    const t = trackAt(e);
    if (t !== state.hover) { state.hover = t; schedule(); }
  });
  canvas.addEventListener("mouseleave", () => { state.hover = null; schedule(); });
  canvas.addEventListener("click", (e) => { const t = trackAt(e); if (t !== null) select(t); });
  document.querySelector("#tracks tbody").addEventListener("click", (e) => {
    const row = e.target.closest("tr");
    if (row) select(Number(row.dataset.track));
  });
}

// Every label shown and its box relative to the map's canvas, read from
// the elements themselves (what the eye sees, not what placement meant);
// the markers' boxes beside them.
function shownLabels() {
  const map = document.getElementById("map"), canvas = map.getBoundingClientRect();
  const x0 = canvas.left + map.clientLeft, y0 = canvas.top + map.clientTop;
  const labels = Array.from(document.querySelectorAll("#labels .label"))
    .filter((s) => !s.hidden && !s.classList.contains("hover"))
    .map((s) => {
      const r = s.getBoundingClientRect();
      return { key: s.dataset.key, text: s.textContent, selected: s.classList.contains("selected"),
        left: r.left - x0, top: r.top - y0, width: r.width, height: r.height };
    });
  return { labels, markers: state.markers, hidden: document.querySelectorAll("#labels .label[hidden]").length,
    placement: PLACEMENT };
}

// What the page shows, for tests and for anyone curious in the console.
window.idmesh = {
  colourOf,
  labels: shownLabels,
  select(track) { state.selected = track; render(); },
  snapshot() {
    flush();
    return {
      watermark: state.marginals ? eventsOf(state.marginals.watermark) : null,
      positionsAt: state.positions ? eventsOf(state.positions.watermark) : null,
      finished: state.marginals ? state.marginals.finished : null,
      status: document.getElementById("status").className.replace("status ", ""),
      statusText: document.getElementById("status").textContent,
      problem: document.getElementById("problem").textContent,
      ratio: window.devicePixelRatio || 1,
      firstMapMs: state.firstMapMs,
      tracks: state.drawn,
      // The charts: points plotted, and the highest rate among them.
      rates: state.rates.filter((s) => s.v !== null).length,
      peakRate: Math.max(0, ...state.rates.map((s) => s.v ?? 0)),
      rate: document.getElementById("rate").textContent,
    };
  },
};

start();
