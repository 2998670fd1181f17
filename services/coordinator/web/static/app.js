// Graspscape viewer: one page, four views chosen by the URL hash (#/, #/exploration/ID,
// #/submit, #/workers). Live numbers come from one EventSource on /events/explorations;
// everything else is the coordinator's REST API. No framework, no build step.
import { TAB10, labelName } from "./palette.js";

const main = document.getElementById("main");
const live = document.getElementById("live");

let snapshot = null;            // the last progress event
const listeners = new Set();    // views that redraw on a progress event
let choices = null;

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined) continue;
    node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return node;
}

function fmt(x, digits = 3) {
  if (x === null || x === undefined || Number.isNaN(x)) return "–";
  if (typeof x === "number") {
    if (Number.isInteger(x)) return x.toLocaleString("en");
    return x.toFixed(digits);
  }
  if (typeof x === "boolean") return x ? "yes" : "no";
  if (typeof x === "object") return JSON.stringify(x);
  return String(x);
}

function duration(s) {
  if (s === null || s === undefined) return "–";
  if (s < 1) return "0 s";
  if (s < 90) return `${Math.round(s)} s`;
  if (s < 5400) return `${Math.round(s / 60)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}

function pct(x) { return x === null || x === undefined ? "–" : `${(100 * x).toFixed(1)} %`; }

async function getJSON(url, options = {}) {
  const res = await fetch(url, options);
  const text = await res.text();
  let body = null;
  try { body = text ? JSON.parse(text) : null; } catch { body = text; }
  if (!res.ok) {
    const detail = body && body.detail !== undefined ? body.detail : body;
    const msg = Array.isArray(detail) ? detail.map((d) => d.msg || JSON.stringify(d)).join("; ")
      : (typeof detail === "string" ? detail : JSON.stringify(detail));
    throw new Error(`${res.status}: ${msg}`);
  }
  return body;
}

async function getChoices() {
  if (!choices) choices = await getJSON("/web/choices");
  return choices;
}

// ---- live progress (server-sent events) ------------------------------------------------
function connectEvents() {
  const source = new EventSource("/events/explorations");
  source.addEventListener("progress", (event) => {
    snapshot = JSON.parse(event.data);
    live.textContent = `${snapshot.workers_connected} worker(s), ` +
      `${snapshot.processes_connected} process(es) connected`;
    live.dataset.updated = String(Date.now());
    for (const fn of listeners) fn(snapshot);
  });
  source.addEventListener("open", () => { live.dataset.connected = "1"; });
  source.addEventListener("error", () => {
    live.textContent = "coordinator unreachable; reconnecting…";
  });
}

// ---- explorations list -----------------------------------------------------------------
function progressRow(e) {
  const done = `${fmt(e.poses_done)} / ${fmt(e.poses_total)}`;
  return el("tr", { "data-id": e.id, "data-testid": `exploration-${e.id}` },
    el("td", {}, el("a", { href: `#/exploration/${e.id}` }, `#${e.id}`)),
    el("td", {}, e.label || `object ${e.object_id}`),
    el("td", {}, e.strategy),
    el("td", { class: `status-${e.status}`, "data-field": "status" }, e.status),
    el("td", {}, el("progress", { max: 1, value: e.fraction_done,
      "aria-label": `exploration ${e.id}: ${pct(e.fraction_done)} done` })),
    el("td", { class: "num", "data-field": "poses_done" }, done),
    el("td", { class: "num" }, pct(e.viable_share)),
    el("td", { class: "num" }, running(e) ? fmt(e.throughput_poses_per_s, 2) : "–"),
    el("td", { class: "num", "data-field": "eta" }, eta(e)));
}

// A rate and an ETA mean something only while poses come in; the server gives no ETA
// until it can estimate one (eta_s null), nor for a finished run.
function running(e) { return e.status === "running" || e.status === "queued"; }

function eta(e) {
  if (!running(e)) return "–";
  return e.eta_s === null || e.eta_s === undefined ? "estimating…" : duration(e.eta_s);
}

