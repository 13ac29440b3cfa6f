// Jobs: the caller's jobs with live progress; a job's page with its state, timings, metrics, downloads in every
// format, cancel and retry.
import { download, get, openapi, post, remove } from "../api.js";
import { fill, formatNumber, guarded, h, poll, short, showMessage, stateCell, table, when } from "../ui.js";
import { property } from "./forms.js";

export const ENDED = ["succeeded", "failed", "cancelled"];

/** A job's progress: where a failed or cancelled job stopped, not 100 %. */
export function progressCell(job) {
  const progress = job.state === "succeeded" ? 1 : job.progress;
  return h("td", {}, h("progress", { max: 1, value: progress }), ` ${Math.floor(100 * progress)} %`);
}

export async function jobsPage(main, { signal }) {
  const list = h("section", { id: "jobs" });
  main.append(h("h1", {}, "Jobs"), list);
  poll(async () => {
    const page = await get("/v1/jobs?limit=100");
    fill(list, table(["job", "state", "stage", "progress", "hairstyle", "target", "created"],
      page.jobs.map((job) => h("tr", { "data-id": job.id },
        h("td", {}, h("a", { href: `#/jobs/${job.id}` }, h("code", {}, short(job.id)))), h("td", {}, stateCell(job.state)),
        h("td", {}, job.stage ?? ""), progressCell(job), h("td", {}, h("code", {}, short(job.hairstyle_id))),
        h("td", {}, h("code", {}, short(job.target_character_id))), h("td", {}, when(job.created_at))))));
    return false;
  }, 2000, signal);
}

/** Start the same pair with the same options again (a failed or cancelled job, or to run it anew). */
export async function retry(job) {
  const options = Object.fromEntries(Object.entries(job.options).filter(([, value]) => value !== null));
  const created = await post("/v1/retargets", { json: {
    hairstyle_id: job.hairstyle_id, target_character_ids: [job.target_character_id], options, hairline: job.hairline,
    output_format: job.output_format, flag_guides: job.flag_guides } });
  return created.jobs[0];
}

const MM_PER_M = 1000;

/** The wrap's residual (metrics.wrap.residual_m, metres) in millimetres, or null for a job that wrapped nothing. */
export function wrapResidual(metrics) {
  const residual = metrics?.wrap?.residual_m;
  if (!residual) return null;
  const mm = (metres) => `${(MM_PER_M * metres).toFixed(2)} mm`;
  return `mean ${mm(residual.mean)}, p95 ${mm(residual.p95)}`;
}

function metricRows(metrics) {
  const rows = Object.entries(metrics ?? {}).filter(([, value]) => typeof value !== "object")
    .map(([name, value]) => h("tr", {}, h("th", {}, name), h("td", {}, formatNumber(value))));
  const residual = wrapResidual(metrics);
  // the target had another mesh topology: the source body was wrapped onto it, this far from its surface
  if (residual) rows.push(h("tr", { id: "wrap-residual" }, h("th", {}, "wrap residual"), h("td", {}, residual)));
  return rows;
}

export async function jobPage(main, { params: [id], signal }) {
  const schema = await openapi();
  const formats = property(schema, "RetargetIn", "output_format").enum;
  const head = h("section", { id: "job" });
  const actions = h("div", { class: "toolbar" });
  const downloads = h("section", { class: "card", id: "downloads" });
  const details = h("section", { id: "details" });
  main.append(h("h1", {}, `Job ${short(id)}`), head, actions, downloads, details);
  let shown = null;
  poll(async () => {
    const job = await get(`/v1/jobs/${id}`);
    fill(head, table(["state", "stage", "progress", "message", "hairstyle", "target", "created", "finished"], [
      h("tr", {}, h("td", {}, stateCell(job.state)), h("td", {}, job.stage ?? ""), progressCell(job),
        h("td", {}, job.error ? `${job.error.message} (${job.error.code})` : job.message ?? ""),
        h("td", {}, h("code", {}, short(job.hairstyle_id))), h("td", {}, h("code", {}, short(job.target_character_id))),
        h("td", {}, when(job.created_at)), h("td", {}, when(job.finished_at)))]));
    if (shown !== job.state) {
      shown = job.state;
      render(job);
    }
    return ENDED.includes(job.state);
  }, 1000, signal);

  function render(job) {
    fill(actions, 
      ENDED.includes(job.state) ? null : h("button", { id: "cancel", onclick: () => guarded(async () => { await remove(`/v1/jobs/${id}`); }) }, "Cancel"),
      ENDED.includes(job.state) ? h("button", { id: "retry", onclick: () => guarded(async () => {
        const again = await retry(job);
        location.hash = `#/jobs/${again.id}`;
      }) }, "Retry") : null,
      job.state === "succeeded" ? h("a", { href: `#/view/${id}`, id: "open-viewer" }, "Open in viewer") : null,
      job.state === "succeeded" ? h("a", { href: `#/hairline/${id}`, id: "draw-hairline" }, "Draw hairline") : null);
    fill(downloads, );
    if (job.state === "succeeded") {
      downloads.append(h("h2", {}, "Downloads"), h("div", { class: "toolbar" },
        formats.map((format) => h("button", { "data-format": format, onclick: () => guarded(async () => {
          await download(`/v1/jobs/${id}/result?format=${format}`, `${id}.${format}`);
          showMessage(`downloaded ${id}.${format}`, "info");
        }) }, format)),
        h("button", { onclick: () => guarded(() => download(`/v1/jobs/${id}/report`, `${id}.json`)) }, "report"),
        h("button", { onclick: () => guarded(() => download(`/v1/jobs/${id}/preview.png`, `${id}.png`)) }, "preview")));
    }
    fill(details, 
      job.timings ? h("section", {}, h("h2", {}, "Timings (s)"), table(["stage", "seconds"],
        Object.entries(job.timings).map(([stage, seconds]) => h("tr", {}, h("td", {}, stage), h("td", {}, formatNumber(seconds)))))) : null,
      job.metrics ? h("section", {}, h("h2", {}, "Metrics"), h("table", { id: "metrics" }, metricRows(job.metrics))) : null,
      h("section", {}, h("h2", {}, "Options"), h("pre", {}, JSON.stringify({ options: job.options, hairline: job.hairline }, null, 1))));
  }
}
