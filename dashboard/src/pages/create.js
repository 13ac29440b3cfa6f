// A new retarget (one hairstyle, its targets) or batch (hairstyles x targets): options within their documented
// ranges, a hairline preset with an amount, and the output format.
import { openapi, post } from "../api.js";
import { guarded, h } from "../ui.js";
import { characterChoices } from "./characters.js";
import { hairstyleChoices } from "./hairstyles.js";
import { component, numberField, numbers, property, select } from "./forms.js";

const OPTIONS = "RetargetOptionsIn";
const HAIRLINE = "HairlineIn";
const SEQUENCE = "SequenceIn";

function checkboxes(name, choices) {
  return h("div", { class: "grid", "data-name": name }, choices.map(([value, label]) =>
    h("label", {}, h("input", { type: "checkbox", name, value }), label)));
}

const checked = (form, name) => [...form.querySelectorAll(`input[name=${name}]:checked`)].map((box) => box.value);

/** The request's options object: the numbers typed and the choices made. */
export function optionsOf(form) {
  return { ...numbers(form.querySelector("fieldset.options")), method: form.elements.method.value,
           qp_backend: form.elements.qp_backend.value, wrap: form.elements.wrap.value };
}

export function hairlineOf(form) {
  const preset = form.elements.hairline_preset.value;
  if (!preset) return null;
  return { preset, amount: Number(form.elements.hairline_amount.value) };
}

export async function newPage(main, { query }) {
  const schema = await openapi();
  const [hairstyles, characters] = await Promise.all([hairstyleChoices(), characterChoices()]);
  const numeric = Object.entries(component(schema, OPTIONS).properties)
    .filter(([, spec]) => ["number", "integer"].includes((spec.anyOf?.find((item) => item.type !== "null") ?? spec).type))
    .map(([field]) => numberField(schema, OPTIONS, field));
  const method = component(schema, OPTIONS).properties.method;
  const wrap = property(schema, OPTIONS, "wrap");
  const presets = property(schema, HAIRLINE, "preset").enum;
  const amount = property(schema, HAIRLINE, "amount");
  const amountLabel = h("output", { name: "amount_shown" }, amount.default);
  const targetOrder = [];  // the targets in the order they were checked: a sequence of characters' frames
  // novalidate: out-of-range values reach the API, whose message names the field and its range
  const form = h("form", { class: "card", id: "retarget-form", novalidate: true },
    h("h2", {}, "Hairstyles"), checkboxes("hairstyle", hairstyles),
    h("h2", {}, "Target characters"), checkboxes("target", characters),
    h("fieldset", { class: "options" }, h("legend", {}, "Options (empty: the default)"),
      h("label", { title: method.description }, "method", select("method", method.examples, method.default)),
      h("label", {}, "QP backend", select("qp_backend", component(schema, OPTIONS).properties.qp_backend.enum,
                                          component(schema, OPTIONS).properties.qp_backend.default)),
      h("label", { title: wrap.description }, "wrap", select("wrap", wrap.enum, wrap.default),
        h("span", { class: "hint", id: "wrap-hint" }, `targets of another mesh topology are wrapped: ${wrap.default}`)),
      numeric),
    h("fieldset", {}, h("legend", {}, "Hairline"),
      h("label", {}, "preset", select("hairline_preset", ["", ...presets], query.get("preset") ?? "", { "": "none" })),
      h("label", {}, "amount", h("input", {
        type: "range", name: "hairline_amount", min: amount.minimum, max: amount.maximum, step: 0.05,
        value: amount.default, oninput: (event) => { amountLabel.value = event.target.value; } }), amountLabel),
      h("p", { class: "hint" }, "To draw a hairline, open a finished job and choose Draw hairline.")),
    sequenceFields(schema, targetOrder),
    h("label", { title: property(schema, "RetargetIn", "output_format").description }, "Output format",
      select("output_format", ["", ...property(schema, "RetargetIn", "output_format").enum], "",
             { "": "default" })),
    h("button", { type: "submit" }, "Start"));
  main.append(h("h1", {}, "New retarget or batch"), form);
  for (const id of query.getAll("hairstyle")) form.querySelector(`input[name=hairstyle][value="${id}"]`)?.click();
  form.querySelector("[data-name=target]").addEventListener("change", (event) => {
    const at = targetOrder.indexOf(event.target.value);
    if (at >= 0) targetOrder.splice(at, 1);
    if (event.target.checked) targetOrder.push(event.target.value);
    form.querySelector("#frame-order").textContent = targetOrder.length
      ? `frames in the order checked: ${targetOrder.map((id, k) => `${k}: ${id.slice(0, 8)}`).join(", ")}` : "";
  });

  form.addEventListener("submit", (event) => {
    event.preventDefault();
    guarded(async () => {
      const hairstyleIds = checked(form, "hairstyle");
      const targetIds = checked(form, "target");
      if (!hairstyleIds.length || !targetIds.length) throw new Error("choose at least one hairstyle and one target");
      const body = { options: optionsOf(form), hairline: hairlineOf(form), sequence: sequenceOf(form) };
      if (form.elements.output_format.value) body.output_format = form.elements.output_format.value;
      const framesOfCharacters = body.sequence?.frames_from === "characters";
      if (hairstyleIds.length === 1 && (targetIds.length === 1 || framesOfCharacters)) {
        const created = await post("/v1/retargets", { json: { hairstyle_id: hairstyleIds[0],
          target_character_ids: framesOfCharacters ? targetOrder : targetIds, ...body } });
        location.hash = `#/jobs/${created.jobs[0].id}`;
      } else if (framesOfCharacters) {
        throw new Error("the frames of a sequence of characters take one hairstyle");
      } else {
        const batch = await post("/v1/batches", { json: { hairstyle_ids: hairstyleIds, target_character_ids: targetIds, ...body } });
        location.hash = `#/batches/${batch.id}`;
      }
    });
  });
}

/** The sequence fieldset: none, each target's own animation, or the targets in order as frames. */
function sequenceFields(schema, targetOrder) {
  const kinds = property(schema, SEQUENCE, "frames_from");
  const frames = property(schema, SEQUENCE, "frames");
  return h("fieldset", { class: "sequence" }, h("legend", {}, "Sequence (hair that follows a changing body)"),
    h("label", { title: kinds.description }, "frames from",
      select("frames_from", ["", ...kinds.enum], "", { "": "none: one body per target" })),
    h("label", { title: frames.description }, "frames",
      h("input", { type: "text", name: "frames", placeholder: "START:END[:STEP], e.g. 0:48" })),
    numberField(schema, SEQUENCE, "temporal"),
    h("p", { class: "hint", id: "frame-order" }, ""));
}

/** The request's sequence, or null. */
export function sequenceOf(form) {
  const kind = form.elements.frames_from.value;
  if (!kind) return null;
  const sequence = { frames_from: kind, ...numbers(form.querySelector("fieldset.sequence")) };
  if (form.elements.frames.value.trim()) sequence.frames = form.elements.frames.value.trim();
  return sequence;
}
