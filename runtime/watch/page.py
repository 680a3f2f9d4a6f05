r"""The watch page: one self-contained HTML file with inline CSS and JavaScript.

Why no external asset (no CDN, no web font): the page must work on a ship's or a lab's
network with no Internet access, and a third-party script on a page that carries operator
actions is a risk we need not take. Text from the log is always inserted with
``textContent`` (or as SVG text nodes), never as HTML; the one piece of markup inserted is
the net's drawing from ``/info``, which coral drew itself (`analysis.netdraw`), parsed
inertly (a ``DOMParser`` document runs no script) and stripped of scripts and handlers.

What the page reads (`runtime.watch.server` and `runtime.watch.live` serve them):

* ``GET info`` once: the net's drawing and node names, inputs, workspace, way-points
  (`runtime.watch.info.page_info`); a server without it gives a page without the net;
* ``GET snapshot[?t=]`` and ``GET events`` (SSE): documents ``{mission, live, start, end,
  snapshot}``, the snapshot as `runtime.watch.state.Snapshot.to_json` writes it;
* ``GET rights``: ``{view, operate}`` for the token in the page's URL (``?token=``); the
  operator panel is shown only with ``operate``; ``POST operate`` with
  ``Authorization: Bearer <token>`` and ``X-Coral-Client: page``.

Element ids and markers a browser test may rely on (kept stable):

====================================================  ====================================
``#mission``                                          the mission's name
``#mode``                                             ``LIVE``, ``ended`` or ``replay``
``#clock``                                            the shown time, ``12.3 s``
``#paused``                                           the paused badge (``hidden`` if not)
``#end``                                              the end banner (empty while running;
                                                      ``live view lost: ...`` if broken)
``#scrub``, ``#play``, ``#speed``, ``#live``          the replay bar
``#net svg.net``                                      the net's drawing
``#net .place[data-node=p3] .tokens``                 a place's tokens (dots up to 3, then
                                                      a number; empty for none)
``#net .transition[data-node=t5]``                    classes ``enabled``, ``inflight``,
                                                      ``offered`` (an input that can be
                                                      given) and ``fired`` (a short flash)
``#net-note``                                         why there is no drawing, if none
``#enabled``, ``#in-flight``                          the names, comma separated
``#marking``                                          tbody: one row per marked place
                                                      ``<tr data-place=NAME>``
``#commands``                                         tbody: one row per command
                                                      ``<tr data-command-id=N>``, cells
                                                      ``.awaiting``, ``.countdown``,
                                                      ``.reply``
``#telemetry``                                        tbody: the newest sample
``#track``, ``#depth``, ``#heading``                  the plots (SVG): x-y track in the
                                                      workspace (``.workspace``,
                                                      ``.waypoint``, ``.track``,
                                                      ``.position``), depth and heading
                                                      (``.series``, heading unwrapped)
``#timeline``                                         the events timeline (SVG): one lane
                                                      per command name
                                                      (``.lane[data-lane="command NAME"]``,
                                                      a bar from sent to reply) and per
                                                      transition fired
                                                      (``.lane[data-lane=NAME]``), one
                                                      ``.firing`` mark per firing
``#link``                                             tbody: ``<tr data-key=KEY>`` per
                                                      link figure
``#operator``                                         the operator panel (``hidden``
                                                      without the operate right):
                                                      ``button[data-action=pause]``,
                                                      ``[data-action=resume]``,
                                                      ``[data-action=give][data-input=N]``
                                                      (a give asks ``window.confirm``
                                                      first; a test may replace it)
``#operator-answer``                                  the server's answer to the last
                                                      action
``#operator-log``                                     tbody: the operator actions logged
====================================================  ====================================
"""

from __future__ import annotations

from typing import Final

__all__ = ["PAGE"]

