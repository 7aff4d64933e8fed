// DeepMorph studio: plain JavaScript, no library. Every action calls the studio's JSON API;
// the token travels in an HttpOnly cookie set when the page was opened with ?token=.
"use strict";

const $ = (sel) => document.querySelector(sel);
const SVGNS = "http://www.w3.org/2000/svg";
const state = { drawing: null, selected: null, weak: new Set(), models: [], live: null };
const ANIMATION_MS = 700; // between two morphs of the animation

function showError(message) {
  const box = $("#error");
  box.textContent = message || "";
  box.hidden = !message;
}

// quiet: leave the red bar to the caller (a request that a newer one may have overtaken)
async function api(path, { quiet = false, ...options } = {}) {
  const response = await fetch(path, { credentials: "same-origin", ...options });
  const type = response.headers.get("content-type") || "";
  const data = type.includes("json") ? await response.json() : await response.blob();
  if (!response.ok) {
    const message = data && data.error ? data.error : `${response.status} ${response.statusText}`;
    if (!quiet) showError(message);
    throw new Error(message);
  }
  if (!quiet) showError("");
  return data;
}

// the red bar shows the answer (or error) of the newest of a kind of request only: an older one
// still in flight gives null, or with keep (a download) its own answer, the bar left as it is
const latest = {};
async function newest(kind, request, keep = false) {
  const seq = (latest[kind] = (latest[kind] || 0) + 1);
  try {
    const data = await request();
    if (latest[kind] !== seq) return keep ? data : null;
    showError("");
    return data;
  } catch (exc) {
    if (latest[kind] !== seq && !keep) return null;
    if (latest[kind] === seq) showError(exc.message);
    throw exc;
  }
}

const postJson = (path, body, quiet = false) =>
  api(path, { method: "POST", headers: { "content-type": "application/json" }, body: JSON.stringify(body), quiet });

// -- tabs -------------------------------------------------------------------------------------
function openTab(name) {
  document.querySelectorAll("#tabs button").forEach((b) => b.classList.toggle("active", b.dataset.tab === name));
  document.querySelectorAll(".tab").forEach((s) => (s.hidden = s.id !== `tab-${name}`));
  location.hash = name;
  if (name !== "scan") stopCamera();
  if (name !== "drawing") stopAnimation();
  if (["payloads", "print", "scan"].includes(name)) loadModels();
  if (name === "payloads") loadEntries();
  if (name === "capacity" && state.drawing) runCapacity(); // the bounds as they are now
  if (name === "print") loadPrintEntries().then(printPreview, () => {});
}
document.querySelectorAll("#tabs button").forEach((b) => b.addEventListener("click", () => openTab(b.dataset.tab)));

// -- drawing ----------------------------------------------------------------------------------
function fmt(x) {
  return Number(x).toFixed(2).replace(/\.?0+$/, "");
}

function mmPerUnit() {
  const vb = state.drawing ? state.drawing.viewbox : [0, 0, 1, 1];
  return Number($("#width-mm").value || 50) / vb[2];
}

function showDrawing(data, keepSelection = false) {
  state.drawing = data;
  $("#drawing-img").src = `/api/drawing.svg?v=${Date.now()}`;
  const fixed = data.primitives.filter((p) => p.fixed).length;
  $("#drawing-summary").textContent =
    `${data.name}: ${data.primitives.length} shapes, ${data.n_variables} variables, ${fixed} fixed. ` +
    `Click a shape to set how it may move; circles show each point's allowed movement to scale.`;
  if (!keepSelection) state.selected = null;
  drawOverlay();
  selectShape(state.selected);
}

