// Batches: the caller's batches with progress; a batch's page with its jobs, cancel, results zip.
import { download, get, remove } from "../api.js";
import { fill, guarded, h, poll, short, stateCell, table, when } from "../ui.js";
import { progressCell } from "./jobs.js";

export async function batchesPage(main, { signal }) {
  const list = h("section", { id: "batches" });
  main.append(h("h1", {}, "Batches"), list);
  poll(async () => {
    const page = await get("/v1/batches?limit=100");
    fill(list, table(["batch", "state", "progress", "jobs", "created"], page.batches.map((batch) =>
      h("tr", { "data-id": batch.id }, h("td", {}, h("a", { href: `#/batches/${batch.id}` }, h("code", {}, short(batch.id)))),
        h("td", {}, stateCell(batch.state)), progressCell({ state: batch.state === "done" ? "succeeded" : batch.state, progress: batch.progress }),
        h("td", {}, Object.entries(batch.counts).filter(([, count]) => count).map(([state, count]) => `${count} ${state}`).join(", ")),
        h("td", {}, when(batch.created_at))))));
    return false;
  }, 2000, signal);
}

export async function batchPage(main, { params: [id], signal }) {
  const head = h("section", { id: "batch" });
  const jobs = h("section", { id: "batch-jobs" });
  const actions = h("div", { class: "toolbar" });
  main.append(h("h1", {}, `Batch ${short(id)}`), head, actions, jobs);
  poll(async () => {
    const batch = await get(`/v1/batches/${id}`);
    const percent = Math.floor(100 * batch.progress);
    fill(head, h("p", {}, stateCell(batch.state), " ",
      h("progress", { id: "batch-progress", max: 1, value: batch.progress }), h("span", { id: "batch-percent" }, ` ${percent} %`), " ",
      Object.entries(batch.counts).filter(([, count]) => count).map(([state, count]) => `${count} ${state}`).join(", ")));
    fill(actions, 
      batch.state !== "done" ? h("button", { onclick: () => guarded(() => remove(`/v1/batches/${id}`)) }, "Cancel") : null,
      batch.state === "done" ? h("button", { id: "batch-results", onclick: () => guarded(() => download(`/v1/batches/${id}/results`, `${id}.zip`)) }, "Download all results (zip)") : null);
    fill(jobs, table(["job", "hairstyle", "target", "state", "progress", ""], batch.jobs.map((job) =>
      h("tr", { "data-id": job.id }, h("td", {}, h("a", { href: `#/jobs/${job.id}` }, h("code", {}, short(job.id)))),
        h("td", {}, h("code", {}, short(job.hairstyle_id))), h("td", {}, h("code", {}, short(job.target_character_id))),
        h("td", { title: job.error?.message ?? "" }, stateCell(job.state), job.error ? ` ${job.error.message}` : ""), progressCell(job),
        h("td", {}, job.state === "succeeded" ? h("a", { href: `#/view/${job.id}` }, "view") : "")))));
    return batch.state === "done";
  }, 1000, signal);
}
