// The live map: polls /state (JSON built by gcs/mapserver.py from what the station heard over MAVLink) and draws
// it as SVG, north up. No framework, no build step, nothing fetched from outside this station.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const W = 800, H = 600, PAD = 40;
const POLL_MS = 300;
const $ = (id) => document.getElementById(id);

function el(name, attrs, parent) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

function clear(g) { while (g.firstChild) g.removeChild(g.firstChild); }

function qualityClass(q) { return q >= 0.75 ? "good" : q >= 0.4 ? "fair" : "poor"; }
const COLOURS = { good: "#2ecc71", fair: "#f1c40f", poor: "#e74c3c" };

// A view that keeps every drawn thing on screen: [north, east] -> SVG x (east), y (north up).
function makeView(points) {
  let n0 = Infinity, n1 = -Infinity, e0 = Infinity, e1 = -Infinity;
  for (const [n, e] of points) {
    n0 = Math.min(n0, n); n1 = Math.max(n1, n); e0 = Math.min(e0, e); e1 = Math.max(e1, e);
  }
  if (!isFinite(n0)) { n0 = -10; n1 = 10; e0 = -10; e1 = 10; }
  const scale = Math.min((W - 2 * PAD) / Math.max(e1 - e0, 10), (H - 2 * PAD) / Math.max(n1 - n0, 10));
  const cn = (n0 + n1) / 2, ce = (e0 + e1) / 2;
  return {
    scale,
    x: (e) => W / 2 + (e - ce) * scale,
    y: (n) => H / 2 - (n - cn) * scale,
  };
}

function drawGrid(v) {
  const g = $("grid"); clear(g);
  const step = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000].find((d) => d * v.scale >= 60) || 1000;
  $("scale").textContent = `grid ${step} m`;
  for (let k = -60; k <= 60; k++) {
    const x = v.x(k * step), y = v.y(k * step);
    if (x >= 0 && x <= W) el("line", { x1: x, y1: 0, x2: x, y2: H }, g);
    if (y >= 0 && y <= H) el("line", { x1: 0, y1: y, x2: W, y2: y }, g);
  }
}

function drawTrail(v, trail) {
  const g = $("trail"); clear(g);
  g.setAttribute("data-count", String(trail.length));
  let run = [], cls = null;
  const flush = () => {
    if (run.length > 1) {
      el("polyline", { points: run.map(([n, e]) => `${v.x(e)},${v.y(n)}`).join(" "), fill: "none",
                       stroke: COLOURS[cls], "stroke-width": 4, "stroke-linecap": "round",
                       "stroke-linejoin": "round", class: `trail-${cls}` }, g);
    }
  };
  for (const p of trail) {
    const c = qualityClass(p[2]);
    if (c !== cls) { const last = run[run.length - 1]; flush(); run = last ? [last] : []; cls = c; }
    run.push(p);
  }
  flush();
  for (const p of trail) {
    el("circle", { cx: v.x(p[1]), cy: v.y(p[0]), r: 2, fill: COLOURS[qualityClass(p[2])] }, g);
  }
}

// The vehicle's link map: one square per cell, coloured by the share of the owner's packets delivered there.
function drawLinkMap(v, lm) {
  const g = $("linkmap"); clear(g);
  const cells = lm && lm.cells ? lm.cells : [];
  g.setAttribute("data-count", String(cells.length));
  if (!cells.length) return;
  const side = lm.cell * v.scale;
  for (const [n, e, q, obs] of cells) {
    const cls = q === null ? "unknown" : qualityClass(q);
    const r = el("rect", { x: v.x(e) - side / 2, y: v.y(n) - side / 2, width: side, height: side,
                           fill: q === null ? "#7f8c8d" : COLOURS[cls], "fill-opacity": 0.28, stroke: "none",
                           class: `linkmap-${cls}` }, g);
    el("title", {}, r).textContent = q === null ? `no packets expected (${obs} obs)`
      : `delivery ${(100 * q).toFixed(0)} % (${obs} obs)`;
  }
}

function drawRobot(v, pos, yaw) {
  const g = $("robot"); clear(g);
  if (!pos) return;
  const deg = (yaw || 0) * 180 / Math.PI;  // yaw from north, clockwise: SVG rotates clockwise too
  const r = el("g", { transform: `translate(${v.x(pos[1])},${v.y(pos[0])}) rotate(${deg})`, id: "robot-mark" }, g);
  el("polygon", { points: "0,-14 9,10 0,5 -9,10", fill: "#ecf0f1", stroke: "#111", "stroke-width": 1.5 }, r);
}