function drawOverlay() {
  const svg = $("#overlay");
  svg.replaceChildren();
  if (!state.drawing) return;
  const [x, y, w, h] = state.drawing.viewbox;
  svg.setAttribute("viewBox", `${x} ${y} ${w} ${h}`);
  const stroke = w / 150;
  for (const p of state.drawing.primitives) {
    const g = document.createElementNS(SVGNS, "g");
    g.setAttribute("class", "shape" + (p.fixed ? " fixed" : "") + (state.weak.has(p.index) ? " weak" : "") +
      (state.selected === p.index ? " selected" : ""));
    g.dataset.index = p.index;
    const line = document.createElementNS(SVGNS, "polyline");
    line.setAttribute("points", p.points.map((q) => q.join(",")).join(" "));
    line.setAttribute("class", "hit");
    line.setAttribute("stroke-width", String(stroke * 5));
    g.appendChild(line);
    for (const [px, py] of p.points) {
      // the allowed movement to scale; a point that may not move still gets a small target to click
      const c = document.createElementNS(SVGNS, "circle");
      c.setAttribute("cx", px);
      c.setAttribute("cy", py);
      c.setAttribute("r", p.move_radius > 0 ? p.move_radius : stroke * 4);
      c.setAttribute("class", p.move_radius > 0 ? "move" : "grab");
      c.setAttribute("stroke-width", String(stroke));
      g.appendChild(c);
      const dot = document.createElementNS(SVGNS, "circle");
      dot.setAttribute("cx", px);
      dot.setAttribute("cy", py);
      dot.setAttribute("r", String(stroke * 1.5));
      dot.setAttribute("class", "point");
      g.appendChild(dot);
    }
    if (p.shift) {
      const xs = p.points.map((q) => q[0]), ys = p.points.map((q) => q[1]);
      const r = document.createElementNS(SVGNS, "rect");
      r.setAttribute("x", Math.min(...xs) - p.shift[0]);
      r.setAttribute("y", Math.min(...ys) - p.shift[1]);
      r.setAttribute("width", Math.max(...xs) - Math.min(...xs) + 2 * p.shift[0]);
      r.setAttribute("height", Math.max(...ys) - Math.min(...ys) + 2 * p.shift[1]);
      r.setAttribute("class", "shift");
      r.setAttribute("stroke-width", String(stroke));
      g.appendChild(r);
    }
    g.addEventListener("click", (event) => {
      event.stopPropagation();
      selectShape(p.index);
    });
    svg.appendChild(g);
  }
}

function selectShape(index) {
  state.selected = index;
  const form = $("#bounds-form");
  document.querySelectorAll("#overlay .shape").forEach((g) =>
    g.classList.toggle("selected", Number(g.dataset.index) === index));
  if (index === null || index === undefined || !state.drawing) {
    form.hidden = true;
    return;
  }
  const p = state.drawing.primitives[index];
  form.hidden = false;
  $("#sel-index").textContent = `#${p.index}`;
  $("#sel-info").textContent = `${p.kind} at line ${p.line}: ${p.variables} variables` +
    (p.fixed ? ", fixed" : "");
  $("#group-choice").hidden = !p.group;
  if (!p.group) form.group.checked = false;
  const own = (form.group.checked && p.group ? p.group.own : p.own) || {};
  form.move.value = own.move ?? (p.bounds.move ?? "");
  form.shift.value = own.shift ?? "";
  form.scale.value = own.scale ?? "";
  form.rotate.value = own.rotate ?? "";
  form.fixed.checked = form.group.checked ? own.fixed === "true" : p.fixed;
  const mm = mmPerUnit();
  $("#sel-mm").textContent = `at ${fmt($("#width-mm").value)} mm wide: each point may move ` +
    `${fmt(p.move_radius * mm)} mm (${fmt(p.move_radius)} units)`;
}

$("#bounds-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const form = event.target;
  const body = {
    index: state.selected,
    move: form.move.value,
    shift: form.shift.value,
    scale: form.scale.value,
    rotate: form.rotate.value,
    fixed: form.fixed.checked,
    group: form.group.checked,
  };
  showDrawing(await postJson("/api/drawing/bounds", body), true);
});

