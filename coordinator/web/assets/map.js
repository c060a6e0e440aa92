// The live map of an idmesh deployment. Plain JavaScript, no library:
// Server-Sent Events from the gateway (the same paths as its REST API,
// `Accept: text/event-stream`) feed one state object, and every change
// redraws the canvas and the panels.
//
// Tracks sit at their last known position (query/positions) coloured by
// P(red) from query/marginals, ringed in the colour of the leader that
// surveils them; on identity streams each is labelled with its most likely
// identity and that probability (query/identity). Leaders are diamonds,
// their regions (points nearer to them than to any other leader) shaded.
// `degraded` names who is missing: the coordinator's own error, and the
// leaders of the stream that query/stats did not hear from.
"use strict";

const PREFIX = document.querySelector('meta[name="idmesh-prefix"]').content;
const API = "/" + PREFIX + "/query/";
const LEADER_COLOURS = ["#d69e2e", "#38a169", "#805ad5", "#dd6b20", "#319795", "#d53f8c", "#2c5282", "#718096"];
const RADIUS = 8;
const HISTORY = 120;

const state = {
  marginals: null, identity: null, positions: null, stats: null,
  identityStream: null, // unknown until the coordinator says
  failures: {}, connected: false,
  rates: [], latencies: [], last: null,
  bounds: null, regions: null, drawn: [], firstMapMs: null,
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

function push(series, value) {
  series.push(value);
  if (series.length > HISTORY) series.shift();
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
      if (l.status === 200) push(state.latencies, l.ms);
    });
  }
  source.onerror = () => { state.connected = false; schedule(); };
  return source;
}

listen("marginals", 500, (a) => {
  const now = performance.now(), events = eventsOf(a.watermark);
  if (state.last && now > state.last.t) push(state.rates, Math.max(0, (events - state.last.events) / ((now - state.last.t) / 1000)));
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

let pending = false;
function schedule() {
  if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; render(); }); }
}

// Who is missing: leaders of the stream that query/stats did not hear from.
function missingLeaders() {
  if (!state.positions || !state.stats) return [];
  const answering = new Set(state.stats.leaders.map((l) => l.leader));
  return state.positions.leaders.map((l) => l.name).filter((n) => !answering.has(n));
}