function viewList() {
  const body = el("tbody", { "data-testid": "explorations" });
  const summary = el("p", { class: "note" }, "Waiting for the first progress event…");
  const table = el("table", {},
    el("caption", { class: "note", style: "text-align:left" },
      "Newest first; numbers update live."),
    el("thead", {}, el("tr", {}, ["Id", "Label / object", "Strategy", "Status", "Progress",
      "Poses done / planned", "Viable share", "Poses per second", "Time left"].map((h, i) =>
      el("th", { scope: "col", class: i >= 5 ? "num" : null }, h)))),
    body);
  main.replaceChildren(el("h2", {}, "Explorations"), summary, table);
  const draw = (snap) => {
    body.replaceChildren(...snap.explorations.map(progressRow));
    summary.textContent = `${snap.total} exploration(s); ${snap.workers_connected} worker(s) ` +
      `with ${snap.processes_connected} process(es) connected.`;
    if (!snap.explorations.length) {
      body.append(el("tr", {}, el("td", { colspan: 9 },
        "No exploration yet: ", el("a", { href: "#/submit" }, "submit one"), ".")));
    }
  };
  if (snapshot) draw(snapshot);
  return draw;
}

// ---- one exploration -------------------------------------------------------------------
function facts(detail, p) {
  const live = running(detail);
  return el("ul", { class: "facts", "data-testid": "facts" },
    el("li", {}, "status ", el("b", { class: `status-${detail.status}` }, detail.status)),
    el("li", {}, "poses ", el("b", { "data-field": "poses_done" },
      `${fmt(p.poses_done)} / ${fmt(p.poses_total)}`)),
    el("li", {}, "viable ", el("b", {}, pct(p.viable_share))),
    live ? el("li", {}, "poses per second ", el("b", {}, fmt(p.throughput_poses_per_s, 2))) : null,
    live ? el("li", { "data-field": "eta" }, "time left ",
      el("b", {}, eta({ status: detail.status, eta_s: p.eta_s }))) : null,
    el("li", {}, "gripper ", el("b", {}, detail.spec.gripper)),
    el("li", {}, "policy ", el("b", {}, detail.spec.settings.policy_name)),
    el("li", {}, "strategy ", el("b", {}, detail.spec.strategy.name)));
}

// The grasp panel: what a person reads first, each with its unit; every stored field
// behind a toggle.
const deg = (v) => (typeof v === "number" ? `${(v * 180 / Math.PI).toFixed(1)}°` : "–");
const CURATED = [
  ["outcome", "Outcome", (p) => p.outcome],
  ["mu_s", "μs (grasp quality)", (p) => fmt(p.mu_s)],
  ["robust_label", "Robustness", (p) => p.robust_label || "–"],
  ["robust_s", "Robust success s_δ", (p) => fmt(p.robust_s, 2)],
  ["approach", "Approach θ, φ", (p) => `${deg(p.theta)}, ${deg(p.phi)}`],
  ["r", "Start gap", (p) => (typeof p.r === "number" ? `${(p.r * 1000).toFixed(0)} mm` : "–")],
  ["roll", "Roll", (p) => deg(p.roll)],
  ["effort_max_nm", "Largest joint effort", (p) => `${fmt(p.effort_max_nm, 2)} N·m`],
  ["torque_margin_ratio", "Torque margin", (p) => pct(p.torque_margin_ratio)],
  ["pose", "Pose", (p) => `#${p.id}`],
];

function poseNumbers(pose) {
  const curated = [];
  for (const [key, name, value] of CURATED) {
    curated.push(el("dt", {}, name), el("dd", { "data-field": key }, value(pose)));
  }
  const raw = [];
  const skip = new Set(["contacts_per_link", "signature", "grasp"]);
  for (const [k, v] of Object.entries(pose)) {
    if (skip.has(k) || (v !== null && typeof v === "object")) continue;
    raw.push(el("dt", {}, k), el("dd", { "data-raw": k }, fmt(v)));
  }
  return el("div", {},
    el("dl", { class: "numbers", "data-testid": "grasp-numbers" }, curated),
    el("details", { class: "raw", "data-testid": "raw-fields" },
      el("summary", {}, "All stored fields"), el("dl", { class: "numbers" }, raw)));
}

