// forgemon's history page: draws what /history/data gives (history::trend) and computes no
// statistic of its own: the chart limits come with the data. When the page has drawn, it sets
// document.body.dataset.ready and window.historyDrawn = {blows, ms: this load, at: since the page's
// time origin} (the browser test reads them).
"use strict";

const $ = (id) => document.getElementById(id);
const PALETTE = ["#1f5fa8", "#e0601a", "#2e7d32", "#6a1b9a", "#c62828", "#00838f", "#9a6a00", "#5d4037"];
let data = null;

function colour(i) { return PALETTE[i % PALETTE.length]; }
function name(n) { return n === null ? "(none)" : n; }
function day(ms) { return new Date(ms).toISOString().slice(0, 16).replace("T", " "); }
function short(ms) { return day(ms).slice(5); }
function fixed(x, d) { return x === null || x === undefined ? "–" : x.toFixed(d); }

// A canvas sized to its box at the screen's pixel ratio, and its context.
function surface(id) {
  const c = $(id), dpr = window.devicePixelRatio || 1;
  const w = c.clientWidth, h = c.clientHeight;
  c.width = w * dpr; c.height = h * dpr;
  const g = c.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, w, h);
  g.font = "12px DejaVu Sans, Arial, sans-serif";
  return { g, w, h };
}

// Axes for x in [x0, x1] and y in [y0, y1]: the mapping, with the y ticks drawn.
function frame(s, x0, x1, y0, y1, yTicks, yFmt) {
  const L = 48, R = 10, T = 8, B = 20;
  const sx = (x) => L + (x - x0) / ((x1 - x0) || 1) * (s.w - L - R);
  const sy = (y) => s.h - B - (y - y0) / ((y1 - y0) || 1) * (s.h - T - B);
  const g = s.g;
  g.strokeStyle = "#c9ced6"; g.fillStyle = "#5f6670"; g.lineWidth = 1;
  for (let k = 0; k <= yTicks; k++) {
    const y = y0 + (y1 - y0) * k / yTicks;
    g.beginPath(); g.moveTo(L, sy(y)); g.lineTo(s.w - R, sy(y)); g.stroke();
    g.fillText(yFmt(y), 4, sy(y) + 4);
  }
  return { sx, sy, L, R, T, B };
}

// Every blow in time order, evenly spaced (a weekend or a stop leaves no gap), its time at
// five ticks.
function drawTrend() {
  const s = surface("trend"), t = data.t_ms, e = data.efficiency;
  if (t.length === 0) { s.g.fillText("no blows under these filters", 60, 40); return; }
  const n = t.length, f = frame(s, 0, Math.max(n - 1, 1), 0, 1, 4, (y) => y.toFixed(2));
  const g = s.g;
  for (let i = 0; i < n; i++) {
    if (e[i] === null) continue;
    g.fillStyle = colour(data.die[i]);
    g.fillRect(f.sx(i) - 1, f.sy(e[i]) - 1, 2, 2);
  }
  g.fillStyle = "#5f6670";
  for (let k = 0; k <= 4; k++) {
    const i = Math.round((n - 1) * k / 4), label = day(t[i]);
    const w = g.measureText(label).width;
    g.fillText(label, Math.min(Math.max(f.sx(i) - w / 2, f.L), s.w - f.R - w), s.h - 4);
  }
  $("trend-legend").innerHTML = data.die_sets
    .map((d, i) => `<span class="key" style="background:${colour(i)}"></span>${name(d)}`).join(" &nbsp; ");
}

// The efficiencies of blow `b` in time order, and their moving ranges.
function series(b) {
  const xs = [];
  for (let i = 0; i < data.t_ms.length; i++) {
    if (data.billet_blow[i] === b && data.efficiency[i] !== null) xs.push(data.efficiency[i]);
  }
  return xs;
}

