// The atlas's 3D view: the live viewer's View3D (three.js included) started on a static page.
// build.mjs bundles this file into static/atlas3d.js, one classic script, because browsers
// load no ES module from file://. The page loads its object's data first as another classic
// script (view3d-data.js, written by services/local/atlas_site.py):
//   window.GRASPSCAPE_ATLAS_3D = {obj: "<OBJ text>" | null, directions: {pose_id, theta, phi,
//                                 r, mu_s, label, total_viable},
//                                 resting: {position, quaternion, …} | null (on a table)}
// and holds #view3d (canvas), #legend3d and #picked3d.
import { View3D } from "../static/view3d.js";
import { TAB10, labelName } from "../static/palette.js";

function show(box, d, i) {
  const deg = (x) => `${(x * 180 / Math.PI).toFixed(1)}°`;
  const label = d.label[i];
  const rows = [["pose", String(d.pose_id[i])], ["manifold", labelName(label)],
    ["θ, φ", `${deg(d.theta[i])}, ${deg(d.phi[i])}`], ["r", `${(1000 * d.r[i]).toFixed(1)} mm`],
    ["μs", d.mu_s[i].toFixed(3)]];
  const dl = document.createElement("dl");
  dl.className = "numbers";
  for (const [k, v] of rows) {
    const dt = document.createElement("dt");
    const dd = document.createElement("dd");
    dt.textContent = k;
    dd.textContent = v;
    dd.dataset.field = k;
    dl.append(dt, dd);
  }
  const heading = document.createElement("p");
  heading.textContent = `Pose ${d.pose_id[i]} (viable)`;
  const best = label >= 0 && document.getElementById(`grasp-${labelName(label)}`);
  if (best) {
    const a = document.createElement("a");
    a.href = `#grasp-${labelName(label)}`;
    a.textContent = `the best grasp of ${labelName(label)}`;
    heading.append(": see ", a);
  }
  box.replaceChildren(heading, dl);
}

function start() {
  const canvas = document.getElementById("view3d");
  const legend = document.getElementById("legend3d");
  const picked = document.getElementById("picked3d");
  if (!canvas || !legend || !picked) return;
  const data = window.GRASPSCAPE_ATLAS_3D;
  if (!data) {
    legend.textContent = "3D view unavailable: its data file (view3d-data.js) did not load.";
    return;
  }
  try {
    const view = new View3D(canvas, legend, TAB10, labelName,
      (_poseId, i) => show(picked, data.directions, i));
    view.pickShows = "numbers";
    if (data.obj) view.loadMesh(data.obj);
    if (data.resting) view.loadTable(data.resting);
    view.loadDirections(data.directions);
    canvas.dataset.ready = "1";
  } catch (err) {
    legend.textContent = `3D view unavailable: ${err.message || err}`;
  }
}

if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
else start();