function render() {
  const missing = missingLeaders();
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
  const m = state.marginals;
  document.getElementById("watermark").textContent = m ? `${eventsOf(m.watermark)} events` : "–";
  document.getElementById("watermark").dataset.events = m ? eventsOf(m.watermark) : "";
  const rate = state.rates[state.rates.length - 1];
  document.getElementById("rate").textContent = rate === undefined ? "–" : rate.toFixed(0);
  const latency = state.latencies[state.latencies.length - 1];
  document.getElementById("latency").textContent = latency === undefined ? "–" : latency.toFixed(1) + " ms";
  document.getElementById("sets").textContent = m ? `${m.coefficients} on ${m.leaders} leaders` : "–";
  const p = state.positions;
  document.getElementById("positions-at").textContent = p ? `positions at ${eventsOf(p.watermark)} events` : "";
  drawMap(missing);
  drawChart("chart-rate", state.rates, "#2c5282");
  drawChart("chart-latency", state.latencies, "#c05621");
  renderLeaders(missing);
  renderSensors();
  renderTracks();
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

// The field's extent, only ever growing (so the map does not jump).
function bounds(p) {
  const points = p.positions.filter(Boolean).concat(p.leaders.map((l) => l.at).filter(Boolean));
  if (points.length === 0) return null;
  let b = state.bounds ? state.bounds.slice() : [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of points) b = [Math.min(b[0], x), Math.min(b[1], y), Math.max(b[2], x), Math.max(b[3], y)];
  if (b[2] - b[0] < 1e-9) { b[0] -= 1; b[2] += 1; }
  if (b[3] - b[1] < 1e-9) { b[1] -= 1; b[3] += 1; }
  state.bounds = b;
  return b;
}

function drawMap(missing) {
  const { ctx, w, h } = context("map");
  ctx.clearRect(0, 0, w, h);
  const p = state.positions, m = state.marginals;
  state.drawn = [];
  if (!p) { ctx.fillStyle = "#718096"; ctx.fillText("waiting for positions…", 20, 24); return; }
  const b = bounds(p);
  const strip = 34; // unplaced tracks wait in a strip along the bottom
  const pad = 24, fw = w - 2 * pad, fh = h - 2 * pad - strip;
  const scale = b ? Math.min(fw / (b[2] - b[0]), fh / (b[3] - b[1])) : 1;
  const ox = b ? pad + (fw - scale * (b[2] - b[0])) / 2 : pad, oy = b ? pad + (fh - scale * (b[3] - b[1])) / 2 : pad;
  // y grows upwards in the field, downwards on the canvas.
  const at = ([x, y]) => [ox + (x - b[0]) * scale, oy + (b[3] - y) * scale];
  const placed = p.leaders.every((l) => l.at);
  if (b && placed) drawRegions(ctx, w, h - strip, p.leaders, at, b, scale, ox, oy);
  ctx.strokeStyle = "#cbd5e0"; ctx.strokeRect(pad - 6, pad - 6, fw + 12, fh + 12);
  p.leaders.forEach((l, i) => {
    if (!l.at) return;
    const [x, y] = at(l.at);
    ctx.beginPath(); ctx.moveTo(x, y - 11); ctx.lineTo(x + 11, y); ctx.lineTo(x, y + 11); ctx.lineTo(x - 11, y); ctx.closePath();
    ctx.fillStyle = leaderColour(i); ctx.fill(); ctx.strokeStyle = "#1a202c"; ctx.lineWidth = 1.5; ctx.stroke();
    ctx.font = "bold 12px system-ui, sans-serif"; ctx.fillStyle = "#1a202c";
    ctx.fillText(l.name, x + 14, y + 4);
    if (missing.includes(l.name)) {
      ctx.strokeStyle = "#c53030"; ctx.lineWidth = 3;
      ctx.beginPath(); ctx.moveTo(x - 13, y - 13); ctx.lineTo(x + 13, y + 13); ctx.moveTo(x + 13, y - 13); ctx.lineTo(x - 13, y + 13); ctx.stroke();
      ctx.fillStyle = "#c53030"; ctx.fillText("missing", x + 14, y + 18);
    }
  });
  const ident = state.identityStream && state.identity && state.identity.tracks === p.tracks ? state.identity : null;
  const values = m && m.tracks === p.tracks ? m.p_red : null;
  let unplaced = 0;
  ctx.font = "11px system-ui, sans-serif";
  for (let t = 0; t < p.tracks; t++) {
    let x, y;
    if (p.positions[t] && b) [x, y] = at(p.positions[t]);
    else { x = pad + RADIUS + (unplaced++) * 2.5 * RADIUS; y = h - strip / 2; }
    const value = values ? values[t] : null;
    const colour = value === null ? [160, 174, 192] : colourOf(value);
    ctx.beginPath(); ctx.arc(x, y, RADIUS + 2, 0, 2 * Math.PI);
    ctx.fillStyle = leaderColour(p.owners[t]); ctx.fill();
    ctx.beginPath(); ctx.arc(x, y, RADIUS - 1, 0, 2 * Math.PI);
    ctx.fillStyle = rgb(colour); ctx.fill();
    let label = String(t);
    if (ident) {
      const i = ident.predicted_identity[t];
      label += ` · id ${i} ${probabilityOf(ident.p_identity[t], i).toFixed(2)}`;
    }
    ctx.fillStyle = "#1a202c"; ctx.fillText(label, x + RADIUS + 4, y - RADIUS + 2);
    state.drawn.push({ track: t, x, y, p_red: value, colour, owner: leaderName(p, p.owners[t]),
      identity: ident ? ident.predicted_identity[t] : null });
  }
  if (values && state.firstMapMs === null) {
    state.firstMapMs = performance.now();
    document.body.dataset.firstMapMs = state.firstMapMs.toFixed(1);
  }
}

// Shades each leader's region: cells of the canvas coloured by their
// nearest leader, computed once per extent and kept.
function drawRegions(ctx, w, h, leaders, at, b, scale, ox, oy) {
  const key = [w, h, ...b].join(",");
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
  ctx.save(); ctx.globalAlpha = 0.13; ctx.drawImage(state.regions.canvas, 0, 0, w, h); ctx.restore();
}

function drawChart(id, series, colour) {
  const { ctx, w, h } = context(id);
  ctx.clearRect(0, 0, w, h);
  if (series.length < 2) return;
  const top = Math.max(...series) * 1.1 || 1;
  ctx.strokeStyle = colour; ctx.lineWidth = 1.5; ctx.beginPath();
  series.forEach((v, i) => {
    const x = 4 + (w - 8) * i / (HISTORY - 1), y = h - 4 - (h - 16) * v / top;
    if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
  });
  ctx.stroke();
  ctx.fillStyle = "#4a5568"; ctx.font = "10px system-ui, sans-serif";
  ctx.fillText(`max ${(top / 1.1).toFixed(top < 10 ? 1 : 0)}`, 6, 11);
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
    return `<tr data-track="${d.track}"><td>${d.track}</td><td style="color:${rgb(d.colour)}">${d.p_red === null ? "–" : d.p_red.toFixed(3)}</td>
      <td>${escape(d.owner)}</td><td>${ident}</td></tr>`;
  }).join("");
}

// What the page shows, for tests and for anyone curious in the console.
window.idmesh = {
  colourOf,
  snapshot() {
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
    };
  },
};