$("#overlay").addEventListener("click", () => selectShape(null));
$("#bounds-form").group.addEventListener("change", () => selectShape(state.selected));
$("#width-mm").addEventListener("input", () => selectShape(state.selected));

async function openDrawing(file) {
  if (!file) return;
  const data = await api("/api/drawing", {
    method: "POST",
    headers: { "content-type": "image/svg+xml", "x-file-name": file.name },
    body: file,
  });
  state.weak = new Set();
  showDrawing(data);
}

$("#svg-file").addEventListener("change", async (event) => {
  try {
    await openDrawing(event.target.files[0]);
  } finally {
    event.target.value = "";
  }
});

// an SVG dragged onto the tab opens as if chosen with "Open an SVG"
const drawingTab = $("#tab-drawing");
drawingTab.addEventListener("dragover", (event) => {
  event.preventDefault();
  drawingTab.classList.add("dropping");
});
drawingTab.addEventListener("dragleave", () => drawingTab.classList.remove("dropping"));
drawingTab.addEventListener("drop", (event) => {
  event.preventDefault();
  drawingTab.classList.remove("dropping");
  openDrawing(event.dataTransfer.files[0]);
});

$("#use-ghost").addEventListener("click", async () => {
  state.weak = new Set();
  showDrawing(await postJson("/api/drawing/bundled", {}));
});

let morphSeed = 0;
function morph(extreme) {
  if (!state.drawing) return;
  morphSeed += 1;
  $("#drawing-img").src = `/api/drawing/morph.svg?seed=${morphSeed}&extreme=${extreme ? 1 : 0}`;
}
$("#morph-random").addEventListener("click", () => morph(false));
$("#morph-extreme").addEventListener("click", () => morph(true));

// Animate: a random morph and the extremes in turn, each a new seed, until Stop
let animation = null;
function stopAnimation() {
  if (animation === null) return;
  clearInterval(animation);
  animation = null;
  $("#morph-animate").textContent = "Animate";
  if (state.drawing) $("#drawing-img").src = `/api/drawing.svg?v=${Date.now()}`; // the drawing as it is
}
$("#morph-animate").addEventListener("click", () => {
  if (animation !== null) {
    stopAnimation();
    return;
  }
  if (!state.drawing) return;
  let frame = 0;
  const next = () => morph(frame++ % 2 === 1);
  next();
  animation = setInterval(next, ANIMATION_MS);
  $("#morph-animate").textContent = "Stop";
});

// -- capacity ---------------------------------------------------------------------------------
function clearCapacity() {
  for (const id of ["#capacity-table", "#capacity-limits", "#capacity-sizes", "#capacity-span", "#capacity-reads",
    "#capacity-note"]) {
    $(id).replaceChildren();
  }
}

async function runCapacity() {
  const form = $("#capacity-form");
  const q = new URLSearchParams({ print_mm: form.print_mm.value, distance_cm: form.distance_cm.value });
  let r;
  try {
    r = await newest("capacity", () => api(`/api/capacity?${q}`, { quiet: true }));
  } catch (exc) {
    clearCapacity(); // no stale numbers beside the error
    return;
  }
  if (r === null) return; // a newer prediction is on its way
  clearCapacity();
  const rows = [
    ["drawing", r.name],
    ["variables", `${r.n_variables} (${r.visible} visible)`],
    ["readable", `${r.readable_groups}`],
    ["code bits", `${r.code_bits}`],
    ["payload", !r.print_size.legibility.reads ? "none at this print size and distance: too small to read"
      : r.payload_bits ? `${r.payload_bits} bits read from 99 % of captures` : "none predicted to read"],
  ];
  for (const [k, v] of rows) {
    const tr = document.createElement("tr");
    const th = document.createElement("th");
    const td = document.createElement("td");
    th.textContent = k;
    td.textContent = v;
    if (k === "payload") td.id = "capacity-bits";
    tr.append(th, td);
    $("#capacity-table").appendChild(tr);
  }
  const ul = $("#capacity-limits");
  ul.replaceChildren(...r.limits.map((line) => Object.assign(document.createElement("li"), { textContent: line })));
  state.weak = new Set((r.elements || []).filter((e) => e.weak > 0).map((e) => e.index));
  drawOverlay();
  showPrintSize(r.print_size);
  // the payloads from 200 px up wait for the drawing's channel, measured in the background
  if (!r.channel_measured) setTimeout(() => { if (location.hash === "#capacity") runCapacity(); }, 2000);
}

