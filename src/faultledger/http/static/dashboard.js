// faultledger dashboard: plain ES2020, no dependencies, served by the fault manager itself.
// Untrusted text (codes, descriptions, sources, reasons) only ever goes into textContent.
"use strict";
window.faultledgerPageId = Math.random().toString(36).slice(2);

const GROUPS = {
  "": ["PREFAILED", "CONFIRMED"], pending: ["PREFAILED"], confirmed: ["CONFIRMED"],
  cleared: ["CLEARED", "HEALED", "PREPASSED"], healed: ["HEALED", "PREPASSED"],
  all: ["PREFAILED", "CONFIRMED", "PREPASSED", "HEALED", "CLEARED"],
};
const ORDER = { CONFIRMED: 0, PREFAILED: 1, PREPASSED: 2, HEALED: 3, CLEARED: 4 };
const SEVERITIES = ["INFO", "WARN", "ERROR", "CRITICAL"];
const DETAIL_PAGE = 50;
const HISTORY_PAGE = 100;
const state = {
  token: sessionStorage.getItem("faultledger-token") || "",
  faults: new Map(), filter: "", lastEventId: null, selected: null, streaming: false,
};
const $ = (id) => document.getElementById(id);

function el(tag, text, className) {
  const node = document.createElement(tag);
  if (text !== undefined && text !== null) node.textContent = String(text);
  if (className) node.className = className;
  return node;
}
function row(cells) {
  const tr = document.createElement("tr");
  for (const cell of cells) tr.appendChild(cell instanceof Node ? cell : el("td", cell));
  return tr;
}
function cell(...children) {
  const td = el("td");
  td.append(...children);
  return td;
}
function plural(count, one, many) { return `${count} ${count === 1 ? one : many}`; }
function duration(seconds) {
  if (seconds === null || seconds === undefined) return "–";
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}
const sleep = (ms) => new Promise((done) => setTimeout(done, ms));

// -- times: always in the shift calendar's zone (the server's), never the browser's ----------
const ZONE = (() => {
  const wanted = document.body.dataset.zone || "UTC";
  try {
    new Intl.DateTimeFormat("en-GB", { timeZone: wanted });
    return wanted;
  } catch (error) {
    $("zone-note").textContent = `all times in UTC: this browser does not know the shift calendar's zone ${wanted}`;
    document.querySelectorAll(".zone").forEach((span) => { span.textContent = "UTC"; });
    return "UTC";
  }
})();
const CLOCK = new Intl.DateTimeFormat("en-GB", {
  timeZone: ZONE, year: "numeric", month: "2-digit", day: "2-digit", hour: "2-digit",
  minute: "2-digit", second: "2-digit", hourCycle: "h23", timeZoneName: "short",
});
/** "2026-11-24 14:03:05" (and " CET" with the zone's abbreviation) in the calendar's zone. */
function clock(milliseconds, withZone) {
  const p = {};
  for (const { type, value } of CLOCK.formatToParts(new Date(milliseconds))) p[type] = value;
  const text = `${p.year}-${p.month}-${p.day} ${p.hour}:${p.minute}:${p.second}`;
  return withZone ? `${text} ${p.timeZoneName}` : text;
}
function when(seconds, withZone) { return seconds ? clock(seconds * 1000, withZone) : "–"; }
function recordTime(record) { return clock(record.occurred_at_ns / 1e6); }

// -- API -------------------------------------------------------------------------------------
class AuthNeeded extends Error {}

async function api(path, options = {}) {
  const headers = Object.assign({}, options.headers || {});
  if (state.token) headers.Authorization = `Bearer ${state.token}`;
  const response = await fetch(path, Object.assign({}, options, { headers }));
  if (response.status === 401) {
    const body = await response.json().catch(() => ({}));
    askForToken(state.token ? (body.message || "the token was refused") : "");
    throw new AuthNeeded(body.message || "token needed");
  }
  return response;
}
async function apiJson(path, options) {
  const response = await api(path, options);
  const body = await response.json().catch(() => ({}));
  if (!response.ok) throw new Error(body.message || `${response.status} ${response.statusText}`);
  return body;
}
async function download(path, name) {
  const response = await api(path);
  if (!response.ok) {
    const body = await response.json().catch(() => ({}));
    throw new Error(body.message || response.statusText);
  }
  const link = el("a");
  link.href = URL.createObjectURL(await response.blob());
  link.download = name;
  document.body.appendChild(link);
  link.click();
  link.remove();
}
function showError(id, error) {
  if (!(error instanceof AuthNeeded)) $(id).textContent = error.message;
}

