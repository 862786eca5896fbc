// forgemon's operator screen (src/daemon/dashboard/mod.rs). Everything shown comes from the
// service: /dashboard/state (the status snapshot, the last 50 blows, this billet's blows),
// /blow/last/curve and the live feed on /events. The state is fetched again on every event
// and whenever the event stream (re)connects, so a service restart is followed by itself,
// and polled every second. The header's link and the sources table's states are drawn from one
// state (`link`), so that they never disagree.
// A token given as ?token= is sent as a bearer header on every fetch (and as ?token= on the
// event stream, which cannot send headers).
"use strict";

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token");
const headers = token ? { Authorization: "Bearer " + token } : {};
const CLASSES = ["soft", "intermediate", "hard", "incomplete", "implausible"];
// The class words under the bars, short enough for a bar 40 px wide (the full word is its title).
const SHORT = { soft: "soft", intermediate: "interm.", hard: "hard", incomplete: "incompl.", implausible: "implaus." };

// The one state the header and the sources table show: whether the service answers (its
// event stream is open and its last state fetch answered), and its last state.
const link = { stream: false, answered: false, state: null, at: null };
const serviceUp = () => link.stream && link.answered;

async function getJSON(path) {
  const r = await fetch(path, { headers, cache: "no-store" });
  if (!r.ok) throw new Error(path + ": HTTP " + r.status);
  return r.json();
}

const fmt = (x, digits) => (x === null || x === undefined ? "–" : Number(x).toFixed(digits));
const classOf = (c) => (CLASSES.includes(c) ? c : "none");
function cell(text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  return td;
}

function renderLast(b) {
  if (!b) return;
  $("big-blow").textContent = b.blow;
  $("big-eff").textContent = b.efficiency === null ? "–" : Math.round(100 * b.efficiency) + " %";
  const badge = $("big-class");
  badge.textContent = b.class;
  badge.className = "class-badge " + classOf(b.class);
  $("big-plastic").textContent = b.plastic_J === null ? "–" : fmt(b.plastic_J, 0) + " J";
  $("big-kinetic").textContent = b.kinetic_in_J === null ? "–" : fmt(b.kinetic_in_J, 0) + " J";
  $("big-speed").textContent = fmt(b.v_impact_mps, 2) + " m/s";
  $("big-height").textContent = b.h_end_m === null ? "–" : fmt(1000 * b.h_end_m, 2) + " mm";
  $("big-channels").textContent = sensingMode(b.channels);
  if (b.efficiency !== null && b.efficiency_sd != null)
    $("big-eff").title = "± " + fmt(100 * b.efficiency_sd, 1) + " % (1σ, " + sensingMode(b.channels) + ")";
}

// The channels a blow's estimate used, and the one it went without (issue 43).
function sensingMode(channels) {
  const all = ["load", "acc", "disp"];
  const used = Array.isArray(channels) ? channels : all;
  const missing = all.filter((c) => !used.includes(c));
  return used.join(" + ") + (missing.length ? " (no " + missing.join(", ") + ")" : "");
}

// The panel shows three lines of the reason: the whole of it is the element's title (on
// hover) and opens over the page on a click (or Enter), closing on the next.
function setReason(text) {
  const r = $("alert-reason");
  if (r.textContent === text) return;
  r.textContent = text;
  r.title = text;
  openReason(false);
}

function openReason(open) {
  const r = $("alert-reason");
  if (open && r.textContent) {
    const box = r.getBoundingClientRect();
    r.style.left = box.left + "px";
    r.style.top = box.top + "px";
    r.style.width = Math.max(box.width, 420) + "px";
    r.style.maxHeight = window.innerHeight - box.top - 8 + "px";
  } else {
    open = false;
    r.removeAttribute("style");
  }
  r.classList.toggle("open", open);
  r.setAttribute("aria-expanded", String(open));
}