async function showGrasp(id, pose, box, title) {
  const ch = await getChoices();
  const heading = el("h3", { tabindex: "-1" }, title);
  const picture = ch.grasp_pictures
    ? el("img", { src: `/explorations/${id}/poses/${pose.id}/grasp.png`,
      alt: `the grasp of pose ${pose.id} (${pose.outcome}, μs ${fmt(pose.mu_s)})`,
      "data-testid": "grasp-picture" })
    : el("p", { class: "note" }, "No grasp pictures: this coordinator runs without the " +
      "workers' simulation (graspscape serve wires the renderer in).");
  if (picture.tagName === "IMG") {
    picture.addEventListener("load", () => { picture.dataset.loaded = "1"; });
  }
  box.replaceChildren(heading, el("div", { class: "grasp" }, picture, poseNumbers(pose)));
  heading.focus({ preventScroll: true });
  box.scrollIntoView({ block: "nearest" });
}

async function showBest(id, manifold, box) {
  box.replaceChildren(el("p", { class: "note" }, `Finding the best grasp of ${manifold}…`));
  try {
    const best = await getJSON(`/explorations/${id}/best?manifold=${manifold}`);
    if (!best.poses.length) { box.replaceChildren(el("p", {}, "No ranked grasp.")); return; }
    await showGrasp(id, best.poses[0], box, `Best grasp of manifold ${manifold}`);
  } catch (err) {
    box.replaceChildren(el("p", { class: "error" }, String(err.message || err)));
  }
}

// The manifold table: the large manifolds (≥ 1 % of the viable volume) a row each, the
// dust (the smaller ones) as one row that opens onto theirs.
const MANIFOLD_COLUMNS = [
  ["Manifold", null], ["Grasp type", null], ["Poses", "num"], ["Volume, cm³", "num"],
  ["Robust core, cm³", "num"], ["Mean μs", "num"], ["Best μs", "num"],
  ["P(success)", null], ["", null]];

// A manifold's best grasp by P(success): k of n draws, the bounds and the claim.
function successText(s) {
  if (!s || !s.success) return "–";
  const e = s.success;
  const bounds = `${e.k}/${e.n} [${fmt(e.lower, 2)}, ${fmt(e.upper, 2)}]`;
  return e.certified ? `${bounds} certified` : bounds;
}

function manifoldRow(id, m, box, dust, success) {
  const pick = (ev) => {
    for (const tr of ev.target.closest("tbody").children) tr.classList.remove("selected");
    ev.target.closest("tr").classList.add("selected");
    showBest(id, m.name, box);
  };
  return el("tr", { "data-manifold": m.name, class: dust ? "dust" : null, hidden: dust },
    el("th", { scope: "row" }, el("span", { class: "swatch",
      style: `background:${TAB10[m.label % 10]}` }), m.name),
    // The digits in contact; where they touch, in the tooltip (a line of numbers per digit).
    el("td", { title: m.description }, m.description.split(" — ")[0]),
    el("td", { class: "num" }, fmt(m.pose_count)),
    el("td", { class: "num" }, fmt(m.volume_cm3, 1)),
    el("td", { class: "num" }, m.core_volume_cm3 === null || m.core_volume_cm3 === undefined
      ? "–" : fmt(m.core_volume_cm3, 1)),
    el("td", { class: "num" }, fmt(m.mu_s_mean)),
    el("td", { class: "num" }, fmt(m.mu_s_max)),
    el("td", { "data-testid": `success-${m.name}`, title: "its best grasp by " +
      "P(success): draws held with its grasp type k/n and the 95 % bounds; certified: the " +
      "lower bound clears the exploration's level" },
      dust ? "–" : successText(success)),
    el("td", {}, el("button", { type: "button", class: "secondary",
      "data-testid": `best-${m.name}`, "aria-label": `best grasp of ${m.name}`,
      onclick: pick }, "Best grasp")));
}

function dustRow(list, dustRows) {
  const d = list.dust;
  const toggle = el("button", { type: "button", class: "secondary", "aria-expanded": "false",
    "data-testid": "dust-toggle" }, "Show them");
  toggle.addEventListener("click", () => {
    const open = toggle.getAttribute("aria-expanded") !== "true";
    toggle.setAttribute("aria-expanded", String(open));
    toggle.textContent = open ? "Hide them" : "Show them";
    for (const tr of dustRows) tr.hidden = !open;
  });
  return el("tr", { "data-testid": "dust" },
    el("th", { scope: "row" }, "Dust"),
    el("td", {}, `${fmt(d.manifolds)} smaller manifolds (each under 1 % of the viable volume)`),
    el("td", { class: "num" }, fmt(d.poses)),
    el("td", { class: "num" }, fmt(d.volume_cm3, 1)),
    el("td", { colspan: 4 }),
    el("td", {}, toggle));
}