// how far the visible variables move in a photo, as `deepmorph capacity --print-mm --distance-cm` says it
function showPrintSize(p) {
  $("#capacity-span").textContent = p.span;
  $("#capacity-reads").textContent = p.verdict;
  $("#capacity-reads").className = p.legibility.reads ? "" : "warn";
  const table = $("#capacity-sizes");
  table.appendChild(Object.assign(document.createElement("caption"),
    { textContent: "moves in the photo (control points across each variable's range), and the payload" }));
  const head = document.createElement("tr");
  for (const h of ["print width", "median move", "smallest move", "under 1 px", "payload bits"]) {
    head.appendChild(Object.assign(document.createElement("th"), { textContent: h }));
  }
  table.appendChild(head);
  for (const row of p.sizes) {
    const tr = document.createElement("tr");
    const yours = Math.abs(row.pixels - p.pixels) < 0.5;
    if (yours) tr.className = "yours";
    const cells = [`${row.pixels.toFixed(0)} px${yours ? " ←" : ""}`, `${row.median_move.toFixed(1)} px`,
      `${row.smallest_move.toFixed(1)} px`, String(row.sub_pixel), row.payload_text];
    for (const v of cells) tr.appendChild(Object.assign(document.createElement("td"), { textContent: v }));
    table.appendChild(tr);
  }
  $("#capacity-note").textContent = `note: ${p.note}`;
}
$("#capacity-form").addEventListener("submit", (event) => {
  event.preventDefault();
  runCapacity();
});
$("#capacity-form").addEventListener("change", () => runCapacity());

// -- training ---------------------------------------------------------------------------------
// the form's defaults and ranges are the training settings' (one place for them: the server's)
async function fillTrainForm() {
  const form = await api("/api/jobs/form");
  for (const input of document.querySelectorAll("#train-form input[name]")) {
    const spec = form[input.name];
    if (!spec) continue;
    input.value = spec.default;
    if (input.type === "number") Object.assign(input, { min: spec.min, max: spec.max });
  }
}

$("#train-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const body = Object.fromEntries(new FormData(event.target).entries());
  await postJson("/api/jobs", body);
});

function showJobs(jobs) {
  const box = $("#jobs");
  box.replaceChildren();
  if (!jobs.length) box.textContent = "No training runs yet.";
  for (const job of jobs) {
    const div = document.createElement("div");
    div.className = `job ${job.status}`;
    div.dataset.id = job.id;
    const title = document.createElement("h3");
    title.textContent = `${job.drawing}: ${job.status}`;
    const bar = document.createElement("progress");
    bar.max = job.total || 1;
    bar.value = job.step;
    const text = document.createElement("p");
    text.className = "job-progress";
    const acc = job.metrics.bit_acc !== undefined ? `, bits read ${(100 * job.metrics.bit_acc).toFixed(1)} %` : "";
    let eta = "";
    if (job.status === "running" && job.step > 0 && job.total > job.step) {
      eta = `, about ${Math.ceil((job.elapsed_s / job.step) * (job.total - job.step))} s left`;
    }
    text.textContent = `step ${job.step} / ${job.total || "?"}${acc}${eta}`;
    const message = document.createElement("p");
    message.className = "job-message";
    message.textContent = job.message;
    div.append(title, bar, text, plot(job.history), message);
    for (const warning of job.warnings || []) {
      div.appendChild(Object.assign(document.createElement("p"), { className: "job-warning", textContent: warning }));
    }
    if (["queued", "running"].includes(job.status)) {
      const cancel = document.createElement("button");
      cancel.textContent = "Cancel";
      cancel.addEventListener("click", () => api(`/api/jobs/${job.id}/cancel`, { method: "POST" }));
      div.appendChild(cancel);
    }
    box.appendChild(div);
  }
}