function renderAlert(latched, acked) {
  const box = $("alert"), button = $("ack");
  if (latched) {
    box.className = "panel alert latched";
    $("alert-kind").textContent = latched.kind + " · blow " + latched.blow;
    setReason(latched.reason);
    button.hidden = false;
    button.disabled = false;
  } else if (acked) {
    box.className = "panel alert acked";
    $("alert-kind").textContent = "acknowledged: " + acked.kind + " · blow " + acked.blow;
    setReason(acked.reason);
    button.hidden = true;
  } else {
    box.className = "panel alert none";
    $("alert-kind").textContent = "no alert";
    setReason("");
    button.hidden = true;
  }
}

function renderBars(blows) {
  const bars = $("bars");
  bars.replaceChildren();
  for (const b of blows) {
    const bar = document.createElement("div");
    bar.className = "bar";
    const eff = document.createElement("span");
    eff.className = "eff";
    eff.textContent = b.efficiency === null ? "–" : Math.round(100 * b.efficiency) + "%";
    const fill = document.createElement("div");
    fill.className = "fill " + classOf(b.class);
    fill.style.height = Math.max(0, Math.min(1, b.efficiency ?? 0)) * 62 + "%";
    const word = document.createElement("span");
    word.className = "word " + classOf(b.class);
    word.textContent = SHORT[b.class] ?? b.class;
    const n = document.createElement("span");
    n.className = "n";
    n.textContent = "blow " + b.billet_blow;
    bar.title = "blow " + b.blow + ": " + b.class;
    bar.append(eff, fill, word, n);
    bars.append(bar);
  }
}

// The blow against the active recipe: OK, or NOK with its reasons as the cell's title;
// empty without a recipe (and on an incomplete blow, never judged).
function judgementCell(j) {
  if (!j) return cell("", "jd");
  const td = cell(j.ok ? "OK" : "NOK", "jd " + (j.ok ? "ok" : "nok"));
  td.title = j.ok ? "recipe " + j.recipe : j.reasons.join("\n");
  return td;
}

// The time of day in the browser's zone, which on the plant PC the dashboard runs on is the
// plant's: hours, minutes, seconds and tenths, 24 h.
const ZONE = Intl.DateTimeFormat().resolvedOptions().timeZone;
const CLOCK = new Intl.DateTimeFormat("en-GB", { hour: "2-digit", minute: "2-digit", second: "2-digit",
  fractionalSecondDigits: 1, hourCycle: "h23" });

// First contact as the time of day, its device time as the title; the device time alone
// before the service had a batch to map it by.
function timeCell(b) {
  if (b.t_contact_unix_s === null || b.t_contact_unix_s === undefined) return cell(fmt(b.t_contact_s, 4) + " s", "t");
  const td = cell(CLOCK.format(new Date(1000 * b.t_contact_unix_s)), "t");
  td.title = "first contact, " + ZONE + " time; device clock t = " + fmt(b.t_contact_s, 4) + " s";
  return td;
}

function renderBlows(blows) {
  const rows = blows.map((b) => {
    const tr = document.createElement("tr");
    tr.dataset.blow = b.blow;
    tr.append(
      cell(b.billet), cell(b.blow), timeCell(b), cell(fmt(b.v_impact_mps, 2)),
      cell(fmt(b.kinetic_in_J, 0)), cell(fmt(b.plastic_J, 0)), cell(fmt(b.friction_J, 0)),
      cell(fmt(b.damped_J, 0)), cell(fmt(b.elastic_J, 0)), cell(fmt(b.efficiency, 3), "eff"),
      cell(fmt(b.final_load_N / 1000, 1)), cell(b.h_end_m === null ? "–" : fmt(1000 * b.h_end_m, 2)),
      cell(b.class, "cls " + classOf(b.class)), judgementCell(b.judgement), cell(b.alert ? b.alert.kind : "", "al"));
    return tr;
  });
  $("blows").tBodies[0].replaceChildren(...rows);
}

const rateText = (hz) => (hz === null || hz === undefined ? "–" : hz >= 1000 ? (hz / 1000).toFixed(1) + " kHz" :
  hz.toFixed(0) + " Hz");

