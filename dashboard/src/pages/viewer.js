// The 3D viewer of a job: the target body and the result strands, the source next to them, another job of the
// same pair (a baseline) overlaid for comparison; particles inside the body drawn red.
import { decodeDisplay, get, openapi, post } from "../api.js";
import { fill, formatNumber, guarded, h, poll, short, showMessage } from "../ui.js";
import { LAYER_RGB, THREE, Viewer, bodyMesh, strandLines, wrapOverlay } from "../scene.js";
import { ENDED, wrapResidual } from "./jobs.js";
import { component, select } from "./forms.js";

/** Display budgets offered (vertices), with the API's default (bench/dashboard.py chose it). */
const BUDGETS = [10_000, 50_000, 200_000, 1_000_000, 2_000_000];
const SIDE_GAP = 1.25;  // source drawn this many body widths to the left

const PLAY_FPS = 24;  // a sequence plays at most this many frames a second (fewer while frames are fetched)

/** `&frame=K` of a sequence job's frame, nothing for a job onto one body. */
function frameQuery(frame) {
  return frame === null || frame === undefined ? "" : `&frame=${frame}`;
}

async function strands(jobId, layer, budget, frame = null) {
  return decodeDisplay(await get(`/v1/jobs/${jobId}/display?layer=${layer}&max_vertices=${budget}${frameQuery(frame)}`,
                                 { as: "buffer" }));
}

async function body(jobId, layer, frame = null) {
  return decodeDisplay(await get(`/v1/jobs/${jobId}/body?layer=${layer}${frameQuery(frame)}`, { as: "buffer" }));
}

/** The play button, frame slider and label of a sequence job; `show(frame)` draws one frame. */
function frameControls(job, show, signal) {
  const count = job.frames;
  const times = (job.metrics?.frames_detail ?? []).map((frame) => frame.time);
  const slider = h("input", { type: "range", name: "frame", id: "frame", min: "0", max: String(count - 1), value: "0",
                              step: "1" });
  const label = h("span", { id: "frame-label" });
  const play = h("button", { type: "button", id: "play" }, "Play");
  let playing = false;
  const caption = (frame) => `frame ${frame + 1} of ${count}` + (times.length ? ` (time ${times[frame]})` : "");
  label.textContent = caption(0);
  async function go(frame) {
    slider.value = String(frame);
    label.textContent = caption(frame);
    await show(frame);
  }
  async function loop() {
    while (playing && !signal.aborted) {
      const began = performance.now();
      await go((Number(slider.value) + 1) % count);
      await new Promise((resolve) => setTimeout(resolve, Math.max(0, 1000 / PLAY_FPS - (performance.now() - began))));
    }
  }
  play.addEventListener("click", () => {
    playing = !playing;
    play.textContent = playing ? "Pause" : "Play";
    if (playing) guarded(loop);
  });
  slider.addEventListener("input", () => {
    playing = false;
    play.textContent = "Play";
    guarded(() => go(Number(slider.value)));
  });
  return h("span", { class: "frames", title: "the sequence's frames: play them, or drag to one" }, play, " ", slider,
           " ", label);
}

