// What the live viewer (app.js) and the atlas's 3D bundle (bundle/atlas3d.entry.js) share:
// manifold colours and names as the map pictures draw them.

// The map pictures colour manifold k with matplotlib's tab10[k % 10]; the pages do the same.
export const TAB10 = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b",
  "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"];

// Manifold label 0, 1, … → A, B, … Z, AA (the API's names); "–" for none.
export function labelName(n) {
  if (n < 0) return "–";
  let s = "";
  n += 1;
  while (n > 0) { const r = (n - 1) % 26; s = String.fromCharCode(65 + r) + s; n = Math.floor((n - 1) / 26); }
  return s;
}