function manifoldTable(id, list, box) {
  const large = list.manifolds.filter((m) => m.large !== false);
  const dust = list.manifolds.filter((m) => m.large === false);
  const dustRows = dust.map((m) => manifoldRow(id, m, box, true));
  const chances = list.success || {};
  const rows = large.map((m) => manifoldRow(id, m, box, false, chances[m.name]));
  if (dust.length && list.dust) rows.push(dustRow(list, dustRows), ...dustRows);
  return el("div", {},
    el("p", { class: "note" }, `${large.length} large manifold(s)` +
      (dust.length ? ` and ${dust.length} smaller ones` : "") +
      (list.final ? "" : " so far (running)")),
    el("div", { style: "overflow-x:auto" }, el("table", { "data-testid": "manifolds" },
      el("thead", {}, el("tr", {}, MANIFOLD_COLUMNS.map(([h, cls]) =>
        el("th", { scope: "col", class: cls }, h)))),
      el("tbody", {}, rows))));
}

async function viewExploration(id) {
  main.replaceChildren(el("h2", {}, `Exploration #${id}`), el("p", {}, "Loading…"));
  let detail;
  try { detail = await getJSON(`/explorations/${id}`); } catch (err) {
    main.replaceChildren(el("h2", {}, `Exploration #${id}`), el("p", { class: "error" }, String(err.message)));
    return null;
  }
  const factsBox = el("div", {}, facts(detail, detail.progress));
  const grid = detail.spec.grid;
  const attitudes = (grid.attitudes.rolls || 1) * (1 + 4 * (grid.attitudes.tilts || []).length);
  const cut = el("select", { id: "cut" }, el("option", { value: "horizontal" }, "horizontal (θ = 90°)"),
    el("option", { value: "vertical" }, "vertical (through φ0)"));
  const phi0 = el("input", { id: "phi0", type: "number", min: -360, max: 360, step: 5, value: 0 });
  const attitude = el("input", { id: "attitude", type: "number", min: 0, max: attitudes - 1, step: 1, value: 0 });
  // The grid's coarse r levels (on the finest lattice too); "" draws every r.
  const rLevels = [];
  for (let k = 0; grid.r_min + k * grid.dr <= grid.r_max + 1e-9 && k < 200; k++) {
    rLevels.push(Math.round((grid.r_min + k * grid.dr) * 1e4) / 10);
    if (!(grid.dr > 0)) break;
  }
  const rCut = el("select", { id: "r_mm" }, el("option", { value: "" }, "every r"),
    rLevels.map((r) => el("option", { value: String(r) }, `${r} mm`)));
  const img = el("img", { id: "map", alt: "behavioral map: a cut through pose space and a 3D view", "data-testid": "map" });
  img.addEventListener("load", () => { img.dataset.loaded = "1"; });
  const drawMap = () => {
    img.dataset.loaded = "";
    img.src = `/explorations/${id}/map.png?cut=${cut.value}&phi0_deg=${Number(phi0.value) || 0}` +
      `&attitude=${Math.min(attitudes - 1, Math.max(0, Number(attitude.value) || 0))}` +
      (rCut.value !== "" ? `&r_mm=${rCut.value}` : "") + `&v=${detail.poses_done}`;
  };
  const controls = el("form", { class: "controls", onsubmit: (e) => { e.preventDefault(); drawMap(); } },
    el("label", {}, "Cut", cut), el("label", {}, "φ0 of a vertical cut, °", phi0),
    attitudes > 1 ? el("label", {}, `Attitude, index 0–${attitudes - 1}`, attitude) : null,
    el("label", {}, "Start gap r", rCut),
    el("button", { type: "submit" }, "Draw"));
  for (const c of [cut, attitude, rCut]) c.addEventListener("change", drawMap);
  const graspBox = el("section", { class: "panel grasp-panel", "aria-live": "polite",
    "aria-label": "chosen grasp", "data-testid": "grasp" },
    el("h3", {}, "Chosen grasp"),
    el("p", { class: "note" }, "Choose a manifold (or click a point in the 3D view) to see its grasp."));
  const tableBox = el("div", {}, el("p", {}, "Loading manifolds…"));
  const canvasBox = el("div", {}, el("canvas", { id: "view3d", tabindex: "0",
    "aria-label": "3D view of the object with the viable approach directions; arrow keys rotate" }));
  const legend = el("p", { class: "note", id: "legend3d" });
  const exportLinks = el("p", { class: "exports" }, "Exports: ",
    ["poses.csv", "poses.parquet", "manifolds.json", "object.obj", "graspgen.json", "acronym.h5"].map(
      (n) => el("a", { href: `/explorations/${id}/export/${n}`, download: true }, n)),
    el("a", { href: `/explorations/${id}/map.svg` }, "map.svg"));
  // Two columns: the map and the manifold table on the left; the chosen grasp and the 3D
  // view on the right, kept in view while the table scrolls.
  main.replaceChildren(
    el("h2", {}, `Exploration #${id}`, detail.spec.label ? ` — ${detail.spec.label}` : ""),
    factsBox,
    el("div", { class: "grid" },
      el("div", { class: "column" },
        el("section", { class: "panel map", "aria-label": "map" }, el("h3", {}, "Behavioral map"), controls, img),
        el("section", { "aria-label": "manifolds" }, el("h3", {}, "Manifolds"), tableBox)),
      el("aside", { class: "column side", "data-testid": "side" },
        graspBox,
        el("section", { class: "panel", "aria-label": "3D view" }, el("h3", {}, "Approach directions"), canvasBox, legend))),
    exportLinks);
  drawMap();
  const loadTable = async () => {
    try {
      const list = await getJSON(`/explorations/${id}/manifolds`);
      tableBox.replaceChildren(manifoldTable(id, list, graspBox));
    } catch (err) { tableBox.replaceChildren(el("p", { class: "error" }, String(err.message))); }
  };
  await loadTable();
  let view = null;
  const load3d = async () => {
    try {
      const { View3D } = await import("./view3d.js");
      if (!view) {
        view = new View3D(canvasBox.querySelector("canvas"), legend, TAB10, labelName, async (poseId) => {
          const pose = await getJSON(`/web/explorations/${id}/poses/${poseId}`);
          await showGrasp(id, pose, graspBox, `Grasp of pose ${poseId}`);
        });
        const res = await fetch(`/explorations/${id}/export/object.obj`);
        if (!res.ok) throw new Error(`object mesh: ${res.status}`);
        view.loadMesh(await res.text());
        // On a table, the object at its resting pose above the table (concepts/support.md).
        const resting = detail.spec.support && detail.spec.support.resting;
        if (resting) view.loadTable(resting);
      }
      await view.loadDirections(await getJSON(`/web/explorations/${id}/directions`));
    } catch (err) { legend.textContent = `3D view unavailable: ${err.message || err}`; }
  };
  load3d();
  let lastDone = detail.poses_done;
  let lastStatus = detail.status;
  return (snap) => {
    const e = snap.explorations.find((x) => x.id === id);
    if (!e) return;
    factsBox.replaceChildren(facts({ ...detail, status: e.status }, e));
    // Redraw what depends on the stored poses when enough of them changed (pictures cost).
    if (e.status !== lastStatus || e.poses_done - lastDone >= Math.max(20, 0.1 * lastDone)) {
      lastDone = e.poses_done; lastStatus = e.status;
      detail.poses_done = e.poses_done;
      drawMap(); loadTable(); load3d();
    }
  };
}