function askForToken(message) {
  $("token-form").hidden = false;
  $("token-message").textContent = message;
  $("token-input").focus();
}
$("token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  state.token = $("token-input").value.trim();
  sessionStorage.setItem("faultledger-token", state.token);
  $("token-form").hidden = true;
  start();
});

// -- badges ----------------------------------------------------------------------------------
function statusBadge(status) { return el("span", status, `status ${status}`); }
/** A severity label (INFO … CRITICAL, or a number 0-3 from a record) coloured by level. */
function severityBadge(severity) {
  const label = typeof severity === "number" ? (SEVERITIES[severity] || String(severity)) : String(severity);
  return el("span", label, `severity sev-${SEVERITIES.includes(label) ? label : "UNKNOWN"}`);
}

// -- faults ----------------------------------------------------------------------------------
function faultRow(fault) {
  const tr = row([
    el("td", fault.fault_code), cell(statusBadge(fault.status)), cell(severityBadge(fault.severity_label)),
    el("td", fault.description, "text wide"), fault.occurrence_count,
    when(fault.last_occurred), el("td", fault.reporting_sources.join(", "), "text wide"),
  ]);
  tr.dataset.code = fault.fault_code;
  if (fault.fault_code === state.selected) tr.classList.add("selected");
  tr.addEventListener("click", () => selectFault(fault.fault_code));
  return tr;
}

function renderFaults(changed) {
  const wanted = GROUPS[state.filter];
  const shown = [...state.faults.values()].filter((f) => wanted.includes(f.status))
    .sort((a, b) => (ORDER[a.status] - ORDER[b.status]) || (b.last_occurred - a.last_occurred));
  const body = $("fault-table").tBodies[0];
  body.replaceChildren(...shown.map(faultRow));
  $("no-faults").hidden = shown.length > 0;
  $("fault-count").textContent = `${shown.length} shown of ${plural(state.faults.size, "fault", "faults")}`;
  if (changed) {
    const tr = body.querySelector(`tr[data-code="${CSS.escape(changed)}"]`);
    if (tr) tr.classList.add("flash");
  }
}

async function loadFaults() {
  const response = await api("/api/v1/faults?status=all");
  const body = await response.json();
  state.faults = new Map(body.items.map((f) => [f.fault_code, f]));
  // The list's ETag is "<seq>-<group>": the stream resumes right after it, so no change
  // between the list and the stream is missed.
  const tag = (response.headers.get("ETag") || "").replace(/"/g, "");
  if (state.lastEventId === null && /^\d+-/.test(tag)) state.lastEventId = Number(tag.split("-")[0]);
  renderFaults();
}

function setConnection(live) {
  const badge = $("connection");
  badge.className = `connection ${live ? "live" : "off"}`;
  badge.textContent = live ? "live" : "reconnecting…";
}

function handleBlock(block) {
  let id = null, data = "";
  for (const line of block.split("\n")) {
    if (line.startsWith("id:")) id = Number(line.slice(3).trim());
    else if (line.startsWith("data:")) data += line.slice(5).trim();
  }
  if (id !== null) state.lastEventId = id;
  if (!data) return;
  const event = JSON.parse(data);
  state.faults.set(event.fault.fault_code, event.fault);
  renderFaults(event.fault.fault_code);
  if (state.selected === event.fault.fault_code) refreshDetail();
}

async function stream() {
  if (state.streaming) return;
  state.streaming = true;
  let backoff = 500;
  for (;;) {
    try {
      const headers = state.lastEventId === null ? {} : { "Last-Event-ID": String(state.lastEventId) };
      const response = await api("/api/v1/faults/stream", { headers });
      if (!response.ok) throw new Error(`stream answered ${response.status}`);
      setConnection(true);
      backoff = 500;
      const reader = response.body.getReader();
      const decoder = new TextDecoder();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += decoder.decode(value, { stream: true });
        let cut;
        while ((cut = buffer.indexOf("\n\n")) >= 0) {
          handleBlock(buffer.slice(0, cut));
          buffer = buffer.slice(cut + 2);
        }
      }
    } catch (error) {
      if (error instanceof AuthNeeded) { state.streaming = false; setConnection(false); return; }
    }
    setConnection(false);
    await sleep(backoff);
    backoff = Math.min(backoff * 2, 10000);
  }
}