function plot(history) {
  const svg = document.createElementNS(SVGNS, "svg");
  svg.setAttribute("viewBox", "0 0 200 50");
  svg.setAttribute("class", "plot");
  if (history.length > 1) {
    const last = history[history.length - 1][0] || 1;
    const line = document.createElementNS(SVGNS, "polyline");
    line.setAttribute("points", history.map(([s, a]) => `${(200 * s) / last},${50 - 50 * a}`).join(" "));
    svg.appendChild(line);
  }
  return svg;
}

function watchJobs() {
  const events = new EventSource("/api/jobs/events");
  events.onmessage = (event) => showJobs(JSON.parse(event.data));
  events.onerror = () => {
    events.close();
    setTimeout(watchJobs, 2000); // the studio restarted, or the network blinked: attach again
  };
}

// -- models and payloads ----------------------------------------------------------------------
async function loadModels() {
  const models = await api("/api/models");
  state.models = models;
  document.querySelectorAll(".model-select").forEach((select) => {
    const keep = select.value;
    select.replaceChildren(...models.map((m) => {
      const o = document.createElement("option");
      o.value = m.id;
      o.textContent = `${m.id} (${m.drawing}, ${m.payload_bits} bits)`;
      return o;
    }));
    if (models.some((m) => m.id === keep)) select.value = keep;
  });
  if (!$("#print-payload").value) await newPayload();
}

async function loadEntries() {
  const model = $("#payloads-model").value || "ghost";
  const rows = await api(`/api/models/${encodeURIComponent(model)}/entries`);
  const table = $("#entries");
  table.replaceChildren();
  const head = document.createElement("tr");
  for (const h of ["payload", "kind", "target", "note", ""]) {
    head.appendChild(Object.assign(document.createElement("th"), { textContent: h }));
  }
  table.appendChild(head);
  for (const e of rows) {
    const tr = document.createElement("tr");
    for (const v of [e.payload.hex, e.kind, e.target, e.note || ""]) {
      tr.appendChild(Object.assign(document.createElement("td"), { textContent: v }));
    }
    const remove = Object.assign(document.createElement("button"), { textContent: "Remove" });
    remove.addEventListener("click", async () => {
      await api(`/api/models/${encodeURIComponent(model)}/entries/${e.payload.hex}/remove`, { method: "POST" });
      loadEntries();
    });
    const td = document.createElement("td");
    td.appendChild(remove);
    tr.appendChild(td);
    table.appendChild(tr);
  }
}
$("#payloads-model").addEventListener("change", loadEntries);
$("#entry-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const model = $("#payloads-model").value || "ghost";
  const body = Object.fromEntries(new FormData(event.target).entries());
  await postJson(`/api/models/${encodeURIComponent(model)}/entries`, body);
  event.target.reset();
  loadEntries();
});

// -- print ------------------------------------------------------------------------------------
// A payload is typed as a number or as hex, or picked from the model's registry entries; the
// studio reads typed text in the form chosen (deepmorph_core.payload.parse_payload_text).
const printState = { as: "hex", entries: [] };

function printModel() {
  return $("#print-model").value || "ghost";
}

function payloadBits() {
  const model = state.models.find((m) => m.id === printModel());
  return model ? model.payload_bits : 24;
}

// the payload to print and how the studio is to read it
function chosenPayload() {
  if (printState.as === "registry") return { payload: $("#print-entry").value, payload_as: "hex" };
  return { payload: $("#print-payload").value.trim(), payload_as: printState.as };
}

