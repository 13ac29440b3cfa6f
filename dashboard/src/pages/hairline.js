// Draw a front hairline on a job's target head: its current hairline and corners shown, a preset to start
// from (with its amount), points clicked on the head from ear to ear and dragged, the curve through them
// projected on the head; sent as the hairline curve the API accepts (in the groom's axes), or as the preset.
import { decodeDisplay, get, openapi, post } from "../api.js";
import { guarded, h, short, showMessage } from "../ui.js";
import { THREE, Viewer, bodyMesh } from "../scene.js";
import { property, select } from "./forms.js";

const SAMPLES = 64;            // points of the curve sent
const PRESET_CONTROLS = 7;     // control points a preset starts with
const CLICK_SLOP_PX = 4;       // a pointer that moved more than this is orbiting, not clicking
const COLORS = { current: 0x2d6cdf, curve: 0x1b9e4b, control: 0xff8c00, end: 0x555555 };

const vector = (point) => new THREE.Vector3(...point);

function polyline(points, color, width = 1) {
  const geometry = new THREE.BufferGeometry().setFromPoints(points);
  const line = new THREE.Line(geometry, new THREE.LineBasicMaterial({ color, linewidth: width, depthTest: false }));
  line.renderOrder = 2;
  return line;
}

function markers(points, color, radius) {
  const group = new THREE.Group();
  for (const point of points) {
    const ball = new THREE.Mesh(new THREE.SphereGeometry(radius, 12, 8), new THREE.MeshBasicMaterial({ color, depthTest: false }));
    ball.position.copy(point);
    ball.renderOrder = 3;
    group.add(ball);
  }
  return group;
}