// -- fault detail: fields, and its history newest first, paged backwards ------------------------
// Loads run one after another (a chain), so a live update and "older" never interleave; a
// load for a fault no longer selected is dropped.
const detail = { code: null, records: [], total: null, before: null, chain: Promise.resolve(),
  refreshing: false };

function queueDetail(task) {
  const code = detail.code;
  detail.chain = detail.chain.then(() => (detail.code === code ? task(code) : undefined))
    .catch((error) => showError("detail-history-message", error));
  return detail.chain;
}

function selectFault(code) {
  state.selected = code;
  document.querySelectorAll("#fault-table tr.selected").forEach((tr) => tr.classList.remove("selected"));
  const tr = document.querySelector(`#fault-table tr[data-code="${CSS.escape(code)}"]`);
  if (tr) tr.classList.add("selected");
  $("detail").hidden = false;
  $("view-faults").classList.add("detail-open");
  $("detail-code").textContent = code;
  $("detail-description").textContent = "";
  $("detail-fields").replaceChildren();
  $("clear-message").textContent = "";
  Object.assign(detail, { code, records: [], total: null, before: null, refreshing: false });
  renderDetailHistory();
  queueDetail(loadDetailFields);
  return queueDetail((c) => loadDetailHistory(c, "newest"));
}

function refreshDetail() {
  if (detail.refreshing) return;  // one queued refresh covers a burst of updates
  detail.refreshing = true;
  queueDetail(async (code) => {
    detail.refreshing = false;
    await loadDetailFields(code);
    await loadDetailHistory(code, "newer");
  });
}

async function loadDetailFields(code) {
  try {
    const answer = await apiJson(`/api/v1/faults/${encodeURIComponent(code)}`);
    if (detail.code !== code) return;
    const x = answer["x-medkit"];
    $("detail-description").textContent = answer.item.fault_name || "";
    const fields = $("detail-fields");
    fields.replaceChildren();
    const status = answer.item.status;
    const add = (name, value) => {
      fields.appendChild(el("dt", name));
      const dd = el("dd");
      dd.append(value);
      fields.appendChild(dd);
    };
    add("status", `${x.status_raw} (${status.aggregatedStatus}; testFailed ${status.testFailed}, confirmedDTC ${status.confirmedDTC}, pendingDTC ${status.pendingDTC})`);
    add("severity", severityBadge(x.severity_label));
    add("occurrences", String(x.occurrence_count));
    add("first occurred", when(x.first_occurred, true));
    add("last occurred", when(x.last_occurred, true));
    add("last passed", when(x.last_passed, true));
    add("sources", (x.reporting_sources || []).join(", ") || "–");
    $("clear-form").hidden = document.body.dataset.readOnly === "true" || x.status_raw === "CLEARED";
  } catch (error) {
    if (detail.code === code) showError("detail-description", error);
  }
}

/** "newest": the newest page; "older": the page before the oldest shown; "newer": the
 * records written since the newest shown (a live update), added on top. */