// a payload typed as a number written as hex, or back (BigInt: payloads have up to 256 bits);
// text that is not one is left as it is, for the studio to say what is wrong with it
function convertPayload(text, from, to) {
  const t = text.trim();
  let value;
  if (from === "number" && /^[0-9]+$/.test(t)) value = BigInt(t);
  else if (from === "hex" && /^(0x)?[0-9a-f]+$/i.test(t)) value = BigInt(/^0x/i.test(t) ? t : `0x${t}`);
  else return text;
  if (to === "number") return value.toString();
  return `0x${value.toString(16).toUpperCase().padStart(Math.ceil(payloadBits() / 4), "0")}`;
}

function showPayloadAs() {
  const registry = printState.as === "registry";
  $("#print-payload-field").hidden = registry;
  $("#print-random").hidden = registry;
  $("#print-entry-field").hidden = !registry || !printState.entries.length;
  $("#print-entry-none").hidden = !registry || printState.entries.length > 0;
  const typed = printState.as === "number" ? "a number" : "0x…";
  $("#print-payload").placeholder = typed;
  $("#print-payload").inputMode = printState.as === "number" ? "numeric" : "text";
  $("#sheet-form").lines.placeholder = typed;
}

document.querySelectorAll("#print-form input[name=payload_as]").forEach((radio) =>
  radio.addEventListener("change", () => {
    const before = printState.as;
    printState.as = radio.value;
    if (before !== "registry" && printState.as !== "registry") {
      $("#print-payload").value = convertPayload($("#print-payload").value, before, printState.as);
    }
    showPayloadAs();
  }));

// the model's registry entries, listed by what they stand for
async function loadPrintEntries() {
  const rows = await api(`/api/models/${encodeURIComponent(printModel())}/entries`);
  const select = $("#print-entry");
  const keep = select.value;
  printState.entries = rows;
  select.replaceChildren(...rows.map((e) => {
    const o = document.createElement("option");
    o.value = e.payload.hex;
    o.textContent = `${e.target}${e.note ? ` (${e.note})` : ""}: ${e.payload.hex}`;
    return o;
  }));
  if (rows.some((e) => e.payload.hex === keep)) select.value = keep;
  $("#sheet-entries").textContent = String(rows.length);
  showPayloadAs();
}

async function newPayload() {
  const p = await api(`/api/models/${encodeURIComponent(printModel())}/random`);
  $("#print-payload").value = printState.as === "number" ? p.number : p.hex;
  printPreview();
}
$("#print-random").addEventListener("click", newPayload);
$("#print-model").addEventListener("change", async () => {
  await loadPrintEntries();
  await newPayload();
});

function printQuery(format) {
  const form = $("#print-form");
  const q = new URLSearchParams({
    ...chosenPayload(), width_mm: form.width_mm.value, dpi: form.dpi.value, format,
  });
  return `/api/models/${encodeURIComponent(printModel())}/print?${q}`;
}

function printPreview() {
  if (!chosenPayload().payload) return;
  $("#print-preview").src = printQuery("svg") + "&preview=1";
  sheetPreview();
}
$("#print-form").addEventListener("change", printPreview);

function saveBlob(blob, name) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

document.querySelectorAll("#tab-print [data-format]").forEach((button) =>
  button.addEventListener("click", async () => {
    const format = button.dataset.format;
    const { payload } = chosenPayload();
    if (!payload) {
      showError(printState.as === "registry" ? "no registry entry to print: add one in the Payloads tab"
        : "no payload: type one, or draw a new random payload");
      return;
    }
    const blob = await api(printQuery(format));
    saveBlob(blob, `${printModel()}-${payload}-${$("#print-form").width_mm.value}mm.${format}`);
  }));