function drawImr() {
  const b = Number($("imr-blow").value);
  const c = data.spc.find((x) => x.blow === b);
  const sx = surface("imr-x"), sm = surface("imr-mr");
  if (!c) { sx.g.fillText("fewer than two blows", 60, 40); $("imr-figures").textContent = ""; return; }
  const xs = series(b), mr = xs.slice(1).map((x, i) => Math.abs(x - xs[i]));
  // The axes' range (a loop: spreading 100 000 values into Math.min overflows the stack).
  const lo = xs.reduce((m, x) => Math.min(m, x), c.x_lcl), hi = xs.reduce((m, x) => Math.max(m, x), c.x_ucl);
  const pad = (hi - lo) * 0.05 || 0.01;
  const fx = frame(sx, 0, xs.length - 1, lo - pad, hi + pad, 4, (y) => y.toFixed(3));
  line(sx.g, fx, xs, "#1f5fa8");
  limit(sx.g, fx, sx.w, c.mean, "#2e7d32"); limit(sx.g, fx, sx.w, c.x_lcl, "#c62828"); limit(sx.g, fx, sx.w, c.x_ucl, "#c62828");
  const mhi = mr.reduce((m, x) => Math.max(m, x), c.mr_ucl) * 1.05 || 0.01;
  const fm = frame(sm, 0, Math.max(mr.length - 1, 1), 0, mhi, 2, (y) => y.toFixed(3));
  line(sm.g, fm, mr, "#1f5fa8");
  limit(sm.g, fm, sm.w, c.mr_bar, "#2e7d32"); limit(sm.g, fm, sm.w, c.mr_ucl, "#c62828");
  $("imr-figures").textContent =
    `n ${c.n} · mean ${c.mean.toFixed(4)} · limits ${c.x_lcl.toFixed(4)} – ${c.x_ucl.toFixed(4)} · MR̄ ${c.mr_bar.toFixed(4)}`;
}

function line(g, f, ys, stroke) {
  g.strokeStyle = stroke; g.lineWidth = 1; g.beginPath();
  ys.forEach((y, i) => (i ? g.lineTo(f.sx(i), f.sy(y)) : g.moveTo(f.sx(i), f.sy(y))));
  g.stroke();
}

function limit(g, f, w, y, stroke) {
  g.strokeStyle = stroke; g.setLineDash([6, 4]); g.beginPath();
  g.moveTo(f.L, f.sy(y)); g.lineTo(w - f.R, f.sy(y)); g.stroke(); g.setLineDash([]);
}

function groupRows(id, groups, keyed) {
  $(id).innerHTML = groups.map((gr, i) =>
    `<tr><td>${keyed ? `<span class="key" style="background:${colour(i)}"></span>` : ""}${name(gr.name)}</td>` +
    `<td>${gr.blows}</td><td>${gr.billets}</td><td>${gr.hard}</td><td>${gr.nok}</td>` +
    `<td>${fixed(gr.mean_efficiency, 3)}</td><td>${short(gr.first_ms)}</td><td>${short(gr.last_ms)}</td></tr>`).join("");
}

function draw(t0) {
  $("h-blows").textContent = data.t_ms.length;
  $("h-dies").textContent = data.die_sets.length;
  $("h-lots").textContent = data.lots.length;
  $("summary").textContent = data.t_ms.length ? `${day(data.t_ms[0])} – ${day(data.t_ms[data.t_ms.length - 1])} UTC` : "";
  const sel = $("imr-blow"), keep = sel.value;
  sel.innerHTML = data.spc.map((c) => `<option value="${c.blow}">${c.blow} (n ${c.n})</option>`).join("");
  if (data.spc.some((c) => String(c.blow) === keep)) sel.value = keep;
  drawTrend();
  drawImr();
  groupRows("by-die", data.by_die, true);
  groupRows("by-lot", data.by_lot, false);
  window.historyDrawn = { blows: data.t_ms.length, ms: performance.now() - t0, at: performance.now() };
  document.body.dataset.ready = "1";
}

async function load() {
  const t0 = performance.now();
  document.body.dataset.ready = "";
  const q = new URLSearchParams(new FormData($("filters")));
  $("error").textContent = "";
  try {
    const r = await fetch("history/data?" + q.toString());
    if (!r.ok) throw new Error(await r.text());
    data = await r.json();
    draw(t0);
  } catch (err) {
    $("error").textContent = String(err.message || err);
    document.body.dataset.ready = "error";
  }
}

$("filters").addEventListener("submit", (ev) => { ev.preventDefault(); load(); });
$("imr-blow").addEventListener("change", drawImr);
window.addEventListener("resize", () => data && draw(performance.now()));
load();