// ---- submit ----------------------------------------------------------------------------
async function viewSubmit() {
  const ch = await getChoices();
  const option = (v, text = v) => el("option", { value: v }, text);
  const objectSel = el("select", { name: "object", id: "object" },
    el("optgroup", { label: "built-in" }, ch.builtin_objects.map((n) => option(n))),
    el("optgroup", { label: "other" }, option("__name", "a name (pb:…, ycb:…)"), option("__file", "upload a mesh file")));
  const objectName = el("input", { name: "object_name", id: "object_name", placeholder: "ycb:YcbPowerDrill" });
  const file = el("input", { type: "file", name: "file", id: "file", accept: ".obj,.stl,.ply,.glb,.off" });
  const mass = el("input", { type: "number", name: "mass", id: "mass", min: 0, step: "any", placeholder: "kg" });
  const units = el("select", { name: "units", id: "units" }, option("m"), option("cm"), option("mm"));
  const gripper = el("select", { name: "gripper", id: "gripper" }, ch.grippers.map((n) => option(n)));
  gripper.value = ch.grippers.includes("robotiq_3f") ? "robotiq_3f" : ch.grippers[0];
  const policy = el("select", { name: "policy", id: "policy" }, ch.policies.map((n) => option(n)));
  const strategy = el("select", { name: "strategy", id: "strategy" }, ch.strategies.map((n) => option(n)));
  const budget = el("input", { type: "number", name: "budget", id: "budget", min: 1, value: 500 });
  const dtheta = el("input", { type: "number", name: "dtheta", id: "dtheta", min: 1, max: 90, step: "any", value: 20 });
  const rMin = el("input", { type: "number", name: "r_min", id: "r_min", min: 0, max: 0.5, step: "any", value: 0.01 });
  const rMax = el("input", { type: "number", name: "r_max", id: "r_max", min: 0, max: 0.5, step: "any", value: 0.03 });
  const dr = el("input", { type: "number", name: "dr", id: "dr", min: 0.001, max: 0.5, step: "any", value: 0.01 });
  const rolls = el("select", { name: "rolls", id: "rolls" }, ["1", "2", "4", "8"].map((n) => option(n)));
  const levels = el("select", { name: "levels", id: "levels" }, ["0", "1", "2", "3", "4", "5", "6"].map((n) => option(n)));
  levels.value = "1";
  const robustness = el("select", { name: "robustness", id: "robustness" },
    option("default", "torque margin of held poses (what /best ranks by)"), option("none", "none (faster)"));
  const label = el("input", { name: "label", id: "label", maxlength: 200 });
  const token = el("input", { type: "password", name: "token", id: "token", autocomplete: "off",
    placeholder: "only if the coordinator has one" });
  const message = el("p", { role: "status", "data-testid": "submit-status" });
  const toggle = () => {
    objectName.closest("label").hidden = objectSel.value !== "__name";
    for (const n of [file, mass, units]) n.closest("label").hidden = objectSel.value !== "__file";
    budget.closest("label").hidden = !["random", "cmaes", "ppo"].includes(strategy.value);
  };
  objectSel.addEventListener("change", toggle);
  strategy.addEventListener("change", toggle);
  const submit = async (ev) => {
    ev.preventDefault();
    const button = form.querySelector("button[type=submit]");
    button.disabled = true;
    message.className = "";
    message.textContent = "Storing the object…";
    const headers = token.value ? { Authorization: `Bearer ${token.value}` } : {};
    try {
      const body = new FormData();
      if (objectSel.value === "__file") {
        if (!file.files.length) throw new Error("choose a mesh file");
        body.append("file", file.files[0]);
        if (mass.value) body.append("mass_kg", mass.value);
        body.append("units", units.value);
      } else {
        body.append("name", objectSel.value === "__name" ? objectName.value.trim() : objectSel.value);
      }
      const obj = await getJSON("/objects", { method: "POST", body, headers });
      const strat = { name: strategy.value };
      if (["random", "cmaes", "ppo"].includes(strategy.value)) strat.poses = Number(budget.value);
      const spec = {
        object_id: obj.id, gripper: gripper.value,
        grid: { dtheta: Number(dtheta.value) * Math.PI / 180, r_min: Number(rMin.value),
          r_max: Number(rMax.value), dr: Number(dr.value), attitudes: { rolls: Number(rolls.value) } },
        settings: { policy_name: policy.value,
          ...(robustness.value === "none" ? { robustness: { tests: [] } } : {}) },
        refinement: { levels: Number(levels.value) },
        strategy: strat,
      };
      if (label.value.trim()) spec.label = label.value.trim();
      message.textContent = "Submitting…";
      const created = await getJSON("/explorations", { method: "POST", body: JSON.stringify(spec),
        headers: { ...headers, "Content-Type": "application/json" } });
      message.textContent = `Exploration #${created.id} submitted: ${created.poses_total} poses planned.`;
      location.hash = `#/exploration/${created.id}`;
    } catch (err) {
      message.className = "error";
      message.textContent = `Not submitted: ${err.message || err}`;
    } finally { button.disabled = false; }
  };
  const form = el("form", { class: "submit", onsubmit: submit, "data-testid": "submit-form" },
    el("fieldset", {}, el("legend", {}, "Object"),
      el("label", {}, "Object", objectSel), el("label", {}, "Name", objectName),
      el("label", {}, "Mesh file", file), el("label", {}, "Mass, kg", mass), el("label", {}, "Units", units)),
    el("fieldset", {}, el("legend", {}, "Gripper and policy"),
      el("label", {}, "Gripper", gripper), el("label", {}, "Policy", policy),
      el("label", {}, "Robustness tests", robustness)),
    el("fieldset", {}, el("legend", {}, "Pose grid and search"),
      el("label", {}, "Strategy", strategy), el("label", {}, "Pose budget", budget),
      el("label", {}, "Δθ between directions, °", dtheta),
      el("label", {}, "r min, m", rMin), el("label", {}, "r max, m", rMax), el("label", {}, "Δr, m", dr),
      el("label", {}, "Rolls", rolls), el("label", {}, "Refinement levels", levels)),
    el("label", {}, "Label", label), el("label", {}, "API token", token),
    el("div", { class: "actions" }, el("button", { type: "submit" }, "Submit exploration"), message));
  main.replaceChildren(el("h2", {}, "Submit an exploration"), form);
  toggle();
  return null;
}