async function loadDetailHistory(code, which) {
  $("detail-history-message").textContent = "";
  const params = new URLSearchParams({ code, total: "true" });
  if (which === "newer" && detail.records.length) {
    params.set("after_seq", String(detail.records[0].seq));
    params.set("limit", "1000");
    const page = await apiJson(`/api/v1/history?${params}`);
    if (detail.code !== code) return;
    if (page.next_after_seq !== null) return loadDetailHistory(code, "newest");  // a flood: start over
    detail.records.unshift(...page.items.reverse());
    detail.total = page.total;
    renderDetailHistory(page.items.length);
    return;
  }
  params.set("order", "desc");
  params.set("limit", String(DETAIL_PAGE));
  if (which === "older") params.set("before_seq", String(detail.before));
  const page = await apiJson(`/api/v1/history?${params}`);
  if (detail.code !== code) return;
  if (which === "older") detail.records.push(...page.items); else detail.records = page.items;
  detail.before = page.next_before_seq;
  detail.total = page.total;
  renderDetailHistory();
}

function recordText(r) {
  const p = r.payload;
  if (r.kind === "fault_reported") return [`${p.event_type} `, severityBadge(p.severity)];
  if (r.kind === "fault_cleared") return [`cleared${p.reason ? ": " + p.reason : ""}`];
  if (r.kind === "fault_confirmed_by_timer") return ["confirmed by the timer"];
  if (r.kind === "reclassified_on_startup") return ["reclassified on startup"];
  return [r.kind];
}

function renderDetailHistory(added = 0) {
  const body = $("detail-history").tBodies[0];
  body.replaceChildren(...detail.records.map((r, i) => {
    const tr = row([r.seq, recordTime(r), cell(...recordText(r)),
      el("td", (r.payload && r.payload.actor) || r.source_id || "", "text")]);
    tr.dataset.seq = String(r.seq);
    if (i < added) tr.classList.add("flash");
    return tr;
  }));
  $("detail-count").textContent = countText(detail.records.length, detail.total);
  $("detail-older").hidden = detail.before === null || detail.before === undefined;
}

/** "50 newest of 300 records", or "all 3 records". */
function countText(shown, total) {
  if (total === null || total === undefined) return shown ? plural(shown, "record", "records") : "";
  if (shown >= total) return total === 0 ? "no records" : total === 1 ? "1 record" : `all ${total} records`;
  return `${shown} newest of ${total} records`;
}

$("detail-older").addEventListener("click", () => {
  $("detail-older").disabled = true;
  queueDetail((code) => loadDetailHistory(code, "older"))
    .finally(() => { $("detail-older").disabled = false; });
});
$("detail-close").addEventListener("click", () => {
  $("detail").hidden = true;
  $("view-faults").classList.remove("detail-open");
  state.selected = null;
  detail.code = null;
  renderFaults();
});
$("status-filter").addEventListener("change", (event) => { state.filter = event.target.value; renderFaults(); });
$("clear-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const message = $("clear-message");
  message.textContent = "";
  const reason = $("clear-reason").value;
  try {
    const response = await api(`/api/v1/faults/${encodeURIComponent(state.selected)}?reason=${encodeURIComponent(reason)}`, { method: "DELETE" });
    if (response.status !== 204) {
      const body = await response.json().catch(() => ({}));
      message.textContent = body.message || `${response.status} ${response.statusText}`;
    } else {
      $("clear-reason").value = "";
    }
  } catch (error) {
    showError("clear-message", error);
  }
});

// -- statistics: the server's end-of-shift report (JSON) and its stats rows --------------------
const SVG = "http://www.w3.org/2000/svg";
const WEEKDAYS = ["Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"];

function svg(tag, attributes, text) {
  const node = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attributes)) node.setAttribute(name, String(value));
  if (text !== undefined) node.textContent = String(text);
  return node;
}
/** Width of a text at the charts' 11 px font, measured once per text. */
const measured = new Map();
let measuring = null;
function textWidth(text) {
  if (!measured.has(text)) {
    if (measuring === null) {
      measuring = document.createElement("canvas").getContext("2d");
      measuring.font = `11px ${getComputedStyle(document.body).fontFamily}`;
    }
    measured.set(text, measuring.measureText(text).width);
  }
  return measured.get(text);
}
/** Date arithmetic on a production day "YYYY-MM-DD" (a calendar date, no zone involved). */
function addDays(day, days) {
  const [y, m, d] = day.split("-").map(Number);
  return new Date(Date.UTC(y, m - 1, d + days)).toISOString().slice(0, 10);
}
function weekday(day) { return WEEKDAYS[new Date(`${day}T00:00:00Z`).getUTCDay()]; }

