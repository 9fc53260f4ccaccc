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
  robot: "", robotFaults: new Map(), view: "faults", started: false, shelvedOnly: false,
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
// A robot's faults (the robot filter of a fleet central) carry robot_id and ledger_id: a
// robot whose database was replaced has the same code in two logs, so they are keyed by both.
function faultKey(fault) { return fault.ledger_id ? `${fault.ledger_id}/${fault.fault_code}` : fault.fault_code; }

function faultRow(fault) {
  const key = faultKey(fault);
  const code = el("td", fault.fault_code);
  if (fault.ledger_id && logsOf(fault.robot_id).length > 1) code.appendChild(el("span", `log ${fault.ledger_id.slice(0, 8)}…`, "ledger"));
  const ack = fault.acknowledged
    ? el("td", `✓ ${fault.acknowledged.by} ${when(fault.acknowledged.at).slice(11, 16)}`, "text acked")
    : cell(fault.status === "CLEARED" ? "–" : el("span", "new", "unacked"));
  const tr = row([
    code, cell(statusBadge(fault.status)), cell(severityBadge(fault.severity_label)), ack,
    el("td", fault.description, "text wide"), fault.occurrence_count,
    when(fault.last_occurred), el("td", fault.reporting_sources.join(", "), "text wide"),
  ]);
  tr.dataset.code = fault.fault_code;
  tr.dataset.key = key;
  if (key === state.selected) tr.classList.add("selected");
  tr.addEventListener("click", () => (state.robot ? selectRobotFault(key) : selectFault(fault.fault_code)));
  return tr;
}

/** Shelved and not yet expired (an expired shelving no longer hides, before its record). */
function isShelved(fault) { return Boolean(fault.shelved) && fault.shelved.until * 1000 > Date.now(); }