// Each source's state as the service last reported it while it answers; "unknown" while it
// does not (a stopped service cannot say its sources are connected). The rate is the
// service's measure (samples received over the last seconds, `board.rs`).
function sourceState(s) {
  return serviceUp() ? s.state || "unknown" : "unknown";
}

function renderSources(st) {
  const up = serviceUp();
  const rows = Object.entries(st.status.sources).map(([name, s]) => {
    const state = sourceState(s);
    const tr = document.createElement("tr");
    tr.title = (up ? "" : "the service does not answer: its last report, at " + CLOCK.format(link.at) + "; ") +
      "samples lost in gaps: " + s.samples_lost + (s.detail ? "; " + s.detail : "");
    tr.append(cell(name), cell(state, state === "connected" ? "st-connected" : "st-other"),
      cell(s.samples >= 1e6 ? (s.samples / 1e6).toFixed(1) + " M" : s.samples >= 1e4 ? (s.samples / 1e3).toFixed(0) + " k" : s.samples),
      cell(up ? rateText((st.source_rate_hz || {})[name]) : "–", "rate"), cell(s.drops),
      cell(s.gaps + (s.samples_lost ? " (" + s.samples_lost + " lost)" : "")), cell(fmt(s.clock_drift_ppm, 1)));
    return tr;
  });
  $("sources").tBodies[0].replaceChildren(...rows);
}

// The header's link, from the same state as the sources table: "live" while the service
// answers and every source is connected; the sources that are not, while it answers; and
// "reconnecting…" while it does not.
function renderLink() {
  const conn = $("conn");
  const sources = link.state ? Object.entries(link.state.status.sources) : [];
  const down = sources.filter(([, s]) => sourceState(s) !== "connected");
  if (!serviceUp()) {
    conn.className = "conn down";
    conn.textContent = "reconnecting…";
    conn.title = "the service does not answer; the sources' states are unknown";
  } else if (down.length > 0) {
    conn.className = "conn warn";
    conn.textContent = down.map(([name, s]) => name + " " + sourceState(s)).join(", ");
    conn.title = "the service answers; these sources are not connected";
  } else {
    conn.className = "conn up";
    conn.textContent = "live";
    conn.title = "the service answers and every source is connected";
  }
  if (link.state) renderSources(link.state);
}

function renderHeader(status) {
  $("machine").textContent = status.machine;
  $("billet").textContent = status.billets;
  $("billet-blows").textContent = status.billet_blows;
  $("blows-total").textContent = status.blows;
  const h = status.last_blow ? status.last_blow.h_end_m : null;
  $("height").textContent = h === null || h === undefined ? "–" : fmt(1000 * h, 2) + " mm";
  renderDies(status.die_life);
}

// The die set in the hammer: its name and blows, coloured at its warning and limit
// (`[die_life]`); its hard blows and energy as the title.
function renderDies(d) {
  if (!d) return;
  const el = $("die-life");
  el.textContent = `${d.die_set === null ? "–" : d.die_set} · ${d.blows}` + (d.limit_blows ? ` / ${d.limit_blows}` : "");
  el.className = d.level === "ok" ? "" : d.level === "warning" ? "die-warning" : "die-limit";
  el.title = `${d.hard_blows} hard blows, ${fmt(d.energy_J / 1e6, 2)} MJ into the dies` +
    (d.level === "ok" ? "" : ` (${d.level} reached)`);
}

