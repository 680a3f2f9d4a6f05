"""The watch page: one self-contained HTML file with inline CSS and JavaScript.

Why no external asset (no CDN, no web font): the page must work on a ship's or a lab's
network with no Internet access, and a third-party script on a page that will one day
carry operator actions is a risk we need not take. Text from the log is always inserted
with ``textContent``, never as HTML.
"""

from __future__ import annotations

from typing import Final

__all__ = ["PAGE"]

PAGE: Final = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>coral watch</title>
<style>
body { font: 14px/1.4 system-ui, sans-serif; margin: 1em 2em; color: #222; }
h1 { font-size: 1.3em; margin: 0 0 .3em; } h2 { font-size: 1.05em; margin: 1em 0 .3em; }
table { border-collapse: collapse; } td, th { padding: 2px 10px 2px 0; text-align: left; }
th { border-bottom: 1px solid #999; }
.num { text-align: right; font-variant-numeric: tabular-nums; }
#bar { display: flex; gap: .8em; align-items: center; margin: .5em 0; }
#scrub { flex: 1; } #mode { font-weight: bold; } .end { color: #a00; font-weight: bold; }
.awaiting { color: #b60; } .cols { display: flex; gap: 3em; flex-wrap: wrap; }
</style></head>
<body>
<h1>coral watch: <span id="mission"></span></h1>
<div id="bar">
  <span id="mode"></span>
  <button id="play">play</button>
  <select id="speed"><option>1</option><option selected>5</option><option>20</option>
  <option>100</option></select>x
  <input id="scrub" type="range" min="0" max="0" step="0.1" value="0">
  <span id="clock" class="num"></span>
  <button id="live">follow live</button>
</div>
<div id="end"></div>
<div class="cols">
 <div><h2>Marking</h2><table><thead><tr><th>place</th><th class="num">tokens</th></tr></thead>
  <tbody id="marking"></tbody></table></div>
 <div><h2>Telemetry</h2><table><tbody id="telemetry"></tbody></table>
  <h2>Link</h2><table><tbody id="link"></tbody></table></div>
</div>
<h2>Commands</h2>
<table><thead><tr><th class="num">id</th><th>sent</th><th>command</th><th>transition</th>
<th>parameters</th><th>status</th></tr></thead><tbody id="commands"></tbody></table>
<script>
"use strict";
const token = new URLSearchParams(location.search).get("token");
const auth = token ? "token=" + encodeURIComponent(token) : "";
const $ = (id) => document.getElementById(id);
let latest = null, following = true, playing = null, inflight = false, wanted = null;

function cell(row, text, cls) {
  const td = row.insertCell(); td.textContent = text; if (cls) td.className = cls; return td;
}
function rows(id, list, fill) {
  const body = $(id); body.replaceChildren();
  for (const item of list) fill(body.insertRow(), item);
}
function fmt(v, digits) { return v === null || v === undefined ? "-" : Number(v).toFixed(digits); }

function render(doc) {
  const s = doc.snapshot;
  $("mission").textContent = doc.mission;
  $("clock").textContent = fmt(s.time, 1) + " s";
  $("mode").textContent = following ? (doc.live ? "LIVE" : "ended") : "replay";
  rows("marking", Object.entries(s.marking), (r, [p, n]) => { cell(r, p); cell(r, n, "num"); });
  const t = s.telemetry;
  rows("telemetry", t ? [["x (m)", fmt(t.x, 2)], ["y (m)", fmt(t.y, 2)],
    ["depth (m)", fmt(t.depth, 2)], ["heading (deg)", fmt(t.heading, 1)],
    ["at (s)", fmt(t.time, 1)]] : [["no sample yet", ""]],
    (r, [k, v]) => { cell(r, k); cell(r, v, "num"); });
  rows("link", Object.entries(s.link), (r, [k, v]) => { cell(r, k); cell(r, v, "num"); });
  rows("commands", s.commands, (r, c) => {
    cell(r, c.command_id, "num"); cell(r, fmt(c.sent_at, 1)); cell(r, c.name);
    cell(r, c.transition); cell(r, JSON.stringify(c.params));
    cell(r, c.status + (c.sends > 1 ? " (sent " + c.sends + " times)" : ""),
         c.replies.length ? "" : "awaiting");
  });
  $("end").textContent = s.end
    ? "mission ended: " + s.end.end + " at " + fmt(s.end.time, 1) + " s" : "";
  $("end").className = s.end ? "end" : "";
}

function span(doc) {
  const bar = $("scrub"); bar.min = doc.start; bar.max = doc.end;
  if (following) bar.value = doc.end;
}

async function fetchAt(t) {
  if (inflight) { wanted = t; return; }
  inflight = true;
  try {
    const r = await fetch("snapshot?t=" + t + (auth ? "&" + auth : ""));
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

async function start() {
  const r = await fetch("snapshot" + (auth ? "?" + auth : ""));
  if (!r.ok) { $("mission").textContent = "cannot read the snapshot (" + r.status + ")"; return; }
  latest = await r.json(); span(latest); render(latest);
  if (latest.live) {
    const source = new EventSource("events" + (auth ? "?" + auth : ""));
    source.onmessage = (m) => {
      latest = JSON.parse(m.data); span(latest);
      if (following) render(latest);
      if (!latest.live) source.close();
    };
  }
}
start();
</script>
</body></html>
"""