export async function hairlinePage(main, { params: [id] }) {
  const schema = await openapi();
  const [job, hairline, targetBody] = await Promise.all([
    get(`/v1/jobs/${id}`), get(`/v1/jobs/${id}/hairline`),
    get(`/v1/jobs/${id}/body?layer=target`, { as: "buffer" }).then(decodeDisplay)]);
  const presets = property(schema, "HairlineIn", "preset").enum;
  const amountSpec = property(schema, "HairlineIn", "amount");
  const current = hairline.points.map(vector);
  const ends = [current[0], current[current.length - 1]];
  const centre = ends[0].clone().add(ends[1]).multiplyScalar(0.5);  // between the ears: inside the head
  const span = ends[0].distanceTo(ends[1]);

  const preset = select("preset", ["", ...presets], "", { "": "none (click points)" });
  const amount = h("input", { type: "range", name: "amount", min: amountSpec.minimum, max: amountSpec.maximum, step: 0.05, value: 1 });
  const state = h("p", { class: "stats", id: "hairline-state" });
  const container = h("div", { class: "viewer", id: "hairline-viewer" });
  const submit = h("button", { id: "submit-hairline", type: "button" }, "Retarget with this hairline");
  main.append(h("h1", {}, `Draw a hairline on job ${short(id)}'s target`),
    h("p", {}, "Blue: the current front hairline (grey: its ends, above the ears). Click points on the head from ear ",
      "to ear, drag them to adjust; green is the curve through them, projected on the head."),
    h("div", { class: "toolbar" }, h("label", {}, "start from preset ", preset), h("label", {}, "amount ", amount),
      h("button", { type: "button", id: "clear-hairline", onclick: () => { controls = []; modified = true; redraw(); } }, "Clear points"),
      submit),
    container, state);

  const viewer = new Viewer(container);
  const head = bodyMesh(targetBody);
  viewer.set("body", head);
  viewer.set("current", polyline(current, COLORS.current));
  const corners = hairline.turning_points.map((index) => current[index]);
  viewer.set("corners", markers(corners, COLORS.end, span * 0.012));
  const focus = new THREE.Box3().setFromPoints(current).expandByScalar(span * 0.35);
  viewer.frame(focus);

  let controls = [];
  let modified = false;
  let curve = [];

  function ordered() {  // ends first and last, the clicked points between them in order across the head
    const across = ends[1].clone().sub(ends[0]);
    const along = (point) => point.clone().sub(ends[0]).dot(across);
    return [ends[0], ...[...controls].sort((a, b) => along(a) - along(b)), ends[1]];
  }

  const raycaster = new THREE.Raycaster();
  function onHead(point) {  // the head's surface point seen from outside along the ray from its centre
    const direction = point.clone().sub(centre).normalize();
    raycaster.set(centre.clone().addScaledVector(direction, span * 2), direction.clone().negate());
    return raycaster.intersectObject(head, false)[0]?.point ?? point;
  }

  function redraw() {
    const points = ordered();
    curve = new THREE.CatmullRomCurve3(points, false, "centripetal").getSpacedPoints(SAMPLES - 1).map(onHead);
    curve[0] = ends[0].clone();
    curve[curve.length - 1] = ends[1].clone();
    viewer.set("curve", controls.length ? polyline(curve, COLORS.curve) : null);
    viewer.set("controls", markers(controls, COLORS.control, span * 0.015));
    state.textContent = preset.value && !modified
      ? `preset ${preset.value} at amount ${amount.value}` : `${controls.length} points drawn`;
    state.dataset.points = String(controls.length);
  }

  function fromPreset() {
    controls = [];
    modified = !preset.value;
    if (preset.value) {
      const target = hairline.presets[preset.value].map(vector);
      const share = Number(amount.value);
      for (let k = 1; k <= PRESET_CONTROLS; k++) {
        const index = Math.round((k * (current.length - 1)) / (PRESET_CONTROLS + 1));
        controls.push(onHead(current[index].clone().lerp(target[index], share)));
      }
    }
    redraw();
  }
  preset.addEventListener("change", fromPreset);
  amount.addEventListener("input", fromPreset);

  // clicks add points, drags of a point move it (the camera stays put meanwhile), other drags orbit
  const canvas = viewer.renderer.domElement;
  const pointer = new THREE.Vector2();
  let pressed = null;
  let dragging = -1;
  function cast(event) {
    const rect = canvas.getBoundingClientRect();
    pointer.set(((event.clientX - rect.left) / rect.width) * 2 - 1, -((event.clientY - rect.top) / rect.height) * 2 + 1);
    raycaster.setFromCamera(pointer, viewer.camera);
  }
  canvas.addEventListener("pointerdown", (event) => {
    pressed = { x: event.clientX, y: event.clientY };
    cast(event);
    const group = viewer.groups.get("controls");
    const hit = group ? raycaster.intersectObjects(group.children, true)[0] : null;
    if (hit) {
      dragging = group.children[0].children.indexOf(hit.object);
      viewer.controls.enabled = false;
    }
  });
  canvas.addEventListener("pointermove", (event) => {
    if (dragging < 0) return;
    cast(event);
    const hit = raycaster.intersectObject(head, false)[0];
    if (hit) {
      controls[dragging] = hit.point.clone();
      modified = true;
      redraw();
    }
  });
  canvas.addEventListener("pointerup", (event) => {
    const moved = pressed && Math.hypot(event.clientX - pressed.x, event.clientY - pressed.y) > CLICK_SLOP_PX;
    if (dragging < 0 && !moved) {
      cast(event);
      const hit = raycaster.intersectObject(head, false)[0];
      if (hit) {
        controls.push(hit.point.clone());
        modified = true;
        redraw();
      }
    }
    dragging = -1;
    viewer.controls.enabled = true;
    pressed = null;
  });

  submit.addEventListener("click", () => guarded(async () => {
    let edit;
    if (preset.value && !modified) {
      edit = { preset: preset.value, amount: Number(amount.value) };
    } else {
      if (!controls.length) throw new Error("click at least one point on the head (or choose a preset)");
      // hairport's frame -> the groom's axes: p_groom = R^T p
      const rotation = new THREE.Matrix3().set(...hairline.groom_rotation.flat()).transpose();
      edit = { curve: { units: "m", points: curve.map((point) => point.clone().applyMatrix3(rotation).toArray()) } };
    }
    const options = Object.fromEntries(Object.entries(job.options).filter(([, value]) => value !== null));
    const created = await post("/v1/retargets", { json: { hairstyle_id: job.hairstyle_id,
      target_character_ids: [job.target_character_id], options, hairline: edit, output_format: job.output_format } });
    showMessage(`hairline sent: job ${created.jobs[0].id}`, "info");
    location.hash = `#/view/${created.jobs[0].id}`;
  }));

  // where the current hairline's points (raised by `lift` metres toward the crown) are on the screen: for
  // scripted use of the page (the browser tests click there)
  const onScreen = (point) => {
    const rect = canvas.getBoundingClientRect();
    const projected = point.clone().project(viewer.camera);
    return [rect.left + ((projected.x + 1) / 2) * rect.width, rect.top + ((1 - projected.y) / 2) * rect.height];
  };
  window.hairportHairline = {
    viewer,
    screenPoints(count, lift) {
      const picks = [];
      for (let k = 1; k <= count; k++) {
        const point = current[Math.round((k * (current.length - 1)) / (count + 1))].clone();
        point.y += lift;
        picks.push(onScreen(point));
      }
      return picks;
    },
    controlScreenPoints: () => controls.map(onScreen),
  };
  redraw();
}