// The live advisor's plan (`[advisor]`): blows left to the target and the next blow's
// speed and energy; the whole plan as the title. Hidden without an advisor.
function renderAdvice(a) {
  $("advice-kv").hidden = !a;
  if (!a) return;
  const p = a.plan;
  let text, title;
  if (!p) {
    text = "unknown";
    title = a.why_not || "";
  } else if (!p.reachable) {
    text = "target " + fmt(1000 * p.target_m, 1) + " mm not reachable";
    title = p.why || "";
  } else if (p.blows_to_target === 0) {
    text = "at target " + fmt(1000 * p.target_m, 1) + " mm";
    title = "";
  } else {
    const next = p.plan[0];
    text = p.blows_to_target + " blow" + (p.blows_to_target === 1 ? "" : "s") + " to " + fmt(1000 * p.target_m, 1) +
      " mm; next " + fmt(next.v0_mps, 2) + " m/s (" + fmt(next.kinetic_J / 1000, 1) + " kJ)" +
      (p.hard_blows > 0 ? ", " + p.hard_blows + " hard" : "");
    title = p.plan.map((b) => "blow " + b.blow + ": " + fmt(b.v0_mps, 2) + " m/s → " + fmt(1000 * b.h_end_m, 2) +
      " mm, " + b.class).join("\n");
  }
  $("advice").textContent = text;
  $("advice").title = title;
}

function render(st) {
  renderHeader(st.status);
  renderAdvice(st.status.advice);
  renderLast(st.status.last_blow);
  renderAlert(st.status.latched_alert, st.acknowledged_alert);
  renderBars(st.billet_blows);
  renderBlows(st.recent_blows);
  renderLink();
}

// The plot: load (kN) against time from first contact (ms), phases shaded.
const PHASES = [["impact", null, "impact_end_s", "#fde2c8"], ["forming", "impact_end_s", "forming_end_s", "#dcebfa"],
  ["spring-back", "forming_end_s", "spring_back_end_s", "#e4f4dd"], ["post", "spring_back_end_s", "post_end_s", "#efe8f7"]];

function drawCurve(c) {
  const canvas = $("curve");
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  canvas.width = w * dpr;
  canvas.height = h * dpr;
  const g = canvas.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, w, h);
  if (!c) return;
  $("curve-title").textContent = "blow " + c.blow + ": load against time from first contact" +
    (c.method ? " (" + c.method.replace("_", " ") + ")" : "");
  const all = c.measured.t_s.concat(c.model.t_s);
  const loads = c.measured.load_N.concat(c.model.load_N).map((x) => x / 1000);
  if (all.length === 0) return;
  // Up to 2 ms after the post phase when the phases are known: the ring after it says little.
  const end = c.phases.post_end_s !== null && c.phases.post_end_s !== undefined ? c.phases.post_end_s + 0.002 : Infinity;
  const t0 = Math.min(...all) * 1000, t1 = Math.min(Math.max(...all), end) * 1000;
  const lmax = Math.max(...loads, 1), lmin = Math.min(...loads, 0);
  const L = 64, R = 12, T = 36, B = 34; // the phase names sit in the top margin
  const x = (ms) => L + ((ms - t0) / (t1 - t0 || 1)) * (w - L - R);
  const y = (kn) => T + (1 - (kn - lmin) / (lmax - lmin || 1)) * (h - T - B);
  g.font = "13px DejaVu Sans, Arial, sans-serif";
  for (const [name, from, to, colour] of PHASES) {
    const a = from ? c.phases[from] : 0, b = c.phases[to];
    if (a === null || a === undefined || b === null || b === undefined) continue;
    g.fillStyle = colour;
    g.fillRect(x(a * 1000), T, x(b * 1000) - x(a * 1000), h - T - B);
  }
  // Phase names above the plot, on two staggered rows so that a short phase's name does not
  // cover the next, each with a tick down to where its phase starts.
  g.fillStyle = "#3d434a";
  g.strokeStyle = "#9aa1a9";
  PHASES.forEach(([name, from, to], i) => {
    const a = from ? c.phases[from] : 0, b = c.phases[to];
    if (a === null || a === undefined || b === null || b === undefined) return;
    const row = 13 + (i % 2) * 15;
    g.fillText(name, x(a * 1000) + 3, row);
    g.beginPath(); g.moveTo(x(a * 1000) + 0.5, row - 10); g.lineTo(x(a * 1000) + 0.5, T); g.stroke();
  });
  // Axes with round ticks.
  g.strokeStyle = "#9aa1a9";
  g.fillStyle = "#1a1d21";
  g.lineWidth = 1;
  const tick = (span) => { const p = Math.pow(10, Math.floor(Math.log10(span / 5))); return [1, 2, 5, 10].map((m) => m * p).find((s) => span / s <= 7); };
  const ts = tick(t1 - t0);
  g.textAlign = "center";
  for (let t = Math.ceil(t0 / ts) * ts; t <= t1; t += ts) {
    g.beginPath(); g.moveTo(x(t), h - B); g.lineTo(x(t), h - B + 5); g.stroke();
    g.fillText(Number(t.toFixed(3)) + "", x(t), h - B + 18);
  }
  g.fillText("ms from first contact", L + (w - L - R) / 2, h - 2);
  const ls = tick(lmax - lmin);
  g.textAlign = "right";
  for (let l = Math.ceil(lmin / ls) * ls; l <= lmax; l += ls) {
    g.beginPath(); g.moveTo(L - 5, y(l)); g.lineTo(w - R, y(l)); g.strokeStyle = "#e1e4e8"; g.stroke();
    g.fillText(Number(l.toFixed(3)) + "", L - 8, y(l) + 4);
  }
  g.save();
  g.translate(14, T + (h - T - B) / 2);
  g.rotate(-Math.PI / 2);
  g.textAlign = "center";
  g.fillText("load kN", 0, 0);
  g.restore();
  const line = (s, colour, dash) => {
    if (s.t_s.length === 0) return;
    g.strokeStyle = colour;
    g.lineWidth = 2.5;
    g.setLineDash(dash);
    g.beginPath();
    s.t_s.forEach((t, i) => (i ? g.lineTo : g.moveTo).call(g, x(t * 1000), y(s.load_N[i] / 1000)));
    g.stroke();
    g.setLineDash([]);
  };
  g.save();
  g.beginPath();
  g.rect(L, 0, w - L - R, h - B);
  g.clip();
  line(c.measured, "#1f5fa8", []);
  line(c.model, "#e0601a", [8, 5]);
  g.restore();
}

