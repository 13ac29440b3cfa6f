// Hairstyles: upload a hair file for a source character; preprocessing state, guides and k.
import { get, openapi, post } from "../api.js";
import { fill, formatNumber, guarded, h, poll, short, showMessage, stateCell, table, when } from "../ui.js";
import { characterChoices } from "./characters.js";
import { enumOf, numberField, numbers, select } from "./forms.js";

const FORM = "Body_create_hairstyle_v1_hairstyles_post";

export async function hairstylesPage(main, { signal }) {
  const schema = await openapi();
  const characters = await characterChoices();
  const form = h("form", { class: "card", id: "hairstyle-form" },
    h("h2", {}, "Upload a hairstyle"),
    h("label", {}, "Hair file", h("input", { type: "file", name: "hair", required: true })),
    h("label", {}, "Made for character",
      h("select", { name: "source_character_id", required: true },
        characters.map(([id, label]) => h("option", { value: id }, label)))),
    h("label", {}, "Units", select("units", enumOf(schema, FORM, "units"), "auto")),
    numberField(schema, FORM, "guides"), numberField(schema, FORM, "k"),
    h("button", { type: "submit" }, "Upload"));
  if (!characters.length) form.prepend(h("p", { class: "hint" }, "Upload its character first (Characters)."));
  const list = h("section", { id: "hairstyles" });
  main.append(h("h1", {}, "Hairstyles"), form, list);

  form.addEventListener("submit", (event) => {
    event.preventDefault();
    guarded(async () => {
      const data = new FormData();
      data.append("hair", form.elements.hair.files[0]);
      data.append("source_character_id", form.elements.source_character_id.value);
      data.append("units", form.elements.units.value);
      for (const [name, value] of Object.entries(numbers(form))) data.append(name, value);
      const hairstyle = await post("/v1/hairstyles", { form: data });
      showMessage(`hairstyle ${hairstyle.id}: ${formatNumber(hairstyle.strands)} strands, preprocessing ${hairstyle.preprocessing.state}`, "info");
      form.reset();
    });
  });
  poll(async () => {
    const page = await get("/v1/hairstyles?limit=200");
    fill(list, h("h2", {}, `Your hairstyles (${page.total})`), table(
      ["id", "character", "strands", "particles", "format", "guides", "k", "preprocessing", "uploaded"],
      page.hairstyles.map((hairstyle) => h("tr", { "data-id": hairstyle.id },
        h("td", {}, h("code", {}, short(hairstyle.id))), h("td", {}, h("code", {}, short(hairstyle.source_character_id))),
        h("td", {}, formatNumber(hairstyle.strands)), h("td", {}, formatNumber(hairstyle.particles)),
        h("td", {}, hairstyle.format), h("td", {}, hairstyle.options.guides), h("td", {}, hairstyle.options.k),
        h("td", { title: hairstyle.preprocessing.error?.message ?? "" }, stateCell(hairstyle.preprocessing.state),
          hairstyle.preprocessing.error ? ` ${hairstyle.preprocessing.error.message}` : ""),
        h("td", {}, when(hairstyle.created_at))))));
    return false;  // keeps polling while the page is open: new uploads show their preprocessing
  }, 2000, signal);
}

/** The caller's hairstyles, for choosing. */
export async function hairstyleChoices() {
  const page = await get("/v1/hairstyles?limit=200");
  return page.hairstyles.map((hairstyle) => [hairstyle.id,
    `${short(hairstyle.id)} (${formatNumber(hairstyle.strands)} strands, ${hairstyle.preprocessing.state})`]);
}