// Charts are drawn at the container's real width (no stretched text) and again when it
// changes; a label is drawn only where it fits, so none overlap.
const charts = new Map();
const resized = new ResizeObserver((entries) => { for (const entry of entries) drawChart(entry.target); });

function bars(container, spec) {
  charts.set(container, spec);
  resized.observe(container);
  drawChart(container);
}

function drawChart(container) {
  const spec = charts.get(container);
  const width = Math.floor(container.clientWidth);
  if (!spec || width < 50) return;  // hidden: drawn when shown
  const { rows, key, colour, one, many, highlight } = spec;
  const height = 176, top = 22, base = 134, left = 24;
  const chart = svg("svg", { viewBox: `0 0 ${width} ${height}`, width, height, role: "img" });
  const peak = Math.max(1, ...rows.map((r) => r[key] || 0));
  const slot = (width - left - 4) / Math.max(rows.length, 1);
  const scale = (base - top) / peak;
  chart.append(svg("line", { x1: left, x2: width, y1: base, y2: base, stroke: "#9aa1ad" }),
    svg("line", { x1: left, x2: width, y1: base - peak * scale, y2: base - peak * scale, stroke: "#e3e6ec" }),
    svg("text", { x: left - 4, y: base - peak * scale + 4, "text-anchor": "end", class: "axis" }, peak),
    svg("text", { x: left - 4, y: base + 4, "text-anchor": "end", class: "axis" }, 0));
  rows.forEach((r, i) => {
    const value = r[key] || 0;
    const x = left + i * slot;
    const bar = svg("rect", {
      x: x + 1, y: base - value * scale, width: Math.max(slot - 2, 1), height: value * scale,
      fill: colour, class: r.period === highlight ? "bar chosen" : "bar",
    });
    bar.appendChild(svg("title", {}, `${r.period}: ${plural(value, one, many)}`));
    chart.appendChild(bar);
    const valueText = String(value);
    if (value && textWidth(valueText) + 2 <= slot) {
      chart.appendChild(svg("text", { x: x + slot / 2, y: base - value * scale - 3, "text-anchor": "middle", class: "value" }, valueText));
    }
    const initial = String(r.period_name || "").slice(0, 1).toUpperCase();
    if (initial && textWidth("W") + 4 <= slot) {
      chart.appendChild(svg("text", { x: x + slot / 2, y: base + 13, "text-anchor": "middle", class: "shift" }, initial));
    }
  });
  // One label per production day, centred under its shifts: the longest form that fits.
  let first = 0;
  for (let i = 1; i <= rows.length; i += 1) {
    if (i < rows.length && rows[i].production_day === rows[first].production_day) continue;
    const day = rows[first].production_day || String(rows[first].period).split("/")[0];
    const x0 = left + first * slot, span = (i - first) * slot;
    if (first > 0) chart.appendChild(svg("line", { x1: x0, x2: x0, y1: top, y2: height - 2, stroke: "#e3e6ec" }));
    const label = [`${weekday(day)} ${day.slice(5)}`, day.slice(5), day.slice(8)].find((t) => textWidth(t) + 4 <= span);
    if (label) chart.appendChild(svg("text", { x: x0 + span / 2, y: base + 30, "text-anchor": "middle", class: "day" }, label));
    first = i;
  }
  container.replaceChildren(chart);
}

const GOOD_WHEN_HIGHER = new Set(["mtbf_seconds"]);
const NEUTRAL = new Set(["heals", "clears"]);

function valueText(kind, value) {
  if (value === null || value === undefined) return "–";
  if (kind === "duration") return duration(value);
  if (kind === "percent") return `${Number(value).toFixed(1)} %`;
  return String(Math.round(value));
}

/** "e-stops" → "e-stop", "activations (all faults)" → "activation (all faults)". */
function singular(label) {
  const cut = label.indexOf(" (");
  const noun = cut < 0 ? label : label.slice(0, cut);
  return noun.endsWith("s") ? noun.slice(0, -1) + label.slice(noun.length) : label;
}