function renderFaults(changed) {
  const wanted = GROUPS[state.filter];
  const all = state.robot ? state.robotFaults : state.faults;
  // The operator's view: shelved faults hidden (or only them), unacknowledged ones first.
  const shown = [...all.values()].filter((f) => wanted.includes(f.status) && isShelved(f) === state.shelvedOnly)
    .sort((a, b) => (Boolean(a.acknowledged) - Boolean(b.acknowledged))
      || (ORDER[a.status] - ORDER[b.status]) || (b.last_occurred - a.last_occurred));
  const body = $("fault-table").tBodies[0];
  body.replaceChildren(...shown.map(faultRow));
  $("no-faults").hidden = shown.length > 0;
  $("fault-count").textContent = `${shown.length} shown of ${plural(all.size, "fault", "faults")}${state.robot ? ` of ${state.robot}` : ""}`;
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
  if (state.robot) return;  // the stream is this server's own log, not the robot's shown
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

function markSelected(key) {
  document.querySelectorAll("#fault-table tbody tr").forEach((tr) => tr.classList.toggle("selected", tr.dataset.key === key));
}

function selectFault(code) {
  state.selected = code;
  markSelected(code);
  $("detail").hidden = false;
  $("view-faults").classList.add("detail-open");
  $("detail-history-part").hidden = false;
  $("detail-robot-note").hidden = true;
  $("detail-code").textContent = code;
  $("detail-description").textContent = "";
  $("detail-fields").replaceChildren();
  $("clear-message").textContent = "";
  $("operator-message").textContent = "";
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
    add("episode", `${x.episode}, since ${when(x.episode_started, true)}`);
    add("first occurred ever", when(x.first_occurred_ever, true));
    add("occurrences", `${x.occurrences_in_episode} in this episode, ${x.occurrences_total} in total (FAILED reports)`);
    add("last occurred", when(x.last_occurred, true));
    add("last passed", when(x.last_passed, true));
    add("sources", (x.reporting_sources || []).join(", ") || "–");
    const ack = x.acknowledged;
    add("acknowledged", ack ? `${when(ack.at, true)} by ${ack.by}${ack.note ? `: ${ack.note}` : ""}` : "not yet");
    const shelf = x.shelved && x.shelved.until * 1000 > Date.now() ? x.shelved : null;
    if (shelf) add("shelved", `by ${shelf.by} until ${when(shelf.until, true)}${shelf.reason ? `: ${shelf.reason}` : ""}`);
    const readOnly = document.body.dataset.readOnly === "true";
    $("clear-form").hidden = readOnly || x.status_raw === "CLEARED";
    $("ack-form").hidden = readOnly || Boolean(ack) || x.status_raw === "CLEARED";
    $("shelve-form").hidden = readOnly || Boolean(shelf);
    $("unshelve-form").hidden = readOnly || !shelf;
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
function closeDetail() {
  $("detail").hidden = true;
  $("view-faults").classList.remove("detail-open");
  state.selected = null;
  detail.code = null;
}
$("detail-close").addEventListener("click", () => { closeDetail(); renderFaults(); });
$("status-filter").addEventListener("change", (event) => { state.filter = event.target.value; renderFaults(); });
$("shelved-filter").addEventListener("change", (event) => { state.shelvedOnly = event.target.checked; renderFaults(); });

/** POST an operator action for the selected fault; the stream brings the change back. */
async function operate(action, body, done) {
  const message = $("operator-message");
  message.textContent = "";
  try {
    await apiJson(`/api/v1/faults/${encodeURIComponent(state.selected)}/${action}`, {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
    });
    if (done) done();
    refreshDetail();
  } catch (error) {
    showError("operator-message", error);
  }
}
$("ack-form").addEventListener("submit", (event) => {
  event.preventDefault();
  operate("ack", { note: $("ack-note").value }, () => { $("ack-note").value = ""; });
});
$("shelve-form").addEventListener("submit", (event) => {
  event.preventDefault();
  operate("shelve", { for: $("shelve-for").value, reason: $("shelve-reason").value },
    () => { $("shelve-reason").value = ""; });
});
$("unshelve-form").addEventListener("submit", (event) => {
  event.preventDefault();
  operate("unshelve", {});
});
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

// -- a fleet central: robots' faults, and the Fleet view -----------------------------------------
// Shown only when this server holds robot logs (GET /api/v1/fleet/robots lists them). A
// robot's log changes only when it pushes, and the central's event stream is its own log's,
// so the robot's faults and the Fleet view are read again every few seconds while shown.
const LIVE_LAG_SEC = 30;
/** A robot more than this behind (or with records the central lacks) is "behind": its
 * current shift's figures are marked provisional too. Syncing with --follow, a robot makes
 * contact every 5 s. */
const TICK_MS = 5000;
const fleet = { chains: [], load: 0, since: null, confirmed: new Map(), robotLoad: 0 };

function logsOf(robot) { return fleet.chains.filter((c) => c.robot_id === robot); }

async function loadRobots() {
  const body = await apiJson("/api/v1/fleet/robots");
  fleet.chains = body.items;
  const names = [...new Set(body.items.map((c) => c.robot_id))].sort();
  const select = $("robot-filter");
  const listed = [...select.options].slice(1).map((option) => option.value);
  if (names.join("\n") !== listed.join("\n")) {
    const own = el("option", "this server's own log");
    own.value = "";
    select.replaceChildren(own, ...names.map((name) => {
      const option = el("option", name);
      option.value = name;
      return option;
    }));
    select.value = state.robot;
  }
  $("robot-filter-label").hidden = names.length === 0;
  $("fleet-tab").hidden = names.length === 0;
  return body.items;
}

function syncText(chain) {
  const behind = chain.lag_seconds >= LIVE_LAG_SEC || chain.lag_records > 0;
  return { behind, text: behind ? `${duration(chain.lag_seconds)} behind` : `${Math.round(chain.lag_seconds)} s` };
}

function robotNote(robot) {
  const logs = logsOf(robot);
  const parts = logs.map((c) => {
    const sync = syncText(c);
    return `${sync.behind ? sync.text : "in sync"}, last contact ${clock(Date.parse(c.last_pushed_at), true)}`;
  });
  const held = logs.length > 1 ? `its ${logs.length} logs (its database was replaced)` : "its log";
  return `${robot}'s faults as this central holds ${held}: ${parts.join("; ")}. Read again every 5 s; clear a fault on the robot.`;
}

async function loadRobotFaults() {
  const robot = state.robot;
  if (!robot) return;
  const load = ++fleet.robotLoad;
  const note = $("robot-note");
  try {
    const body = await apiJson(`/api/v1/faults?robot=${encodeURIComponent(robot)}&status=all`);
    if (load !== fleet.robotLoad || state.robot !== robot) return;
    state.robotFaults = new Map(body.items.map((f) => [faultKey(f), f]));
    note.className = "muted";
    note.textContent = robotNote(robot);
    renderFaults();
    const chosen = state.robotFaults.get(state.selected);
    if (chosen) showRobotFault(chosen);
    $("view-faults").dataset.robot = robot;
  } catch (error) {
    if (load !== fleet.robotLoad || error instanceof AuthNeeded) return;
    note.className = "error";
    note.textContent = error.message;
  }
}

function chooseRobot(robot) {
  state.robot = robot;
  $("robot-filter").value = robot;
  closeDetail();
  state.robotFaults = new Map();
  delete $("view-faults").dataset.robot;
  $("robot-note").hidden = !robot;
  $("robot-note").className = "muted";
  $("robot-note").textContent = robot ? `reading ${robot}'s faults…` : "";
  renderFaults();
  loadRobotFaults();
}
$("robot-filter").addEventListener("change", (event) => chooseRobot(event.target.value));

function selectRobotFault(key) {
  const fault = state.robotFaults.get(key);
  if (!fault) return;
  state.selected = key;
  detail.code = null;  // no history loads: those read this server's own log
  markSelected(key);
  showRobotFault(fault);
}

/** The detail of a robot's fault from its list item: the central cannot change a robot's log. */
function showRobotFault(fault) {
  $("detail").hidden = false;
  $("view-faults").classList.add("detail-open");
  $("detail-code").textContent = fault.fault_code;
  $("detail-description").textContent = fault.description || "";
  const fields = $("detail-fields");
  fields.replaceChildren();
  const add = (name, value) => {
    fields.appendChild(el("dt", name));
    const dd = el("dd");
    dd.append(value);
    fields.appendChild(dd);
  };
  add("robot", fault.robot_id);
  add("log", fault.ledger_id);
  add("status", statusBadge(fault.status));
  add("severity", severityBadge(fault.severity_label));
  add("occurrences", String(fault.occurrence_count));
  add("first occurred", when(fault.first_occurred, true));
  add("last occurred", when(fault.last_occurred, true));
  add("last passed", when(fault.last_passed, true));
  add("sources", fault.reporting_sources.join(", ") || "–");
  $("clear-form").hidden = true;
  for (const id of ["ack-form", "shelve-form", "unshelve-form"]) $(id).hidden = true;
  $("clear-message").textContent = "";
  $("detail-history-part").hidden = true;
  $("detail-robot-note").hidden = false;
  $("detail-robot-note").textContent = `A fault in ${fault.robot_id}'s log as this central holds it: clear it on the robot.`;
}

/** Runs ``work`` on every item, at most ``width`` at a time (the browser's connections are few). */
async function inTurns(items, width, work) {
  let next = 0;
  const worker = async () => {
    while (next < items.length) await work(items[next++]);
  };
  await Promise.all(Array.from({ length: Math.min(width, items.length) }, worker));
}

/** Confirmed faults per log, asked again only for a robot whose logs changed since (a fault
 * changes only with a record, and a record moves the log's last_seq). */
async function confirmedCounts(chains) {
  const seqs = new Map();
  for (const c of chains) seqs.set(c.robot_id, `${seqs.get(c.robot_id) || ""}${c.ledger_id}:${c.last_seq};`);
  const stale = [...seqs].filter(([robot, held]) => (fleet.confirmed.get(robot) || {}).held !== held);
  await inTurns(stale, 4, async ([robot, held]) => {
    const body = await apiJson(`/api/v1/faults?robot=${encodeURIComponent(robot)}&status=confirmed`);
    const counts = new Map();
    for (const f of body.items) counts.set(f.ledger_id, (counts.get(f.ledger_id) || 0) + 1);
    fleet.confirmed.set(robot, { held, counts });
  });
  return fleet.confirmed;
}

/** The current shift (the last one, when it ends at as_of: counted up to now) and the one
 * before it, among the rows' shifts; gaps between shifts are left out. */
function shiftsOf(rows, asOf) {
  const periods = new Map();
  for (const r of rows) if (r.period !== "unscheduled" && !periods.has(r.period)) periods.set(r.period, r);
  const ordered = [...periods.values()].sort((a, b) => Date.parse(a.start) - Date.parse(b.start));
  const last = ordered[ordered.length - 1];
  const running = Boolean(last) && Math.abs(Date.parse(last.end) - Date.parse(asOf)) < 1000;
  const previous = running ? ordered[ordered.length - 2] : last;
  return { current: running ? last.period : null, previous: previous ? previous.period : null };
}

function shiftLabel(id, now) {
  if (!id) return now ? "no shift now" : "–";
  const [day, name] = id.split("/");
  return now ? `${name}, now` : `${name} ${day.slice(5)}`;
}

async function loadFleet() {
  const load = ++fleet.load;
  try {
    const chains = await loadRobots();
    // From the previous shift found last time (its start), at first from 4 days back: far
    // enough for the shift before the current one across a weekend without shifts.
    const params = new URLSearchParams({ by: "shift", since: fleet.since || new Date(Date.now() - 4 * 86400e3).toISOString() });
    for (const key of ["robot", "line", "site"]) params.append("group_by", key);
    const stats = await apiJson(`/api/v1/stats?${params}`);
    if (load !== fleet.load) return;
    const confirmed = await confirmedCounts(chains);
    if (load !== fleet.load) return;
    renderFleet(chains, stats, confirmed);
    $("fleet-message").textContent = "";
    $("view-fleet").dataset.shown = stats.as_of;
  } catch (error) {
    fleet.since = null;
    if (load === fleet.load) showError("fleet-message", error);
  }
}

function renderFleet(chains, stats, confirmed) {
  const { current, previous } = shiftsOf(stats.items, stats.as_of);
  fleet.since = previous;
  const figures = new Map();
  for (const r of stats.items) figures.set(`${r.robot}|${r.ledger_id || ""}|${r.period}`, r);
  let provisional = false;
  const rows = chains.map((c) => {
    const ledger = logsOf(c.robot_id).length > 1 ? c.ledger_id : "";
    const at = (period) => (period ? figures.get(`${c.robot_id}|${ledger}|${period}`) : undefined);
    const now = at(current), before = at(previous);
    const sync = syncText(c);
    const figure = (r, key, running) => {
      if (!r) return el("td", "–", "num fig");
      // complete: false is the central's word for "the robot has not pushed past this
      // period's end"; the current shift ends now, so there it counts once the robot is behind.
      const unsure = r.complete === false && (!running || sync.behind);
      const td = el("td", r[key], unsure ? "num fig provisional" : "num fig");
      if (unsure) {
        td.appendChild(el("span", "*", "mark"));
        td.title = "still syncing: figures may grow";
        provisional = true;
      }
      return td;
    };
    const name = el("td", c.robot_id, "robot");
    if (ledger) name.appendChild(el("span", `log ${c.ledger_id.slice(0, 8)}…`, "ledger"));
    const labels = now || before || {};
    const count = (confirmed.get(c.robot_id) || { counts: new Map() }).counts.get(c.ledger_id) || 0;
    const syncCell = el("td", sync.text, sync.behind ? "sync behind" : "sync ok");
    if (c.lag_records) syncCell.title = `${plural(c.lag_records, "record", "records")} not at the central at the last contact`;
    const tr = row([name, el("td", labels.line || "", "labels"), el("td", labels.site || "", "labels"),
      el("td", count, count ? "num alert" : "num"),
      figure(now, "estops", true), figure(before, "estops", false),
      figure(now, "aborted_goals", true), figure(before, "aborted_goals", false),
      syncCell, el("td", clock(Date.parse(c.last_pushed_at)), "contact")]);
    tr.dataset.robot = c.robot_id;
    tr.dataset.ledger = c.ledger_id;
    tr.addEventListener("click", () => { showView("faults"); chooseRobot(c.robot_id); });
    return tr;
  });
  const table = $("fleet-table");
  table.classList.toggle("no-labels", !stats.items.some((r) => r.line || r.site));
  table.querySelectorAll("th.shift-current").forEach((th) => { th.textContent = shiftLabel(current, true); th.title = current || ""; });
  table.querySelectorAll("th.shift-previous").forEach((th) => { th.textContent = shiftLabel(previous, false); th.title = previous || ""; });
  table.tBodies[0].replaceChildren(...rows);
  $("fleet-legend").hidden = !provisional;
  const counted = `counted up to ${clock(Date.parse(stats.as_of), true)}, read again every 10 s`;
  $("fleet-span").textContent = current
    ? `Current shift ${current} (in progress), previous ${previous || "–"}; ${counted}`
    : `No shift now; the last was ${previous || "–"}; ${counted}`;
}

// -- views -----------------------------------------------------------------------------------
const loaded = new Set();
function showView(name) {
  state.view = name;
  document.querySelectorAll(".tab").forEach((tab) => tab.classList.toggle("active", tab.dataset.view === name));
  document.querySelectorAll(".view").forEach((view) => { view.hidden = view.id !== `view-${name}`; });
  if (name === "stats" && !loaded.has(name)) loadStats();
  // The History tab opens at the newest record of the last search, every time it is shown.
  if (name === "history") loadHistory(false);
  if (name === "fleet") loadFleet();
  if (name === "faults" && state.robot) loadRobotFaults();
  loaded.add(name);
}
document.querySelectorAll(".tab").forEach((tab) => tab.addEventListener("click", () => showView(tab.dataset.view)));

let ticks = 0;
setInterval(() => {
  ticks += 1;
  // Not while the page asks for a token (each 401 would ask again and take the focus).
  if (!state.started || document.hidden || !$("token-form").hidden) return;
  if (state.view === "faults" && state.robot) loadRobotFaults();
  if (state.view === "fleet" && ticks % 2 === 0) loadFleet();
  else if (ticks % 6 === 0) loadRobots().catch(() => {});  // a central's first robot shows up
}, TICK_MS);

async function start() {
  try {
    await loadFaults();
    state.started = true;
    stream();
    // A server that holds no robot logs shows neither the robot filter nor the Fleet view.
    await loadRobots().catch((error) => { if (error instanceof AuthNeeded) throw error; });
  } catch (error) {
    if (!(error instanceof AuthNeeded)) { setConnection(false); $("fault-count").textContent = error.message; }
  }
}
start();
