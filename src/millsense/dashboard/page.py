"""The dashboard's page: HTML and the script that draws the snapshots of the websocket
(:meth:`~millsense.dashboard.live.LiveState.snapshot`) with plotly.js served by the dashboard
itself (no network). Status and alarms are updated at every snapshot, the plots from the
latest one when the previous drawing is done (drawing never falls behind the session).
Signals are drawn as the zig-zag through each chunk's minimum and maximum; the token of the
page's address goes with every request."""

from __future__ import annotations

PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>millsense live</title><link rel="icon" href="data:,">
<style>
body{font-family:system-ui,sans-serif;margin:0.8em;color:#222}
#bar{display:flex;gap:1.2em;align-items:center;flex-wrap:wrap;margin-bottom:0.5em}
.stat b{font-size:1.1em} button{font-size:1em;padding:0.3em 0.8em}
#alarms{list-style:none;padding:0;margin:0.3em 0}
.alarm{background:#fdd;border:1px solid #d33;padding:0.3em 0.6em;margin:0.2em 0}
.alarm.acknowledged{background:#eee;border-color:#aaa}
.grid{display:grid;grid-template-columns:1fr 1fr;gap:0.4em}
.plot{height:260px;border:1px solid #eee}
#conn{color:#888}
</style>
<script src="plotly.min.js?token=TOKEN_PLACEHOLDER"></script>
</head><body>
<div id="bar">
 <span class="stat">t <b id="time">–</b> s</span>
 <span class="stat">mode <b id="mode">–</b></span>
 <span class="stat">feed <b id="feed">–</b> % (in effect <b id="feed_eff">–</b> %)</span>
 <span class="stat">spindle <b id="rpm">–</b> rev/min (<b id="spindle">–</b> %)</span>
 <span class="stat">NC line <b id="nc">–</b></span>
 <span class="stat">control <b id="control">–</b></span>
 <button id="control-on">control on</button>
 <button id="control-off">control off</button>
 <span id="conn">connecting…</span>
</div>
<ul id="alarms"></ul>
<div class="grid">
 <div id="plot-torque" class="plot"></div><div id="plot-spectrum" class="plot"></div>
 <div id="plot-feed" class="plot"></div><div id="plot-position" class="plot"></div>
 <div id="plot-regulated" class="plot"></div><div id="plot-spindle" class="plot"></div>
</div>
<ul id="overrides"></ul>
<script>
"use strict";
const token = new URLSearchParams(location.search).get("token") || "";
const q = "token=" + encodeURIComponent(token);
const layout = (title, xt) => ({title: {text: title, font: {size: 13}},
  margin: {l: 50, r: 10, t: 30, b: 35}, xaxis: {title: {text: xt}}, showlegend: true,
  legend: {orientation: "h", y: -0.25}});
let updates = 0;
function zigzag(tr) {
  const x = [], y = [];
  for (let i = 0; i < tr.t.length; i++) {
    x.push(tr.t[i], tr.t[i]); y.push(tr.lo[i], tr.hi[i]);
  }
  return {x: x, y: y, name: tr.name, mode: "lines", line: {width: 1}};
}
function fmt(v, d) { return (v === null || v === undefined) ? "–" : Number(v).toFixed(d); }
function post(path) { return fetch(path + (path.includes("?") ? "&" : "?") + q, {method: "POST"}); }
function plotTasks(s) {
  // one task per plot: a snapshot arriving meanwhile updates the status and alarms between two
  const tasks = [];
  for (const key of ["torque", "feed", "regulated", "spindle"]) {
    const p = s.plots[key];
    document.getElementById("plot-" + key).style.visibility = p ? "visible" : "hidden";
    if (p) tasks.push(() => Plotly.react("plot-" + key, p.traces.map(zigzag),
                                         layout(p.title, "time [s]")));
  }
  tasks.push(() => {
    const sp = [{x: s.spectrum.f, y: s.spectrum.amp, name: "spindle torque", mode: "lines"}];
    const sl = layout("rolling spectrum of the spindle torque", "frequency [Hz]");
    if (s.spectrum.tooth_hz) sl.shapes = [1, 2, 3, 4].map(k => ({type: "line", xref: "x",
      yref: "paper", x0: k * s.spectrum.tooth_hz, x1: k * s.spectrum.tooth_hz, y0: 0, y1: 1,
      line: {color: "#bbb", dash: "dot", width: 1}}));
    Plotly.react("plot-spectrum", sp, sl);
  });
  tasks.push(() => {
    const pos = [];
    if (s.plan) pos.push({x: s.plan.x, y: s.plan.y, name: "programmed path", mode: "lines",
                          line: {color: "#bbb", width: 1}});
    pos.push({x: s.trail.x, y: s.trail.y, name: "tool-centre point", mode: "lines"});
    const n = s.trail.x.length;
    if (n) pos.push({x: [s.trail.x[n - 1]], y: [s.trail.y[n - 1]], name: "now",
                     mode: "markers", marker: {size: 10, color: "#d62728"}});
    const pl = layout("plan position", "X [mm]");
    pl.yaxis = {scaleanchor: "x", title: {text: "Y [mm]"}};
    Plotly.react("plot-position", pos, pl);
    updates += 1; document.body.dataset.updates = updates;
    document.body.dataset.time = s.time_s; document.body.dataset.finished = s.finished;
  });
  return tasks;
}
function drawText(s) {
  const st = s.status;
  document.getElementById("time").textContent = fmt(s.time_s, 2);
  document.getElementById("mode").textContent = st.mode;
  document.getElementById("feed").textContent = fmt(st.feed_pct, 1);
  document.getElementById("feed_eff").textContent = fmt(st.feed_in_effect_pct, 1);
  document.getElementById("spindle").textContent = fmt(st.spindle_pct, 1);
  document.getElementById("rpm").textContent = fmt(st.spindle_rpm, 0);
  document.getElementById("nc").textContent = fmt(st.nc_line, 0);
  document.getElementById("control").textContent =
    st.control === null ? "–" : (st.control ? "on" : "off");
  // the alarm list is rebuilt only when it changes (its buttons stay clickable)
  const key = s.alarms.map(a => a.id + (a.acknowledged ? "a" : "")).join(",");
  if (key === alarmKey) return drawOverrides(s);
  alarmKey = key;
  const ul = document.getElementById("alarms");
  ul.replaceChildren(...s.alarms.map(a => {
    const li = document.createElement("li");
    li.className = "alarm" + (a.acknowledged ? " acknowledged" : "");
    li.dataset.id = a.id; li.dataset.name = a.name;
    li.textContent = `${fmt(a.time_s, 3)} s  ${a.severity}  ${a.name}: ${a.message} `;
    if (!a.acknowledged) {
      const b = document.createElement("button"); b.textContent = "acknowledge";
      b.className = "ack"; b.onclick = () => post("api/ack/" + a.id); li.appendChild(b);
    }
    return li;
  }));
  drawOverrides(s);
}
let alarmKey = null;
function drawOverrides(s) {
  const ov = document.getElementById("overrides");
  ov.replaceChildren(...s.overrides.slice(-8).reverse().map(o => {
    const li = document.createElement("li");
    li.textContent = `${fmt(o.time_s, 3)} s  ${o.message}`; return li;
  }));
}
// the status and the alarms at every snapshot; the plots of the latest snapshot, one plot per
// task, once the previous drawing is done (a slow drawing never queues snapshots up)
let latest = null, tasks = [], drawing = false;
function onSnapshot(s) {
  drawText(s);
  latest = s;
  if (!drawing) next();
}
function next() {
  if (!tasks.length) {
    if (!latest) { drawing = false; return; }
    tasks = plotTasks(latest); latest = null;
  }
  drawing = true;
  const task = tasks.shift();
  setTimeout(() => { try { task(); } finally { next(); } }, 0);
}
document.getElementById("control-on").onclick = () => post("api/control?on=true");
document.getElementById("control-off").onclick = () => post("api/control?on=false");
function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host
                           + "/ws?" + q);
  ws.onopen = () => { document.getElementById("conn").textContent = "live"; };
  ws.onmessage = (m) => onSnapshot(JSON.parse(m.data));
  ws.onclose = () => { document.getElementById("conn").textContent = "disconnected"; };
}
connect();
</script></body></html>
"""


def page_html(token: str) -> str:
    """The page for a request that showed ``token`` (its script reads the token from the
    page's address; the plotly.js tag carries it written in)."""
    import html
    from urllib.parse import quote

    return PAGE.replace("TOKEN_PLACEHOLDER", html.escape(quote(token, safe="")))


__all__ = ["page_html"]