// ---- workers ---------------------------------------------------------------------------
async function viewWorkers() {
  const body = el("tbody", { "data-testid": "workers" });
  main.replaceChildren(el("h2", {}, "Workers"),
    el("p", { class: "note" }, "Connected: heard from within the last 30 s. Throughput over the coordinator's throughput window."),
    el("table", {}, el("thead", {}, el("tr", {}, ["Worker", "Host", "Processes", "Connected",
      "Poses (window)", "Poses/s", "Last seen", "First seen"].map((h) => el("th", { scope: "col" }, h)))), body));
  const draw = async () => {
    const rows = await getJSON("/web/workers");
    body.replaceChildren(...rows.map((w) => el("tr", {},
      el("td", {}, w.id), el("td", {}, w.host), el("td", { class: "num" }, fmt(w.processes)),
      el("td", { class: w.connected ? "status-done" : "status-cancelled" }, w.connected ? "yes" : "no"),
      el("td", { class: "num" }, fmt(w.poses_last_window)),
      el("td", { class: "num" }, fmt(w.throughput_poses_per_s, 2)),
      el("td", {}, new Date(w.last_seen).toLocaleString()),
      el("td", {}, new Date(w.first_seen).toLocaleString()))));
    if (!rows.length) body.append(el("tr", {}, el("td", { colspan: 8 }, "No worker seen yet.")));
  };
  await draw();
  let last = 0;
  return () => { if (Date.now() - last > 2000) { last = Date.now(); draw(); } };
}

// ---- routing ---------------------------------------------------------------------------
async function route() {
  listeners.clear();
  const hash = location.hash || "#/";
  const m = hash.match(/^#\/exploration\/(\d+)/);
  const page = m ? "exploration" : hash.startsWith("#/submit") ? "submit"
    : hash.startsWith("#/workers") ? "workers" : "list";
  for (const a of document.querySelectorAll("nav a")) {
    if (a.dataset.nav === page) a.setAttribute("aria-current", "page"); else a.removeAttribute("aria-current");
  }
  document.title = `Graspscape — ${m ? `exploration ${m[1]}` : page}`;
  let onProgress = null;
  if (page === "exploration") onProgress = await viewExploration(Number(m[1]));
  else if (page === "submit") onProgress = await viewSubmit();
  else if (page === "workers") onProgress = await viewWorkers();
  else onProgress = viewList();
  if (onProgress) listeners.add(onProgress);
  document.body.dataset.page = page;
  main.focus({ preventScroll: true });
}

window.addEventListener("hashchange", route);
connectEvents();
route();