export async function viewerPage(main, { params: [id], query, signal }) {
  const schema = await openapi();
  const status = h("p", { id: "viewer-status", class: "stats" }, "loading");
  main.append(h("h1", {}, `Job ${short(id)} in 3D`), status);
  let job = null;
  await new Promise((resolve) => poll(async () => {
    job = await get(`/v1/jobs/${id}`);
    status.textContent = `job ${job.state} (${job.stage ?? ""} ${Math.floor(100 * job.progress)} %)`;
    if (ENDED.includes(job.state)) resolve();
    return ENDED.includes(job.state);
  }, 1000, signal));
  if (job.state !== "succeeded") {
    showMessage(`job ${id} ${job.state}${job.error ? `: ${job.error.message} (${job.error.code})` : ""}; nothing to draw`);
    return;
  }
  const container = h("div", { class: "viewer", id: "viewer" });
  const stats = h("p", { class: "stats", id: "viewer-stats" });
  const method = component(schema, "RetargetOptionsIn").properties.method;
  const baselines = method.examples.filter((name) => !["multiscale", "global"].includes(name));
  const fallback = schema.paths["/v1/jobs/{job_id}/display"].get.parameters
    .find((parameter) => parameter.name === "max_vertices").schema.default;
  const asked = query.get("budget") ?? String(fallback);  // ?budget=N: any budget the API takes
  const budget = select("budget", [...new Set([...BUDGETS, fallback].sort((a, b) => a - b).map(String).concat(asked))],
                        asked);
  const compare = h("select", { name: "compare", id: "compare" }, h("option", { value: "" }, "nothing"));
  const baseline = select("baseline", baselines, "root-translate");
  const toggles = Object.fromEntries(["body", "result", "source", "compare"].map((name) =>
    [name, h("input", { type: "checkbox", name: `show-${name}`, checked: name !== "source" })]));
  const sideBySide = h("input", { type: "checkbox", name: "side-by-side", checked: true });
  // a target of another mesh topology: the source body wrapped onto it, drawn over it on demand
  const residual = wrapResidual(job.metrics);
  const showWrapped = residual ? h("input", { type: "checkbox", name: "show-wrapped", checked: false }) : null;
  const toolbar = h("div", { class: "toolbar" },
    ...Object.entries(toggles).map(([name, box]) => h("label", {}, box, ` ${name}`)),
    showWrapped ? h("label", { title: `the source body wrapped onto this target, drawn over it as a wireframe ` +
                                      `(residual ${residual})` },
                    showWrapped, " wrapped mesh") : null,
    h("label", { title: "the source on its own body to the left, or its strands over the result" }, sideBySide,
      " source beside"),
    h("label", {}, "compare with ", compare),
    h("label", {}, "run baseline ", baseline, h("button", { type: "button", id: "run-baseline", onclick: () => guarded(runBaseline) }, "Run")),
    h("label", {}, "display budget ", budget, " vertices"),
    job.frames ? frameControls(job, (frame) => showFrame(frame), signal) : null,
    h("a", { href: `#/jobs/${id}` }, "job page"));
  main.append(toolbar, container, stats);
  const viewer = new Viewer(container);
  window.hairportViewer = viewer;
  signal.addEventListener("abort", () => {
    viewer.dispose();
    if (window.hairportViewer === viewer) window.hairportViewer = null;
  });
  const drawn = {};
  // a sequence job's frames: the one drawn, and those fetched (at the budget they were fetched with)
  let frame = job.frames ? 0 : null;
  const fetched = new Map();

  function frameLayers(number, vertices) {
    const key = `${number}:${vertices}`;
    if (!fetched.has(key)) {
      fetched.set(key, Promise.all([body(id, "target", number), strands(id, "result", vertices, number)]));
    }
    return fetched.get(key);
  }

  async function showFrame(number) {
    const [targetBody, result] = await frameLayers(number, Number(budget.value));
    frame = number;
    viewer.set("body", bodyMesh(targetBody));
    viewer.set("result", strandLines(result, LAYER_RGB.result));
    viewer.visible("body", toggles.body.checked);
    viewer.visible("result", toggles.result.checked);
    drawn.result = result.header;
    container.dataset.frame = String(number);
    container.dataset.inside = String(result.header.inside ?? "");
  }

  async function load() {
    const vertices = Number(budget.value);
    const [targetBody, result] = await (frame === null
      ? Promise.all([body(id, "target"), strands(id, "result", vertices)]) : frameLayers(frame, vertices));
    viewer.set("body", bodyMesh(targetBody));
    viewer.set("result", strandLines(result, LAYER_RGB.result));
    drawn.result = result.header;
    const width = viewer.box(["body"]).getSize(new THREE.Vector3()).x;
    if (toggles.source.checked) {
      const [sourceBody, source] = await Promise.all([body(id, "source"), strands(id, "source", vertices)]);
      const offset = sideBySide.checked ? -SIDE_GAP * width : 0;
      viewer.set("source-body", sideBySide.checked ? bodyMesh(sourceBody) : null, offset);
      viewer.set("source", strandLines(source, LAYER_RGB.source), offset);
      drawn.source = source.header;
    } else {
      viewer.clear("source-body");
      viewer.clear("source");
      delete drawn.source;
    }
    await loadCompare();
    viewer.visible("body", toggles.body.checked);
    viewer.visible("result", toggles.result.checked);
    const box = viewer.box(["result", "source"]);
    if (frame !== null && job.frames > 1) {  // a sequence: the camera holds its last frame's hair too
      const [, last] = await frameLayers(job.frames - 1, vertices);
      box.union(new THREE.Box3().setFromArray(last.arrays.positions));
    }
    viewer.frame(box.expandByScalar(0.05));
    container.dataset.vertices = String(result.header.drawn_vertices);
    if (frame !== null) container.dataset.frame = String(frame);
    container.dataset.loaded = "true";
  }

  async function loadCompare() {
    if (!compare.value || !toggles.compare.checked) {
      viewer.clear("compare");
      delete drawn.compare;
    } else {
      const other = await strands(compare.value, "result", Number(budget.value));
      viewer.set("compare", strandLines(other, LAYER_RGB.compare));
      drawn.compare = other.header;
    }
    stats.textContent = (viewer.software ? "software WebGL (no GPU): drawn without antialiasing. " : "") +
      Object.entries(drawn).map(([layer, header]) =>
      `${layer}: ${formatNumber(header.drawn_strands)} of ${formatNumber(header.strands)} strands, ` +
      `${formatNumber(header.drawn_vertices)} vertices (stride ${header.stride})` +
      (header.inside === null || header.inside === undefined ? "" : `, ${formatNumber(header.inside)} drawn inside the body`) +
      (header.crossing === null || header.crossing === undefined ? ""
        : `, ${formatNumber(header.crossing)} drawn segments through it`)).join("; ");
    stats.dataset.inside = drawn.compare?.inside ?? "";
    stats.dataset.crossing = drawn.compare?.crossing ?? "";
  }

  async function listComparisons(chosen = null) {
    const page = await get("/v1/jobs?state=succeeded&limit=200");
    const others = page.jobs.filter((other) => other.id !== id && other.hairstyle_id === job.hairstyle_id
                                     && other.target_character_id === job.target_character_id);
    fill(compare, h("option", { value: "" }, "nothing"), ...others.map((other) =>
      h("option", { value: other.id, selected: other.id === chosen }, `${short(other.id)} ${other.options.method}`)));
  }

  async function runBaseline() {
    const created = await post("/v1/retargets", { json: { hairstyle_id: job.hairstyle_id,
      target_character_ids: [job.target_character_id], options: { method: baseline.value } } });
    const baselineId = created.jobs[0].id;
    showMessage(`baseline ${baseline.value} started as job ${baselineId}`, "info");
    await new Promise((resolve, reject) => poll(async () => {
      const other = await get(`/v1/jobs/${baselineId}`);
      if (other.state === "succeeded") resolve();
      else if (ENDED.includes(other.state)) reject(new Error(`baseline job ${other.state}: ${other.error?.message ?? ""}`));
      return ENDED.includes(other.state);
    }, 1000, signal));
    await listComparisons(baselineId);
    toggles.compare.checked = true;
    await loadCompare();
    showMessage(`comparing with baseline ${baseline.value} (job ${short(baselineId)}, green; inside the body: red)`, "info");
  }

  for (const [name, box] of Object.entries(toggles)) {
    box.addEventListener("change", () => guarded(async () => {
      if (name === "source") await load();
      else if (name === "compare") await loadCompare();
      else viewer.visible(name, box.checked);
    }));
  }
  let wrappedLoaded = false;
  async function toggleWrapped() {
    if (showWrapped.checked && !wrappedLoaded) {
      const wrapped = await body(id, "wrapped");
      viewer.set("wrapped", wrapOverlay(wrapped));
      wrappedLoaded = true;
      container.dataset.wrappedVertices = String(wrapped.header.vertices);
    }
    viewer.visible("wrapped", showWrapped.checked);
    container.dataset.wrapped = String(showWrapped.checked);
  }

  showWrapped?.addEventListener("change", () => guarded(toggleWrapped));
  compare.addEventListener("change", () => guarded(loadCompare));
  sideBySide.addEventListener("change", () => guarded(load));
  budget.addEventListener("change", () => guarded(load));
  await listComparisons(query.get("compare"));
  await guarded(load);
}
