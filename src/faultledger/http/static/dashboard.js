// faultledger dashboard: plain ES2020, no dependencies, served by the fault manager itself.
// Untrusted text (codes, descriptions, sources) only ever goes into textContent.
"use strict";
window.faultledgerPageId = Math.random().toString(36).slice(2);

const GROUPS = {
  "": ["PREFAILED", "CONFIRMED"], pending: ["PREFAILED"], confirmed: ["CONFIRMED"],
  cleared: ["CLEARED", "HEALED", "PREPASSED"], healed: ["HEALED", "PREPASSED"],
  all: ["PREFAILED", "CONFIRMED", "PREPASSED", "HEALED", "CLEARED"],
};
const ORDER = { CONFIRMED: 0, PREFAILED: 1, PREPASSED: 2, HEALED: 3, CLEARED: 4 };
const state = {
  token: sessionStorage.getItem("faultledger-token") || "",
  faults: new Map(), filter: "", lastEventId: null, selected: null,
  historyNext: null, historyParams: null, streaming: false,
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
function when(seconds) { return seconds ? new Date(seconds * 1000).toLocaleString() : "–"; }
function duration(seconds) {
  if (seconds === null || seconds === undefined) return "–";
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}
const sleep = (ms) => new Promise((done) => setTimeout(done, ms));

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

// -- faults ----------------------------------------------------------------------------------
function statusBadge(status) { return el("span", status, `status ${status}`); }

function faultRow(fault) {
  const tr = row([
    el("td", fault.fault_code), (() => { const td = el("td"); td.appendChild(statusBadge(fault.status)); return td; })(),
    fault.severity_label, el("td", fault.description, "text wide"), fault.occurrence_count,
    when(fault.last_occurred), el("td", fault.reporting_sources.join(", "), "text wide"),
  ]);
  tr.dataset.code = fault.fault_code;
  if (fault.fault_code === state.selected) tr.classList.add("selected");
  tr.addEventListener("click", () => showDetail(fault.fault_code));
  return tr;
}

function renderFaults(changed) {
  const wanted = GROUPS[state.filter];
  const shown = [...state.faults.values()].filter((f) => wanted.includes(f.status))
    .sort((a, b) => (ORDER[a.status] - ORDER[b.status]) || (b.last_occurred - a.last_occurred));
  const body = $("fault-table").tBodies[0];
  body.replaceChildren(...shown.map(faultRow));
  $("no-faults").hidden = shown.length > 0;
  $("fault-count").textContent = `${shown.length} shown of ${state.faults.size}`;
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
  if (state.selected === event.fault.fault_code) showDetail(state.selected);
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

async function showDetail(code) {
  state.selected = code;
  document.querySelectorAll("#fault-table tr.selected").forEach((tr) => tr.classList.remove("selected"));
  const tr = document.querySelector(`#fault-table tr[data-code="${CSS.escape(code)}"]`);
  if (tr) tr.classList.add("selected");
  $("detail").hidden = false;
  $("detail-code").textContent = code;
  try {
    const detail = await apiJson(`/api/v1/faults/${encodeURIComponent(code)}`);
    const x = detail["x-medkit"];
    $("detail-description").textContent = detail.item.fault_name || "";
    const fields = $("detail-fields");
    fields.replaceChildren();
    const status = detail.item.status;
    const add = (name, value) => { fields.appendChild(el("dt", name)); fields.appendChild(el("dd", value)); };
    add("status", `${x.status_raw} (${status.aggregatedStatus}; testFailed ${status.testFailed}, confirmedDTC ${status.confirmedDTC}, pendingDTC ${status.pendingDTC})`);
    add("severity", x.severity_label);
    add("occurrences", x.occurrence_count);
    add("first occurred", when(x.first_occurred));
    add("last occurred", when(x.last_occurred));
    add("last passed", when(x.last_passed));
    add("sources", (x.reporting_sources || []).join(", ") || "–");
    $("clear-form").hidden = document.body.dataset.readOnly === "true" || x.status_raw === "CLEARED";
    const history = await apiJson(`/api/v1/history?code=${encodeURIComponent(code)}&limit=200`);
    $("detail-history").tBodies[0].replaceChildren(...history.items.slice().reverse().map((r) => {
      const p = r.payload;
      const what = r.kind === "fault_reported" ? `${p.event_type} (${p.severity})`
        : r.kind === "fault_cleared" ? `cleared${p.reason ? ": " + p.reason : ""}` : r.kind;
      return row([r.seq, new Date(r.occurred_at_ns / 1e6).toLocaleString(), el("td", what, "text"),
        el("td", p.actor || r.source_id || "", "text")]);
    }));
  } catch (error) {
    if (!(error instanceof AuthNeeded)) $("detail-description").textContent = error.message;
  }
}
$("detail-close").addEventListener("click", () => { $("detail").hidden = true; state.selected = null; renderFaults(); });
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
    if (!(error instanceof AuthNeeded)) message.textContent = error.message;
  }
});