/** One figure of the report: the value, its label (singular for a count of 1), the previous
 * shift's value named by its id, and the report's own difference texts. */
function figureBox(figure, previousShift) {
  const box = el("div", null, "figure");
  box.dataset.key = figure.key;
  box.appendChild(el("div", figure.value_text || valueText(figure.kind, figure.value), "value"));
  box.appendChild(el("div", figure.kind === "count" && figure.value === 1 ? singular(figure.label) : figure.label, "label"));
  if (!previousShift) {
    box.appendChild(el("div", "no previous shift", "change"));
    return box;
  }
  const known = (v) => v !== null && v !== undefined;
  const change = known(figure.value) && known(figure.previous) ? figure.value - figure.previous : null;
  const line = el("div", "vs ", "previous");
  line.append(el("span", previousShift.id, "nowrap"),
    `: ${figure.previous_text || valueText(figure.kind, figure.previous)}`);
  box.appendChild(line);
  if (change !== null) {
    let tone = "";
    if (change && !NEUTRAL.has(figure.key)) tone = (change > 0) !== GOOD_WHEN_HIGHER.has(figure.key) ? "worse" : "better";
    const percent = figure.percent_text && figure.percent_text !== "-" ? ` (${figure.percent_text})` : "";
    const text = change === 0 ? "= no change" : `${change > 0 ? "▲" : "▼"} ${figure.change_text}${percent}`;
    box.appendChild(el("div", text, `change ${tone}`));
  }
  return box;
}

// Each load has a number; the answers of a load that a later one superseded (the tab opened,
// then a shift was asked for) are dropped, so the page shows what was asked last.
let statsLoad = 0;

async function loadStats() {
  const load = ++statsLoad;
  delete $("view-stats").dataset.shown;  // set again once this load has drawn everything
  $("stats-message").textContent = "";
  try {
    const params = new URLSearchParams({ format: "json" });
    const wanted = $("stats-shift").value.trim();
    if (wanted) params.set("shift", wanted);
    const report = await apiJson(`/api/v1/shift-report?${params}`);
    if (load !== statsLoad) return;
    const shift = report.shift;
    $("stats-title").textContent = `Shift ${shift.id}${report.in_progress ? " (in progress)" : ""}`;
    $("stats-span").textContent = report.in_progress
      ? `${shift.span_text} · counted up to ${clock(Date.parse(report.as_of), true)}` : shift.span_text;
    $("stats-headline").textContent = report.headline || "";
    $("stats-notes").replaceChildren(...(report.notes || []).map((note) => el("li", note)));
    $("figures").replaceChildren(...report.figures.map((f) => figureBox(f, report.previous)));
    const globs = (report.estop_codes && report.estop_codes.length) ? report.estop_codes
      : JSON.parse(document.body.dataset.estopCodes || "[]");
    $("estop-hint").textContent = `E-stops are activations of the codes matching ${globs.join(", ")} (the configuration's estop_codes).`;
    const offenders = report.offenders || [];
    $("offenders").tBodies[0].replaceChildren(...offenders.map((o) => row([
      el("td", o.code, "text"), o.estops, o.activations, o.confirmations, o.failed_reports, duration(o.active_seconds)])));
    $("no-offenders").hidden = offenders.length > 0;
    // The 7 × 24 h up to the shift's end, in the calendar's wall-clock time (a local
    // date-time in the time grammar): 21 whole shifts of a three-shift calendar.
    const end = clock(Date.parse(shift.end));
    const since = `${addDays(end.slice(0, 10), -7)}T${end.slice(11)}`;
    const stats = await apiJson(`/api/v1/stats?by=shift&since=${encodeURIComponent(since)}&until=${encodeURIComponent(shift.id)}`);
    if (load !== statsLoad) return;
    const rows = stats.items;
    bars($("chart-estops"), { rows, key: "estops", colour: "#c62828", one: "e-stop", many: "e-stops", highlight: shift.id });
    bars($("chart-aborted"), { rows, key: "aborted_goals", colour: "#1f5fbf", one: "aborted goal", many: "aborted goals", highlight: shift.id });
    $("shift-report-link").onclick = (event) => {
      event.preventDefault();
      download(`/api/v1/shift-report?shift=${encodeURIComponent(shift.id)}`, `shift-report-${shift.id.replace("/", "-")}.html`)
        .catch((error) => showError("stats-message", error));
    };
    $("view-stats").dataset.shown = shift.id;
  } catch (error) {
    if (load === statsLoad) showError("stats-message", error);
  }
}
$("stats-form").addEventListener("submit", (event) => { event.preventDefault(); loadStats(); });

