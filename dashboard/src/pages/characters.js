// Characters: upload a body mesh (skeleton, units and axes optional); the caller's characters with thumbnails.
import { decodeDisplay, get, openapi, post } from "../api.js";
import { fill, formatNumber, guarded, h, short, showMessage, table, when } from "../ui.js";
import { thumbnail } from "../scene.js";
import { enumOf, select } from "./forms.js";

export async function charactersPage(main) {
  const schema = await openapi();
  const form = h("form", { class: "card", id: "character-form" },
    h("h2", {}, "Upload a character"),
    h("label", {}, "Body mesh", h("input", { type: "file", name: "mesh", required: true })),
    h("label", {}, "Skeleton JSON (optional)", h("input", { type: "file", name: "skeleton" })),
    h("label", {}, "Units", select("units", enumOf(schema, "Body_create_character_v1_characters_post", "units"), "auto")),
    h("label", {}, "Up axis", select("up_axis", enumOf(schema, "Body_create_character_v1_characters_post", "up_axis"), "auto")),
    h("label", {}, "Front axis", select("front_axis", enumOf(schema, "Body_create_character_v1_characters_post", "front_axis"), "auto")),
    h("button", { type: "submit" }, "Upload"));
  const list = h("section", { id: "characters" });
  main.append(h("h1", {}, "Characters"), form, list);

  form.addEventListener("submit", (event) => {
    event.preventDefault();
    guarded(async () => {
      const data = new FormData(form);
      for (const name of ["skeleton"]) if (!data.get(name)?.size) data.delete(name);
      const character = await post("/v1/characters", { form: data });
      showMessage(`character ${character.id} stored (${formatNumber(character.vertices)} vertices)`, "info");
      form.reset();
      await refresh(list);
    });
  });
  await refresh(list);
}

async function refresh(list) {
  const page = await get("/v1/characters?limit=200");
  const rows = page.characters.map((character) => {
    const picture = h("img", { class: "thumb", alt: `character ${character.id}` });
    drawThumbnail(character.id, picture);
    return h("tr", { "data-id": character.id },
      h("td", {}, picture), h("td", {}, h("code", {}, short(character.id))),
      h("td", {}, formatNumber(character.vertices)), h("td", {}, formatNumber(character.faces)),
      h("td", {}, character.has_skeleton ? `${character.bones.length} bones` : "no rig"),
      h("td", {}, character.units), h("td", {}, character.up_axis), h("td", {}, when(character.created_at)));
  });
  fill(list, h("h2", {}, `Your characters (${page.total})`),
    table(["", "id", "vertices", "faces", "skeleton", "units", "up", "uploaded"], rows));
}

const thumbnails = new Map();
async function drawThumbnail(id, image) {
  try {
    if (!thumbnails.has(id)) {
      thumbnails.set(id, get(`/v1/characters/${id}/mesh`, { as: "buffer" }).then((buffer) => thumbnail(decodeDisplay(buffer))));
    }
    image.src = await thumbnails.get(id);
  } catch (error) {
    thumbnails.delete(id);
    image.alt = `no picture: ${error.message}`;
  }
}

/** Options of a <select> listing the caller's characters. */
export async function characterChoices() {
  const page = await get("/v1/characters?limit=200");
  return page.characters.map((character) => [character.id, `${short(character.id)} (${formatNumber(character.vertices)} v${character.has_skeleton ? ", rigged" : ""})`]);
}