function draw(s) {
  const L = s.lease || {};
  const pts = s.trail.map((p) => [p[0], p[1]]);
  if (s.position) pts.push(s.position);
  for (const p of s.route) pts.push(p);
  if (L.return_target) pts.push(L.return_target);
  if (L.return_start) pts.push(L.return_start);
  for (const p of s.lost) pts.push([p[0], p[1]]);
  // the displacement circle is not fitted: at 50 m it would shrink a short trail to a dot
  const v = makeView(pts);
  drawGrid(v);
  drawLinkMap(v, s.linkmap);

  const cg = $("circle"); clear(cg);
  if (s.circle) {
    const [n, e] = s.circle.center;
    el("circle", { cx: v.x(e), cy: v.y(n), r: s.circle.radius * v.scale, fill: "none",
                   stroke: s.circle.kind === "return" ? "#e67e22" : "#7f8c8d", "stroke-width": 1.5,
                   "stroke-dasharray": "8 6", id: "displacement-circle", "data-kind": s.circle.kind }, cg);
  }
  drawTrail(v, s.trail);

  const rg = $("route"); clear(rg);
  if (s.route.length > 1) {
    el("polyline", { points: s.route.map(([n, e]) => `${v.x(e)},${v.y(n)}`).join(" "), fill: "none",
                     stroke: "#5dade2", "stroke-width": 2.5, "stroke-dasharray": "6 5", id: "return-route" }, rg);
  }
  const lg = $("lost"); clear(lg);
  for (const [n, e, t] of s.lost) {
    const x = v.x(e), y = v.y(n), d = 8;
    const m = el("g", { class: "lost-point" }, lg);
    el("line", { x1: x - d, y1: y - d, x2: x + d, y2: y + d, stroke: "#ff5e57", "stroke-width": 3 }, m);
    el("line", { x1: x - d, y1: y + d, x2: x + d, y2: y - d, stroke: "#ff5e57", "stroke-width": 3 }, m);
    el("title", {}, m).textContent = `link lost at t=${t} s`;
  }
  const tg = $("target"); clear(tg);
  if (L.return_target) {
    const [n, e] = L.return_target;
    el("circle", { cx: v.x(e), cy: v.y(n), r: 9, fill: "none", stroke: "#f39c12", "stroke-width": 3,
                   id: "return-target" }, tg);
    el("circle", { cx: v.x(e), cy: v.y(n), r: 3, fill: "#f39c12" }, tg);
  }
  drawRobot(v, s.position, s.yaw);

  const stale = s.heard_s === null || s.heard_s > 2;
  $("link").textContent = s.heard_s === null ? "no vehicle heard yet"
    : `vehicle ${s.vehicle} heard ${s.heard_s.toFixed(1)} s ago${s.armed ? ", armed" : ", disarmed"}`;
  $("link").className = "link" + (stale ? " stale" : "");
  $("state").textContent = L.state || "-";
  $("state").className = L.state ? `state-${L.state}` : "";
  $("lease").textContent = L.epoch === undefined ? "-" : `[${L.epoch},${L.index}]${L.claimed ? "" : " unclaimed"}`;
  $("owner").textContent = L.owner ? `GCS ${L.owner}` : "none";
  $("scheduled").textContent = L.scheduled === undefined ? "-" : `${L.scheduled} lease(s)`;
  $("reason").textContent = L.reason || "-";
  $("age").textContent = L.link_age === null || L.link_age === undefined ? "never" : `${L.link_age.toFixed(1)} s ago`;
  $("position").textContent = s.position ? `N ${s.position[0].toFixed(1)}  E ${s.position[1].toFixed(1)} m` : "-";
  $("displacement").textContent = L.max_displacement ? `${(L.displacement || 0).toFixed(1)} / ${L.max_displacement.toFixed(0)} m`
    : (s.circle ? `limit ${s.circle.radius.toFixed(0)} m` : "-");
  $("trailpoints").textContent = L.trail_points === undefined ? "-" : `${L.trail_points} crumbs`;
  $("plan").textContent = s.plan;
  $("events").textContent = s.events.join("\n");
  $("texts").textContent = s.texts.join("\n");
}

async function poll() {
  try {
    const r = await fetch("/state", { cache: "no-store" });
    draw(await r.json());
  } catch (err) {
    $("link").textContent = `station not answering (${err})`;
    $("link").className = "link stale";
  }
  setTimeout(poll, POLL_MS);
}

for (const b of document.querySelectorAll("button[data-action]")) {
  b.addEventListener("click", async () => {
    const a = $("answer");
    a.textContent = `${b.dataset.action}…`; a.className = "answer";
    try {
      const r = await fetch(`/action/${b.dataset.action}`, { method: "POST" });
      const j = await r.json();
      a.textContent = j.message; a.className = "answer" + (j.ok ? "" : " bad");
    } catch (err) {
      a.textContent = String(err); a.className = "answer bad";
    }
  });
}
poll();