// a sheet of labelled codes: N consecutive payloads from a first one (the payload above unless
// given), a list, one a line (typed as the payload above is), or every registry entry
function sheetRequest(format, preview = false, quiet = false) {
  const f = $("#sheet-form");
  const chosen = chosenPayload();
  const fromRegistry = f.mode.value === "registry";
  const body = {
    mode: fromRegistry ? "list" : f.mode.value, count: f.count.value, start: f.start.value || chosen.payload,
    lines: fromRegistry ? printState.entries.map((e) => e.payload.hex).join("\n") : f.lines.value,
    payload_as: fromRegistry ? "hex" : chosen.payload_as,
    page: f.page.value, code_mm: f.code_mm.value, margin_mm: f.margin_mm.value,
    dpi: $("#print-form").dpi.value, format, preview,
  };
  return postJson(`/api/models/${encodeURIComponent(printModel())}/sheet`, body, quiet);
}

let sheetShown = null;
async function sheetPreview() {
  const img = $("#sheet-preview");
  const f = $("#sheet-form");
  // nothing to show yet: no payload to count from, or a list still to be typed
  if (f.mode.value === "range" && !chosenPayload().payload) return;
  if (f.mode.value === "list" && !f.lines.value.trim()) return;
  try {
    const blob = await newest("sheet", () => sheetRequest("svg", true, true));
    if (blob === null) return;
    if (sheetShown) URL.revokeObjectURL(sheetShown);
    sheetShown = img.src = URL.createObjectURL(blob);
    img.hidden = false;
  } catch (exc) {
    img.hidden = true; // the error is in the red bar
  }
}
$("#sheet-form").addEventListener("change", sheetPreview);

document.querySelectorAll("#sheet-form [data-sheet]").forEach((button) =>
  button.addEventListener("click", async () => {
    const format = button.dataset.sheet;
    // sequenced with the previews: a refusal answered after a newer sheet request stays out of the bar
    const blob = await newest("sheet", () => sheetRequest(format, false, true), true);
    const f = $("#sheet-form");
    saveBlob(blob, `${printModel()}-sheet-${f.page.value}-${f.code_mm.value}mm.${format}`);
  }));

// -- scan -------------------------------------------------------------------------------------
// the pose cube's corners as the server sends them (deepmorph_detect.results.Pose.cube): base on
// the paper 0-3, top towards the camera 4-7
const CUBE_BASE = [[0, 1], [1, 2], [2, 3], [3, 0]];
const CUBE_TOP = [[4, 5], [5, 6], [6, 7], [7, 4]];
const CUBE_UPRIGHTS = [[0, 4], [1, 5], [2, 6], [3, 7]];
function showScan(result, image) {
  const canvas = $("#scan-canvas");
  canvas.width = result.width;
  canvas.height = result.height;
  const ctx = canvas.getContext("2d");
  if (image) ctx.drawImage(image, 0, 0, result.width, result.height);
  const lines = [];
  for (const d of result.detections) {
    if (d.corners) {
      const c = d.corners;
      ctx.lineWidth = Math.max(2, result.width / 200);
      ctx.strokeStyle = d.ok ? "#0a0" : "#d40";
      ctx.beginPath();
      c.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.closePath();
      ctx.stroke();
    }
    if (d.cube) {
      // the camera's pose: a cube standing on the drawing's centre
      const q = d.cube;
      ctx.lineWidth = Math.max(2, result.width / 250);
      for (const [edges, colour] of [[CUBE_BASE, "#e00"], [CUBE_TOP, "#00e"], [CUBE_UPRIGHTS, "#0a0"]]) {
        ctx.strokeStyle = colour;
        ctx.beginPath();
        for (const [a, b] of edges) {
          ctx.moveTo(q[a][0], q[a][1]);
          ctx.lineTo(q[b][0], q[b][1]);
        }
        ctx.stroke();
      }
    }
    let line = `${d.payload.hex} ${d.ok ? "read" : "not verified"}`;
    if (d.pose) line += `, ${d.pose.tvec[2].toFixed(2)} drawing widths away`;
    if (d.ok) line += d.registry ? ` → ${d.registry.kind}: ${d.registry.target}` : " (not in the registry)";
    lines.push(line);
  }
  if (result.note) lines.push(result.note);
  const box = $("#scan-result");
  box.replaceChildren(...lines.map((t) => Object.assign(document.createElement("p"), { textContent: t })));
  if (result.detections.some((d) => d.ok)) box.dataset.payload = result.detections.find((d) => d.ok).payload.hex;
}