let curve = null;
async function refresh() {
  try {
    const st = await getJSON("/dashboard/state");
    Object.assign(link, { answered: true, state: st, at: new Date() });
    render(st);
  } catch (e) {
    link.answered = false;
    renderLink();
  }
}
async function refreshCurve() {
  try {
    curve = await getJSON("/blow/last/curve");
    drawCurve(curve);
  } catch (e) {
    // No blow yet (404), or the service is restarting.
  }
}

function setLive(up) {
  link.stream = up;
  renderLink();
}

function connect() {
  const es = new EventSource("/events" + (token ? "?token=" + encodeURIComponent(token) : ""));
  es.onopen = () => { setLive(true); refresh(); refreshCurve(); };
  es.onerror = () => {
    setLive(false);
    // The browser retries by itself unless the server refused the stream outright.
    if (es.readyState === EventSource.CLOSED) setTimeout(connect, 3000);
  };
  for (const name of ["blow", "billet", "new_billet", "ack", "resync", "advice"]) {
    es.addEventListener(name, () => { refresh(); if (name === "blow" || name === "resync") refreshCurve(); });
  }
}

$("alert-reason").addEventListener("click", () => openReason(!$("alert-reason").classList.contains("open")));
$("alert-reason").addEventListener("keydown", (e) => {
  if (e.key === "Enter" || e.key === " ") { e.preventDefault(); openReason(!$("alert-reason").classList.contains("open")); }
  if (e.key === "Escape") openReason(false);
});
$("ack").addEventListener("click", async () => {
  $("ack").disabled = true;
  try {
    const r = await fetch("/ack", { method: "POST", headers });
    if (!r.ok) throw new Error("HTTP " + r.status);
  } catch (e) {
    $("ack").disabled = false;
    $("alert-reason").textContent = "acknowledge failed: " + e.message;
  }
});
window.addEventListener("resize", () => drawCurve(curve));
setInterval(refresh, 1000);
connect();
