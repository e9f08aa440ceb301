// The live view: one EventSource, one panel per connected simulator. Read-only: it sends nothing back.
"use strict";
const HISTORY_S = 30;
const panels = new Map();  // sid -> {root, history: [[t, steering, throttle, speed]]}
let speedLimit = 25;

function el(root, selector) { return root.querySelector(selector); }
function fmt(x, digits) { return (x >= 0 ? "+" : "") + x.toFixed(digits); }

function showModel(server) {
  const c = server.control, k = server.contract;
  speedLimit = c.speed_limit_kmh;
  const rows = [
    ["model", server.model], ["input", `${k.width}x${k.height} ${k.color}, rows ${k.crop_top}-${k.crop_bottom}, x*${k.scale.toPrecision(3)}${k.offset >= 0 ? "+" : ""}${k.offset}, ${k.layout}`],
    ["control law", `speed limit ${c.speed_limit_kmh} km/h, steering limit ${c.steer_limit_deg}°, tau ${c.tau}, telemetry speed in ${c.speed_unit}`],
  ];
  const m = server.monitor;
  rows.push(["monitor", m ? `${m.score}, ${m.mode}: warning at ${m.warn.toPrecision(3)}, alarm at ${m.alarm.toPrecision(3)} (mean of ${m.window} frames)` : "none"]);
  el(document, "#model").innerHTML = "<dl>" + rows.map(([a, b]) => `<dt>${a}</dt><dd>${b}</dd>`).join("") + "</dl>";
  el(document, "#server").textContent = `${server.clients} simulator(s) connected, ${server.viewers} viewer(s); updated ${new Date().toLocaleTimeString()}`;
}

function panelFor(sid) {
  let p = panels.get(sid);
  if (!p) {
    const root = el(document, "#client-template").content.firstElementChild.cloneNode(true);
    root.dataset.sid = sid;
    el(document, "#clients").appendChild(root);
    p = {root, history: []};
    panels.set(sid, p);
  }
  return p;
}

function setBar(bar, value) {  // value -1..1 drawn from the centre
  const v = Math.max(-1, Math.min(1, value));
  bar.style.left = (50 + Math.min(0, v) * 50) + "%";
  bar.style.width = (Math.abs(v) * 50) + "%";
}

function drawChart(canvas, history, now) {
  const ctx = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  ctx.clearRect(0, 0, w, h);
  ctx.strokeStyle = "#333"; ctx.beginPath(); ctx.moveTo(0, h / 2); ctx.lineTo(w, h / 2); ctx.stroke();
  const series = [[1, "#ffd23f", v => v], [2, "#4cc9f0", v => v], [3, "#b8f2e6", v => 2 * v / Math.max(1, speedLimit) - 1]];
  for (const [i, color, scale] of series) {
    ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath();
    history.forEach((p, k) => {
      const v = Math.max(-1, Math.min(1, scale(p[i])));
      const x = w - (now - p[0]) / HISTORY_S * w, y = h / 2 - v * (h / 2 - 4);
      if (k === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    });
    ctx.stroke();
  }
}

function showClient(c, now) {
  const p = panelFor(c.sid), r = p.root, f = c.frame;
  el(r, ".sid").textContent = `simulator ${c.sid}`;
  el(r, ".agent").textContent = c.agent;
  const counters = Object.entries(c.counters).map(([k, v]) => `<tr><td>${k}</td><td class="c-${k.replace(/ /g, "-")}">${v}</td></tr>`);
  el(r, ".counters tbody").innerHTML = counters.join("");
  if (f) {
    el(r, "img").src = "data:image/jpeg;base64," + f.image;
    el(r, ".age").textContent = `frame ${f.age_s.toFixed(1)} s ago`;
    setBar(el(r, "i.steer"), f.steering);
    el(r, ".steer-text").textContent = `${fmt(f.steering, 3)} (${fmt(f.steering_deg, 1)}°)`;
    const pedal = el(r, "i.pedal");
    setBar(pedal, f.throttle);
    pedal.classList.toggle("brake", f.throttle < 0);
    el(r, ".pedal-text").textContent = f.throttle > -0.005 ? `throttle ${f.throttle.toFixed(2)}` : `brake ${(-f.throttle).toFixed(2)}`;
    el(r, ".speed-text").textContent = `${f.speed.toFixed(1)} ${c.speed_unit}`;
    el(r, ".source").textContent = f.fallback ? "command: fallback (bad frame: held or stopping)" : "command: the model's";
    const mon = el(r, ".monitor");
    mon.textContent = f.monitor ? `monitor: ${f.monitor.state} (score ${f.monitor.mean.toPrecision(3)})` : (c.monitor_failed ? `monitor off: ${c.monitor_failed}` : "");
    mon.className = "monitor" + (f.monitor ? " m-" + f.monitor.state : "");
    p.history.push([now, f.steering, f.throttle, f.speed_kmh]);
  }
  while (p.history.length && now - p.history[0][0] > HISTORY_S) p.history.shift();
  drawChart(el(r, "canvas"), p.history, now);
  if (c.latency) {
    const stages = Object.entries(c.latency);
    el(r, ".latency thead").innerHTML = "<tr><th>server time, ms</th>" + stages.map(([s]) => `<th>${s}</th>`).join("") + "</tr>";
    el(r, ".latency tbody").innerHTML = ["p50", "p99"].map(q => `<tr><td>${q}</td>` +
      stages.map(([s, v]) => `<td class="lat-${s}-${q}">${v[q].toFixed(3)}</td>`).join("") + "</tr>").join("");
  }
}

function update(snapshot) {
  const now = performance.now() / 1000;
  showModel(snapshot.server);
  const seen = new Set();
  for (const c of snapshot.clients) { seen.add(c.sid); showClient(c, now); }
  for (const [sid, p] of panels) if (!seen.has(sid)) { p.root.remove(); panels.delete(sid); }
  el(document, "#empty").hidden = snapshot.clients.length > 0;
  document.body.dataset.updates = String(Number(document.body.dataset.updates || 0) + 1);
}

const source = new EventSource("/events");
source.onmessage = event => update(JSON.parse(event.data));
source.onerror = () => { el(document, "#server").textContent = "disconnected from drive_server; retrying…"; };