$("#photo-file").addEventListener("change", async (event) => {
  const file = event.target.files[0];
  if (!file) return;
  const model = $("#scan-model").value || "ghost";
  const result = await api(`/api/models/${encodeURIComponent(model)}/scan`, {
    method: "POST", headers: { "x-file-name": file.name }, body: file,
  });
  const image = await createImageBitmap(file).catch(() => null);
  showScan(result, image);
  event.target.value = "";
});

async function startCamera() {
  const video = $("#camera");
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia({ video: { width: 640, height: 480 }, audio: false });
  } catch (exc) {
    showError(`no camera: ${exc.message}`);
    return;
  }
  video.srcObject = stream;
  await video.play();
  $("#camera-start").disabled = true;
  $("#camera-stop").disabled = false;
  const live = { stream, frames: 0, started: performance.now(), firstRead: null, log: [] };
  state.live = live;
  const grab = document.createElement("canvas");
  const model = $("#scan-model").value || "ghost";
  while (state.live === live) {
    const grabbed = performance.now();
    grab.width = video.videoWidth;
    grab.height = video.videoHeight;
    grab.getContext("2d").drawImage(video, 0, 0);
    const blob = await new Promise((resolve) => grab.toBlob(resolve, "image/jpeg", 0.9));
    let result;
    try {
      const first = live.frames === 0 ? "&first=1" : "";
      result = await api(`/api/models/${encodeURIComponent(model)}/scan?live=1${first}`, { method: "POST", body: blob });
    } catch (exc) {
      break;
    }
    if (state.live !== live) break;
    live.frames += 1;
    if (live.firstRead === null && result.detections.some((d) => d.ok)) {
      live.firstRead = performance.now() - live.started;
    }
    showScan(result, grab);
    // the last frames' timings (when grabbed, when shown, what was found): how fast a print is read
    live.log.push({ grabbed, shown: performance.now(), found: result.detections.length,
      ok: result.detections.some((d) => d.ok),
      read: result.detections.filter((d) => d.ok).map((d) => d.payload.hex) });
    if (live.log.length > 600) live.log.shift();
    const seconds = (performance.now() - live.started) / 1000;
    const rate = $("#scan-rate");
    rate.textContent = `${(live.frames / seconds).toFixed(1)} frames/s, ${result.ms} ms a frame on the studio`;
    rate.dataset.fps = (live.frames / seconds).toFixed(2);
    rate.dataset.frames = live.frames;
  }
}

function stopCamera() {
  if (!state.live) return;
  state.live.stream.getTracks().forEach((t) => t.stop());
  state.live = null;
  $("#camera-start").disabled = false;
  $("#camera-stop").disabled = true;
}
$("#camera-start").addEventListener("click", startCamera);
$("#camera-stop").addEventListener("click", stopCamera);

// -- start ------------------------------------------------------------------------------------
async function start() {
  watchJobs();
  try {
    await fillTrainForm();
  } catch (exc) {
    // the red bar says why; an empty input trains at the server's default
  }
  try {
    const kept = await api("/api/drawing");
    if (!state.drawing) showDrawing(kept); // unless a drawing was opened meanwhile
  } catch (exc) {
    showError("");
  }
  const tab = location.hash.slice(1);
  openTab(["drawing", "capacity", "train", "payloads", "print", "scan"].includes(tab) ? tab : "drawing");
  document.body.dataset.ready = "1";
}
start();