// -- history: newest first, paged backwards ----------------------------------------------------
const historyView = { params: "", before: null, shown: 0, total: null, load: 0 };

function historyParams() {
  const params = new URLSearchParams();
  for (const [name, id] of [["code", "history-code"], ["since", "history-since"], ["until", "history-until"]]) {
    const value = $(id).value.trim();
    if (value) params.set(name, value);
  }
  return params;
}

async function loadHistory(older) {
  const load = older ? historyView.load : ++historyView.load;  // a new search supersedes
  $("history-message").textContent = "";
  const params = older ? new URLSearchParams(historyView.params) : historyParams();
  if (!older) historyView.params = params.toString();
  params.set("order", "desc");
  params.set("limit", String(HISTORY_PAGE));
  params.set("total", "true");
  if (older) params.set("before_seq", String(historyView.before));
  try {
    const page = await apiJson(`/api/v1/history?${params}`);
    if (load !== historyView.load) return;
    const rows = page.items.map((r) => {
      const p = r.payload;
      const details = r.kind === "fault_reported" ? `${p.event_type} ${p.description || ""}`
        : r.kind === "fault_cleared" ? `by ${p.actor}${p.reason ? ": " + p.reason : ""}`
        : r.kind === "goal_outcome" ? `${p.action} ${p.status}`
        : r.kind === "ledger_identified" ? `robot ${p.robot_id}, ledger ${p.ledger_id}` : "";
      const severity = r.kind === "fault_reported" ? cell(severityBadge(p.severity)) : el("td");
      const tr = row([r.seq, recordTime(r), r.kind, r.fault_code || "", severity,
        el("td", r.source_id || "", "text wide"), el("td", details, "text")]);
      tr.dataset.seq = String(r.seq);
      return tr;
    });
    const body = $("history-table").tBodies[0];
    if (older) body.append(...rows); else body.replaceChildren(...rows);
    historyView.shown = (older ? historyView.shown : 0) + rows.length;
    historyView.before = page.next_before_seq;
    historyView.total = page.total;
    $("history-count").textContent = countText(historyView.shown, historyView.total);
    $("history-older").hidden = page.next_before_seq === null;
  } catch (error) {
    if (load === historyView.load) showError("history-message", error);
  }
}
$("history-form").addEventListener("submit", (event) => { event.preventDefault(); loadHistory(false); });
$("history-older").addEventListener("click", () => loadHistory(true));
for (const [id, format] of [["export-csv", "csv"], ["export-jsonl", "jsonl"]]) {
  $(id).addEventListener("click", () => {
    const params = historyParams();
    params.set("format", format);
    download(`/api/v1/history?${params}`, `history.${format}`)
      .catch((error) => showError("history-message", error));
  });
}

// -- views -----------------------------------------------------------------------------------
const loaded = new Set();
function showView(name) {
  document.querySelectorAll(".tab").forEach((tab) => tab.classList.toggle("active", tab.dataset.view === name));
  document.querySelectorAll(".view").forEach((view) => { view.hidden = view.id !== `view-${name}`; });
  if (name === "stats" && !loaded.has(name)) loadStats();
  // The History tab opens at the newest record of the last search, every time it is shown.
  if (name === "history") loadHistory(false);
  loaded.add(name);
}
document.querySelectorAll(".tab").forEach((tab) => tab.addEventListener("click", () => showView(tab.dataset.view)));

async function start() {
  try {
    await loadFaults();
    stream();
  } catch (error) {
    if (!(error instanceof AuthNeeded)) { setConnection(false); $("fault-count").textContent = error.message; }
  }
}
start();