// -- statistics ------------------------------------------------------------------------------
function isoDate(date) {
  const pad = (n) => String(n).padStart(2, "0");
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())}`;
}

function bars(container, rows, key, colour) {
  const svgNS = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(svgNS, "svg");
  svg.setAttribute("viewBox", "0 0 600 160");
  svg.setAttribute("preserveAspectRatio", "none");
  const peak = Math.max(1, ...rows.map((r) => r[key] || 0));
  const width = 600 / Math.max(rows.length, 1);
  rows.forEach((r, i) => {
    const value = r[key] || 0;
    const height = (value / peak) * 110;
    const rect = document.createElementNS(svgNS, "rect");
    rect.setAttribute("x", String(i * width + 1));
    rect.setAttribute("y", String(140 - height));
    rect.setAttribute("width", String(Math.max(width - 2, 1)));
    rect.setAttribute("height", String(height));
    rect.setAttribute("fill", colour);
    const title = document.createElementNS(svgNS, "title");
    title.textContent = `${r.period}: ${value}`;
    rect.appendChild(title);
    svg.appendChild(rect);
    if (value) {
      const label = document.createElementNS(svgNS, "text");
      label.setAttribute("x", String(i * width + width / 2));
      label.setAttribute("y", String(136 - height));
      label.setAttribute("text-anchor", "middle");
      label.setAttribute("font-size", "11");
      label.textContent = String(value);
      svg.appendChild(label);
    }
    const day = String(r.period).split("/")[0];
    if (i === 0 || String(rows[i - 1].period).split("/")[0] !== day) {
      const tick = document.createElementNS(svgNS, "text");
      tick.setAttribute("x", String(i * width + 2));
      tick.setAttribute("y", "155");
      tick.setAttribute("font-size", "11");
      tick.setAttribute("fill", "#5d6678");
      tick.textContent = day.slice(5);
      svg.appendChild(tick);
    }
  });
  const axis = document.createElementNS(svgNS, "line");
  axis.setAttribute("x1", "0"); axis.setAttribute("x2", "600");
  axis.setAttribute("y1", "140"); axis.setAttribute("y2", "140");
  axis.setAttribute("stroke", "#999");
  svg.appendChild(axis);
  container.replaceChildren(svg);
}

function figure(label, value, previous, format) {
  const box = el("div", null, "figure");
  box.appendChild(el("div", format(value), "value"));
  box.appendChild(el("div", label, "label"));
  if (previous !== undefined && previous !== null) {
    const delta = (value || 0) - (previous || 0);
    const text = `${delta > 0 ? "▲" : delta < 0 ? "▼" : "="} previous shift ${format(previous)}`;
    box.appendChild(el("div", text, `change ${delta > 0 ? "up" : delta < 0 ? "down" : ""}`));
  }
  return box;
}

async function loadStats() {
  const message = $("stats-message");
  message.textContent = "";
  try {
    const since = isoDate(new Date(Date.now() - 7 * 86400 * 1000));
    const glob = $("stats-estop").value.trim() || "*EMERGENCY_STOP*";
    const all = (await apiJson(`/api/v1/stats?by=shift&since=${since}`)).items;
    const estops = (await apiJson(`/api/v1/stats?by=shift&since=${since}&code=${encodeURIComponent(glob)}`)).items;
    const wanted = $("stats-shift").value.trim();
    let index = wanted ? all.findIndex((r) => r.period === wanted) : all.length - 1;
    if (index < 0) throw new Error(`shift ${wanted} is not within the last 7 days`);
    const current = all[index], previous = all[index - 1];
    const stops = (i) => (i >= 0 && estops[i] ? estops[i].activations : null);
    $("stats-title").textContent = `Shift ${current.period} (${new Date(current.start).toLocaleString()} – ${new Date(current.end).toLocaleString()})`;
    const plain = (v) => (v === null || v === undefined ? "–" : String(v));
    $("figures").replaceChildren(
      figure("e-stops (activations)", stops(index), stops(index - 1), plain),
      figure("aborted goals", current.aborted_goals, previous && previous.aborted_goals, plain),
      figure("activations, all codes", current.activations, previous && previous.activations, plain),
      figure("failed reports", current.failed_reports, previous && previous.failed_reports, plain),
      figure("fault time CONFIRMED (sum)", current.active_seconds, previous && previous.active_seconds, duration),
      figure("MTTR", current.mttr_seconds, previous && previous.mttr_seconds, duration),
    );
    bars($("chart-estops"), estops, "activations", "#c62828");
    bars($("chart-aborted"), all, "aborted_goals", "#1f5fbf");
    const offenders = (await apiJson(`/api/v1/stats?by=shift&since=${encodeURIComponent(current.period)}&until=${encodeURIComponent(current.period)}&group_by=code`)).items
      .filter((r) => r.activations || r.failed_reports)
      .sort((a, b) => (b.activations - a.activations) || (b.failed_reports - a.failed_reports)).slice(0, 10);
    $("offenders").tBodies[0].replaceChildren(...offenders.map((r) => row([r.code, r.activations, r.failed_reports, duration(r.active_seconds)])));
    const link = $("shift-report-link");
    link.onclick = (event) => {
      event.preventDefault();
      download(`/api/v1/shift-report?shift=${encodeURIComponent(current.period)}`, `shift-report-${current.period.replace("/", "-")}.html`)
        .catch((error) => { message.textContent = error.message; });
    };
  } catch (error) {
    if (!(error instanceof AuthNeeded)) message.textContent = error.message;
  }
}
$("stats-form").addEventListener("submit", (event) => { event.preventDefault(); loadStats(); });

// -- history ---------------------------------------------------------------------------------
function historyParams() {
  const params = new URLSearchParams();
  for (const [name, id] of [["code", "history-code"], ["since", "history-since"], ["until", "history-until"]]) {
    const value = $(id).value.trim();
    if (value) params.set(name, value);
  }
  return params;
}

async function loadHistory(more) {
  const message = $("history-message");
  message.textContent = "";
  const params = more ? new URLSearchParams(state.historyParams) : historyParams();
  state.historyParams = params.toString();
  params.set("limit", "100");
  if (more && state.historyNext !== null) params.set("after_seq", String(state.historyNext));
  try {
    const page = await apiJson(`/api/v1/history?${params}`);
    const rows = page.items.map((r) => {
      const p = r.payload;
      const details = r.kind === "fault_reported" ? `${p.event_type} severity ${p.severity} ${p.description || ""}`
        : r.kind === "fault_cleared" ? `by ${p.actor}${p.reason ? ": " + p.reason : ""}`
        : r.kind === "goal_outcome" ? `${p.action} ${p.status}` : "";
      return row([r.seq, new Date(r.occurred_at_ns / 1e6).toLocaleString(), r.kind, r.fault_code || "",
        el("td", r.source_id || "", "text wide"), el("td", details, "text")]);
    });
    const body = $("history-table").tBodies[0];
    if (more) body.append(...rows); else body.replaceChildren(...rows);
    state.historyNext = page.next_after_seq;
    $("history-more").hidden = page.next_after_seq === null;
  } catch (error) {
    if (!(error instanceof AuthNeeded)) message.textContent = error.message;
  }
}
$("history-form").addEventListener("submit", (event) => { event.preventDefault(); loadHistory(false); });
$("history-more").addEventListener("click", () => loadHistory(true));
for (const [id, format] of [["export-csv", "csv"], ["export-jsonl", "jsonl"]]) {
  $(id).addEventListener("click", () => {
    const params = historyParams();
    params.set("format", format);
    download(`/api/v1/history?${params}`, `history.${format}`)
      .catch((error) => { $("history-message").textContent = error.message; });
  });
}

// -- views -----------------------------------------------------------------------------------
const loaded = new Set();
function showView(name) {
  document.querySelectorAll(".tab").forEach((tab) => tab.classList.toggle("active", tab.dataset.view === name));
  document.querySelectorAll(".view").forEach((view) => { view.hidden = view.id !== `view-${name}`; });
  if (!loaded.has(name)) {
    loaded.add(name);
    if (name === "stats") loadStats();
    if (name === "history") loadHistory(false);
  }
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