PAGE: Final = r"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>coral watch</title>
<style>
body { font: 14px/1.4 system-ui, sans-serif; margin: 1em 2em; color: #222; }
h1 { font-size: 1.3em; margin: 0 0 .3em; } h2 { font-size: 1.05em; margin: 1em 0 .3em; }
table { border-collapse: collapse; } td, th { padding: 2px 10px 2px 0; text-align: left; }
th { border-bottom: 1px solid #999; }
.num { text-align: right; font-variant-numeric: tabular-nums; }
#bar { display: flex; gap: .8em; align-items: center; margin: .5em 0; }
#scrub { flex: 1; } #mode { font-weight: bold; }
#paused { background: #b60; color: white; padding: 1px 8px; border-radius: 4px; }
#end:not(:empty) { color: #a00; font-weight: bold; padding: .3em .6em;
  border: 1px solid #a00; background: #fff0f0; }
.awaiting { color: #b60; } .late { color: #a00; font-weight: bold; }
.cols { display: flex; gap: 2.5em; flex-wrap: wrap; align-items: flex-start; }
#net { border: 1px solid #ccc; overflow: auto; max-height: 60vh; }
#net.fit svg.net { width: 100%; height: auto; }
svg.net text.tokens { font-weight: 700; }
svg.net g.transition.enabled polygon, svg.net g.transition.enabled rect {
  stroke: #1a7f37; stroke-width: 3; fill: #e6ffec; }
svg.net g.transition.inflight polygon, svg.net g.transition.inflight rect {
  stroke: #b60; stroke-width: 3; fill: #fff4d6; }
svg.net g.transition.offered polygon, svg.net g.transition.offered rect {
  stroke: #0550ae; stroke-width: 2; stroke-dasharray: 4 2; }
svg.net g.transition.fired polygon, svg.net g.transition.fired rect {
  stroke: #cf222e; stroke-width: 4; fill: #ffebe9; }
svg.net g.place.marked ellipse, svg.net g.place.marked circle { stroke-width: 2.5; }
.legend span { margin-right: 1.2em; } .sw { display: inline-block; width: 1em;
  height: .8em; border: 2px solid; vertical-align: middle; margin-right: .3em; }
svg.plot { background: #fcfcfc; border: 1px solid #ddd; }
svg.plot text { font-size: 10px; fill: #333; }
#operator { border: 2px solid #0550ae; padding: .4em .8em; margin: .8em 0; }
#operator button { margin: .2em .4em .2em 0; }
</style></head>
<body>
<h1>coral watch: <span id="mission"></span></h1>
<div id="bar">
  <span id="mode"></span>
  <span id="paused" hidden>PAUSED</span>
  <button id="play">play</button>
  <select id="speed"><option>1</option><option selected>5</option><option>20</option>
  <option>100</option></select>x
  <input id="scrub" type="range" min="0" max="0" step="0.1" value="0">
  <span id="clock" class="num"></span>
  <button id="live">follow live</button>
</div>
<div id="end"></div>
<div id="operator" hidden>
  <strong>Operator</strong>
  <span id="operator-buttons"></span>
  <div id="operator-answer"></div>
</div>
<h2>Net <button id="net-fit">fit to width</button></h2>
<div class="legend"><span><i class="sw" style="border-color:#1a7f37"></i>enabled</span>
<span><i class="sw" style="border-color:#b60"></i>command in flight</span>
<span><i class="sw" style="border-color:#0550ae"></i>input offered</span>
<span><i class="sw" style="border-color:#cf222e"></i>just fired</span></div>
<div id="net"></div>
<p id="net-note"></p>
<p>enabled: <span id="enabled"></span>; in flight: <span id="in-flight"></span></p>
<h2>Commands</h2>
<table><thead><tr><th class="num">id</th><th>sent</th><th>command</th><th>transition</th>
<th>awaiting</th><th>time-out</th><th>reply</th><th class="num">sends</th></tr></thead>
<tbody id="commands"></tbody></table>
<p id="commands-note"></p>
<div class="cols">
 <div><h2>Track</h2><svg id="track" class="plot" width="380" height="320"></svg></div>
 <div><h2>Depth</h2><svg id="depth" class="plot" width="520" height="150"></svg>
  <h2>Heading</h2><svg id="heading" class="plot" width="520" height="150"></svg></div>
 <div><h2>Telemetry</h2><table><tbody id="telemetry"></tbody></table>
  <h2>Marking</h2><table><thead><tr><th>place</th><th class="num">tokens</th></tr></thead>
  <tbody id="marking"></tbody></table></div>
</div>
<h2>Events</h2>
<svg id="timeline" class="plot" width="960" height="80"></svg>
<div class="cols">
 <div><h2>Link</h2><table><tbody id="link"></tbody></table></div>
 <div><h2>Operator actions</h2><table><thead><tr><th class="num">time</th><th>action</th>
  <th>origin</th><th>outcome</th><th>message</th></tr></thead>
  <tbody id="operator-log"></tbody></table></div>
</div>
<script>
"use strict";
const token = new URLSearchParams(location.search).get("token");
const auth = token ? "token=" + encodeURIComponent(token) : "";
const $ = (id) => document.getElementById(id);
const NS = "http://www.w3.org/2000/svg";
let latest = null, following = true, playing = null, inflight = false, wanted = null;
let info = null, shown = null, shownAt = 0, canOperate = false;
const nodes = { places: {}, transitions: {} };

function withAuth(path) { return path + (auth ? (path.includes("?") ? "&" : "?") + auth : ""); }
function cell(row, text, cls) {
  const td = row.insertCell(); td.textContent = text; if (cls) td.className = cls; return td;
}
function rows(id, list, fill) {
  const body = $(id); body.replaceChildren();
  for (const item of list) fill(body.insertRow(), item);
}
function fmt(v, digits) {
  return v === null || v === undefined || v === "" ? "-" : Number(v).toFixed(digits);
}
function base() { return latest ? Number(latest.start) || 0 : 0; }
function at(t) { return fmt(t - base(), 1) + " s"; }  // times shown from the log's start
function tokens(n) { return n <= 0 ? "" : n <= 3 ? "\u2022".repeat(n) : String(n); }
function svgEl(parent, tag, attrs, text) {
  const e = document.createElementNS(NS, tag);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (text !== undefined) e.textContent = text;
  parent.appendChild(e); return e;
}

// ---- the net -------------------------------------------------------------------------
function drawNet() {
  const box = $("net");
  box.replaceChildren();
  if (!info || !info.net_svg) {
    $("net-note").textContent = info ? (info.net_note || "no drawing of the net") :
      "this server gives no net drawing";
    return;
  }
  const parsed = new DOMParser().parseFromString("<body>" + info.net_svg, "text/html");
  const svg = parsed.body.querySelector("svg");
  if (!svg) { $("net-note").textContent = "the net drawing cannot be read"; return; }
  svg.querySelectorAll("script, foreignObject").forEach((e) => e.remove());
  svg.querySelectorAll("*").forEach((e) => {
    for (const a of Array.from(e.attributes)) if (/^on/i.test(a.name)) e.removeAttribute(a.name);
  });
  box.appendChild(document.adoptNode(svg));
  $("net-note").textContent = info.net_note || "";
  box.querySelectorAll("svg.net g.place").forEach((g) => {
    const name = info.places[g.dataset.node]; if (name !== undefined) nodes.places[name] = g;
  });
  box.querySelectorAll("svg.net g.transition").forEach((g) => {
    const name = info.transitions[g.dataset.node];
    if (name !== undefined) nodes.transitions[name] = g;
  });
}

function renderNet(s, previous) {
  for (const [name, g] of Object.entries(nodes.places)) {
    const n = s.marking[name] || 0, text = g.querySelector("text.tokens");
    if (text) text.textContent = tokens(n);
    g.classList.toggle("marked", n > 0);
  }
  const enabled = new Set(s.enabled || []), out = new Set(s.in_flight || []);
  const offered = new Set((s.offered || []).map((i) => (info && info.input_transitions
    ? info.input_transitions[i] : i)));
  for (const [name, g] of Object.entries(nodes.transitions)) {
    g.classList.toggle("enabled", enabled.has(name));
    g.classList.toggle("inflight", out.has(name));
    g.classList.toggle("offered", offered.has(name));
  }
  // A flash on what fired since the snapshot shown before, when the log went forward.
  const fresh = previous && s.seq > previous.seq ? (s.fired_total || 0) -
    (previous.fired_total || 0) : 0;
  for (const [, name] of fresh > 0 ? (s.fired || []).slice(-fresh) : []) {
    const g = nodes.transitions[name];
    if (g) { g.classList.add("fired"); setTimeout(() => g.classList.remove("fired"), 900); }
  }
  if (following || playing) follow([...(s.in_flight || []), ...(s.enabled || [])]);
  $("enabled").textContent = (s.enabled || []).join(", ") || "none";
  $("in-flight").textContent = (s.in_flight || []).join(", ") || "none";
}

function follow(names) {
  // Keep the first active transition in view: a mission's net is wider than the screen.
  const box = $("net"), g = names.map((n) => nodes.transitions[n]).find((x) => x);
  if (!g || box.classList.contains("fit")) return;
  const r = g.getBoundingClientRect(), b = box.getBoundingClientRect();
  if (r.left < b.left || r.right > b.right) box.scrollLeft += r.left - b.left - b.width / 3;
  if (r.top < b.top || r.bottom > b.bottom) box.scrollTop += r.top - b.top - b.height / 3;
}

// ---- commands ------------------------------------------------------------------------
function params(p) {
  return Object.entries(p || {}).map(([k, v]) => k + " = " + JSON.stringify(v)).join(", ");
}
function renderCommands(s) {
  rows("commands", s.commands, (r, c) => {
    r.dataset.commandId = c.command_id;
    cell(r, c.command_id, "num"); cell(r, at(c.sent_at));
    const text = c.name + (Object.keys(c.params || {}).length ? "(" + params(c.params) + ")" : "");
    cell(r, text); cell(r, c.transition);
    const waiting = c.replies.length === 0;
    cell(r, waiting ? (c.awaiting || []).join(" | ") || "a reply" : "-", waiting ? "awaiting" : "");
    const down = cell(r, "-", "countdown num");
    if (waiting && c.timeout_at !== null && c.timeout_at !== undefined) {
      down.dataset.timeoutAt = c.timeout_at;
    }
    cell(r, waiting ? "awaiting reply" :
      c.replies.map((x) => x.kind + " at " + at(x.time)).join(", "), "reply");
    cell(r, c.sends, "num");
  });
  const total = s.commands_total || s.commands.length;
  $("commands-note").textContent = total > s.commands.length
    ? s.commands.length + " of " + total +
      " commands shown (every one in flight, the latest answered)"
    : "";
  tick();
}
function localNow() {
  if (!shown) return 0;
  if (!following || !latest || !latest.live) return shown.time;
  return shown.time + (performance.now() - shownAt) / 1000;
}
function tick() {
  const now = localNow();
  document.querySelectorAll("#commands .countdown").forEach((td) => {
    if (td.dataset.timeoutAt === undefined) return;
    const left = Number(td.dataset.timeoutAt) - now;
    td.textContent = left > 0 ? left.toFixed(1) + " s left" : "time-out due";
    td.classList.toggle("late", left <= 0);
  });
  if (shown) $("clock").textContent = at(now);
}

// ---- plots ---------------------------------------------------------------------------
function ticks(lo, hi, n) {
  const span = hi - lo || 1, raw = span / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((x) => span / x <= n) || 10 * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(v);
  return out;
}
function axes(svg, x0, x1, y0, y1, m, opts) {
  const W = Number(svg.getAttribute("width")), H = Number(svg.getAttribute("height"));
  const sx = (v) => m.l + (v - x0) / ((x1 - x0) || 1) * (W - m.l - m.r);
  const sy = opts.down ? (v) => m.t + (v - y0) / ((y1 - y0) || 1) * (H - m.t - m.b)
                       : (v) => H - m.b - (v - y0) / ((y1 - y0) || 1) * (H - m.t - m.b);
  svgEl(svg, "rect", { x: m.l, y: m.t, width: W - m.l - m.r, height: H - m.t - m.b,
    fill: "none", stroke: "#999" });
  for (const v of ticks(x0, x1, opts.xticks || 6)) {
    svgEl(svg, "line", { x1: sx(v), x2: sx(v), y1: m.t, y2: H - m.b, stroke: "#eee" });
    svgEl(svg, "text", { x: sx(v), y: H - m.b + 12, "text-anchor": "middle" },
      String(+v.toFixed(6)));
  }
  for (const v of ticks(y0, y1, opts.yticks || 4)) {
    svgEl(svg, "line", { x1: m.l, x2: W - m.r, y1: sy(v), y2: sy(v), stroke: "#eee" });
    const label = opts.ylabel ? opts.ylabel(v) : String(+v.toFixed(6));
    svgEl(svg, "text", { x: m.l - 4, y: sy(v) + 3, "text-anchor": "end" }, label);
  }
  if (opts.xname) svgEl(svg, "text", { x: W - m.r, y: H - 2, "text-anchor": "end" }, opts.xname);
  if (opts.yname) svgEl(svg, "text", { x: 2, y: m.t - 4 }, opts.yname);
  return { sx, sy, W, H };
}
function path(points) {
  // Points as [x, y] or null (a break); a path with a move at each break.
  let d = "", pen = false;
  for (const p of points) {
    if (!p) { pen = false; continue; }
    d += (pen ? "L" : "M") + p[0].toFixed(1) + "," + p[1].toFixed(1) + " "; pen = true;
  }
  return d;
}
function range(values, pad) {
  const v = values.filter((x) => x !== null && x !== undefined && isFinite(x));
  if (!v.length) return null;
  let lo = Math.min(...v), hi = Math.max(...v);
  if (hi - lo < 1e-9) { lo -= 1; hi += 1; }
  const p = (hi - lo) * pad; return [lo - p, hi + p];
}
function plotTrack(s) {
  const svg = $("track"); svg.replaceChildren();
  const track = s.track || [], space = info && info.workspace;
  const points = (info && info.waypoints) || [];
  const east = track.map((p) => p[2]), north = track.map((p) => p[1]);
  if (space) { east.push(space.y_min, space.y_max); north.push(space.x_min, space.x_max); }
  for (const w of points) { east.push(w.y); north.push(w.x); }
  let ex = range(east, 0.05), nx = range(north, 0.05);
  if (!ex || !nx) { svgEl(svg, "text", { x: 20, y: 30 }, "no telemetry yet"); return; }
  // Equal scales: widen the narrower range around its middle.
  const m = { l: 34, r: 8, t: 14, b: 28 };
  const W = Number(svg.getAttribute("width")) - m.l - m.r;
  const H = Number(svg.getAttribute("height")) - m.t - m.b;
  const k = Math.max((ex[1] - ex[0]) / W, (nx[1] - nx[0]) / H);
  const ec = (ex[0] + ex[1]) / 2, nc = (nx[0] + nx[1]) / 2;
  ex = [ec - k * W / 2, ec + k * W / 2]; nx = [nc - k * H / 2, nc + k * H / 2];
  const a = axes(svg, ex[0], ex[1], nx[0], nx[1], m,
    { xname: "y, east [m]", yname: "x, north [m]" });
  if (space) {
    svgEl(svg, "rect", { class: "workspace", x: a.sx(space.y_min), y: a.sy(space.x_max),
      width: a.sx(space.y_max) - a.sx(space.y_min), height: a.sy(space.x_min) - a.sy(space.x_max),
      fill: "none", stroke: "black", "stroke-width": 1.5 });
  }
  points.forEach((w, i) => {
    const x = a.sx(w.y), y = a.sy(w.x);
    svgEl(svg, "path", { class: "waypoint", d: "M" + (x - 4) + "," + (y - 4) + " L" + (x + 4) + ","
      + (y + 4) + " M" + (x - 4) + "," + (y + 4) + " L" + (x + 4) + "," + (y - 4),
      stroke: "black", "stroke-width": 2 });
    svgEl(svg, "text", { x: x + 5, y: y - 5 }, String(i + 1));
  });
  const line = track.map((p) => (p[1] === null || p[2] === null ? null : [a.sx(p[2]), a.sy(p[1])]));
  svgEl(svg, "path", { class: "track", d: path(line), fill: "none", stroke: "#1f77b4",
    "stroke-width": 1.5 });
  const last = track.filter((p) => p[1] !== null && p[2] !== null).pop();
  if (last) svgEl(svg, "circle", { class: "position", cx: a.sx(last[2]), cy: a.sy(last[1]), r: 4,
    fill: "#cf222e" });
}
function timeRange(s) {
  const start = latest ? latest.start : 0;
  return [0, Math.max(s.time - start, 1)];
}
function plotSeries(id, s, index, opts) {
  const svg = $(id); svg.replaceChildren();
  const track = s.track || [];
  let values = track.map((p) => p[index]);
  if (opts.heading) {  // whole turns so the middle of the range lies in [-90, 270)
    const r = range(values, 0);
    if (r) { const shift = -360 * Math.floor(((r[0] + r[1]) / 2 + 90) / 360);
      values = values.map((v) => (v === null ? null : v + shift)); }
  }
  const yr = range(values, 0.08), [t0, t1] = timeRange(s);
  if (!yr) { svgEl(svg, "text", { x: 20, y: 30 }, "no telemetry yet"); return; }
  const a = axes(svg, t0, t1, yr[0], yr[1], { l: 40, r: 8, t: 12, b: 26 },
    { down: opts.down, xname: "t [s] since the log's start", yname: opts.name,
      ylabel: opts.heading ? (v) => String(((v % 360) + 360) % 360) : undefined });
  const b = base();
  const line = track.map((p, i) => (values[i] === null ? null : [a.sx(p[0] - b), a.sy(values[i])]));
  svgEl(svg, "path", { class: "series", d: path(line), fill: "none", stroke: "#1f77b4",
    "stroke-width": 1.5 });
}
function plotTimeline(s) {
  const svg = $("timeline"); svg.replaceChildren();
  const lanes = [], lane = {};
  const add = (key, label) => {
    if (!(key in lane)) { lane[key] = lanes.length; lanes.push(label); }
  };
  for (const c of s.commands) add("c:" + c.name, "command " + c.name);
  for (const [, name] of s.fired || []) add("t:" + name, name);
  const rowH = 16, m = { l: 170, r: 10, t: 10, b: 26 };
  svg.setAttribute("height", String(m.t + m.b + Math.max(lanes.length, 1) * rowH));
  const [t0, t1] = timeRange(s);
  const a = axes(svg, t0, t1, -0.5, Math.max(lanes.length, 1) - 0.5, m,
    { down: true, xname: "t [s] since the log's start (controller clock)", yticks: 1,
      ylabel: () => "" });
  const b = base(), X = (t) => a.sx(t - b);
  lanes.forEach((label, i) => {
    const g = svgEl(svg, "g", { class: "lane", "data-lane": label });
    svgEl(g, "text", { x: m.l - 6, y: a.sy(i) + 3, "text-anchor": "end" }, label);
  });
  for (const c of s.commands) {
    const y = a.sy(lane["c:" + c.name]), done = c.replies.length ? c.replies[0].time : s.time;
    svgEl(svg, "line", { x1: X(c.sent_at), x2: X(done), y1: y, y2: y,
      stroke: c.replies.length ? "#9ecae1" : "#fdae6b", "stroke-width": 6 });
    svgEl(svg, "path", { d: "M" + X(c.sent_at) + "," + (y - 4) + " l6,4 l-6,4 z",
      fill: "#1f77b4" });
    for (const r of c.replies) svgEl(svg, "circle", { cx: X(r.time), cy: y, r: 3.5,
      fill: r.kind === "timeout" || r.kind === "error" ? "#cf222e" : "#1a7f37" });
  }
  for (const [t, name] of s.fired || []) {
    svgEl(svg, "path", { class: "firing", d: "M" + X(t) + "," + (a.sy(lane["t:" + name]) - 4)
      + " l4,4 l-4,4 l-4,-4 z", fill: "#808000" });
  }
  if (s.end) svgEl(svg, "line", { x1: X(s.end.time), x2: X(s.end.time), y1: m.t,
    y2: a.H - m.b, stroke: "black", "stroke-dasharray": "4 3" });
}

// ---- link and operator ---------------------------------------------------------------
const LINK = [["round_trip", "round trip (s)", 3], ["reply_after", "last reply after (s)", 2],
  ["handshakes", "handshakes"], ["reconnects", "reconnects"], ["resends", "commands re-sent"],
  ["outages", "outages"], ["outage_seconds", "time in outage (s)", 1],
  ["in_outage", "link down now"], ["rejected", "frames rejected"],
  ["telemetry-lost", "telemetry lost"]];
function renderLink(s) {
  const known = new Set(LINK.map((x) => x[0]));
  const extra = Object.keys(s.link).filter((k) => !known.has(k)).map((k) => [k, k]);
  rows("link", LINK.concat(extra).filter(([k]) => k in s.link), (r, [k, label, digits]) => {
    r.dataset.key = k; const v = s.link[k];
    cell(r, label);
    cell(r, typeof v === "boolean" ? (v ? "yes" : "no") :
      digits !== undefined ? fmt(v, digits) : (v === null ? "-" : String(v)), "num");
  });
}
function renderOperatorLog(s) {
  rows("operator-log", (s.operator || []).slice().reverse(), (r, a) => {
    cell(r, at(a.time), "num");
    cell(r, a.action === "give" ? "give " + a.input : a.action);
    cell(r, a.origin); cell(r, a.accepted ? "accepted" : "refused"); cell(r, a.message);
  });
}
function operatorButtons() {
  const box = $("operator-buttons"); box.replaceChildren();
  const button = (action, input, label) => {
    const b = document.createElement("button");
    b.dataset.action = action; if (input !== null) b.dataset.input = input;
    b.textContent = label; b.addEventListener("click", () => ask(action, input));
    box.appendChild(b);
  };
  button("pause", null, "pause"); button("resume", null, "resume");
  for (const name of (info && info.inputs) || []) button("give", name, "give " + name);
}
function operatorState() {
  if (!canOperate || !latest) return;
  const s = latest.snapshot, over = !latest.live || !!s.end, offered = new Set(s.offered || []);
  document.querySelectorAll("#operator button[data-action]").forEach((b) => {
    const action = b.dataset.action;
    b.disabled = over || (action === "pause" && s.paused) || (action === "resume" && !s.paused)
      || (action === "give" && !offered.has(b.dataset.input));
  });
}
function ask(action, input) {
  // Giving an input cannot be undone (the mission's net acts on it): ask first.
  if (action === "give" && !window.confirm("Give input " + input + " to the running mission?"
    + " The mission's net decides what it does; it cannot be taken back.")) {
    $("operator-answer").textContent = "give " + input + ": cancelled";
    return;
  }
  operate(action, input);
}
async function operate(action, input) {
  $("operator-answer").textContent = "sending " + (input ? "give " + input : action) + "...";
  try {
    const r = await fetch("operate", { method: "POST",
      headers: { "Content-Type": "application/json", "Authorization": "Bearer " + (token || ""),
                 "X-Coral-Client": "page" },
      body: JSON.stringify({ action: action, input: input }) });
    if (r.ok) {
      const answer = await r.json();
      $("operator-answer").textContent =
        (answer.accepted ? "accepted: " : "refused: ") + answer.message;
    } else {
      $("operator-answer").textContent =
        "refused by the server (" + r.status + "): " + (await r.text());
    }
  } catch (e) { $("operator-answer").textContent = "cannot reach the server: " + e; }
}

// ---- the whole page ------------------------------------------------------------------
function render(doc) {
  const s = doc.snapshot || doc;
  const previous = shown;
  shown = s; shownAt = performance.now();
  $("mission").textContent = doc.mission || (info && info.mission) || "";
  $("mode").textContent = following ? (doc.live ? "LIVE" : "ended") : "replay";
  $("paused").hidden = !s.paused;
  rows("marking", Object.entries(s.marking), (r, [p, n]) => {
    r.dataset.place = p; cell(r, p); cell(r, n, "num"); });
  const t = s.telemetry;
  rows("telemetry", t ? [["x, north (m)", fmt(t.x, 2)], ["y, east (m)", fmt(t.y, 2)],
    ["depth (m)", fmt(t.depth, 2)], ["heading (deg)", fmt(t.heading, 1)],
    ["at", at(t.time)]] : [["no sample yet", ""]],
    (r, [k, v]) => { cell(r, k); cell(r, v, "num"); });
  renderNet(s, previous);
  renderCommands(s);
  renderLink(s);
  renderOperatorLog(s);
  plotTrack(s);
  plotSeries("depth", s, 3, { down: true, name: "depth [m]" });
  plotSeries("heading", s, 4, { heading: true, name: "heading [deg]" });
  plotTimeline(s);
  $("end").textContent = doc.broken ? "live view lost: " + doc.broken : s.end
    ? "mission ended: " + s.end.end + " at " + at(s.end.time) : "";
  operatorState();
}

function span(doc) {
  const bar = $("scrub"); bar.min = doc.start; bar.max = doc.end;
  if (following) bar.value = doc.end;
}

async function fetchAt(t) {
  if (inflight) { wanted = t; return; }
  inflight = true;
  try {
    const r = await fetch(withAuth("snapshot?t=" + t));
    if (r.ok) { const doc = await r.json(); if (!following) render(doc); }
  } finally {
    inflight = false;
    if (wanted !== null) { const next = wanted; wanted = null; fetchAt(next); }
  }
}

function stop() {
  if (playing) { clearInterval(playing); playing = null; $("play").textContent = "play"; }
}

$("scrub").addEventListener("input", () => {
  following = false; stop(); fetchAt($("scrub").value);
});
$("live").addEventListener("click", () => {
  following = true; stop(); if (latest) { span(latest); render(latest); }
});
$("play").addEventListener("click", () => {
  if (playing) { stop(); return; }
  const bar = $("scrub");
  if (following || Number(bar.value) >= Number(bar.max)) bar.value = bar.min;
  following = false; $("play").textContent = "pause";
  playing = setInterval(() => {
    const t = Math.min(Number(bar.value) + 0.2 * Number($("speed").value), Number(bar.max));
    bar.value = t; fetchAt(t);
    if (t >= Number(bar.max)) stop();
  }, 200);
});
$("net-fit").addEventListener("click", () => {
  const fit = $("net").classList.toggle("fit");
  $("net-fit").textContent = fit ? "actual size" : "fit to width";
  if (!fit && shown) follow([...(shown.in_flight || []), ...(shown.enabled || [])]);
});
setInterval(tick, 250);

async function getJson(path) {
  try { const r = await fetch(withAuth(path)); return r.ok ? await r.json() : null; }
  catch (e) { return null; }
}

async function start() {
  info = await getJson("info");
  drawNet();
  const rights = await getJson("rights");
  canOperate = !!(rights && rights.operate);
  $("operator").hidden = !canOperate;
  if (canOperate) operatorButtons();
  const r = await fetch(withAuth("snapshot"));
  if (!r.ok) { $("mission").textContent = "cannot read the snapshot (" + r.status + ")"; return; }
  latest = await r.json(); span(latest); render(latest);
  if (latest.live) {
    const source = new EventSource(withAuth("events"));
    source.onmessage = (m) => {
      latest = JSON.parse(m.data); span(latest);
      if (following) render(latest); else operatorState();
      if (!latest.live) source.close();
    };
    source.onerror = () => {  // the server went away (the run ended) or the network did
      if (following) $("mode").textContent = "LIVE: connection lost, retrying";
    };
  }
}
start();
</script>
</body></html>
"""
