// Form fields built from the API's OpenAPI document: choices, ranges and defaults have one definition.
import { h } from "../ui.js";

/** A component schema of the document, `$ref`s and `anyOf: [X, null]` followed. */
export function component(schema, name) {
  return schema.components.schemas[name];
}

function resolve(schema, node) {
  if (!node) return node;
  if (node.$ref) return resolve(schema, schema.components.schemas[node.$ref.split("/").pop()]);
  if (node.anyOf) {
    const real = node.anyOf.find((item) => item.type !== "null");
    return { ...node, ...resolve(schema, real), anyOf: undefined };
  }
  return node;
}

export function property(schema, componentName, field) {
  return resolve(schema, component(schema, componentName).properties[field]);
}

/** The choices of an enum field (a form field or a body field). */
export function enumOf(schema, componentName, field) {
  return property(schema, componentName, field).enum.filter((choice) => choice !== "");
}

export function select(name, choices, chosen, labels = {}) {
  return h("select", { name }, choices.map((choice) => h("option", { value: choice, selected: choice === chosen },
                                                           labels[choice] ?? choice)));
}

/** A number input bounded and described as the schema's field is (min, max, default, description). */
export function numberField(schema, componentName, field) {
  const spec = property(schema, componentName, field);
  const integer = spec.type === "integer";
  const input = h("input", {
    type: "number", name: field, step: integer ? "1" : "any",
    min: spec.minimum ?? spec.exclusiveMinimum, max: spec.maximum ?? spec.exclusiveMaximum,
    value: spec.default ?? "", placeholder: spec.default === undefined || spec.default === null ? "default" : undefined,
  });
  input.dataset.kind = integer ? "integer" : "number";
  return h("label", { title: spec.description ?? "" }, field, input,
           h("span", { class: "hint" }, rangeText(spec)));
}

function rangeText(spec) {
  const low = spec.minimum ?? spec.exclusiveMinimum;
  const high = spec.maximum ?? spec.exclusiveMaximum;
  if (low === undefined && high === undefined) return "";
  return `${low ?? "-inf"} to ${high ?? "inf"}`;
}

/** The values of a form's number inputs as an object (empty inputs left out: the API's default applies). */
export function numbers(form) {
  const values = {};
  for (const input of form.querySelectorAll("input[type=number]")) {
    if (input.value === "" || input.dataset.ignore) continue;
    values[input.name] = input.dataset.kind === "integer" ? parseInt(input.value, 10) : Number(input.value);
  }
  return values;
}
