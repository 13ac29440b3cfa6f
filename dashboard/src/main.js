// The dashboard: a hash router over the pages, and the API key kept for the tab.
import { apiKey, get, setApiKey } from "./api.js";
import { clearMessage, showMessage } from "./ui.js";
import { charactersPage } from "./pages/characters.js";
import { hairstylesPage } from "./pages/hairstyles.js";
import { newPage } from "./pages/create.js";
import { jobsPage, jobPage } from "./pages/jobs.js";
import { batchesPage, batchPage } from "./pages/batches.js";
import { viewerPage } from "./pages/viewer.js";
import { hairlinePage } from "./pages/hairline.js";

const ROUTES = [
  [/^\/?$/, charactersPage],
  [/^\/characters$/, charactersPage],
  [/^\/hairstyles$/, hairstylesPage],
  [/^\/new$/, newPage],
  [/^\/jobs$/, jobsPage],
  [/^\/jobs\/([0-9a-f]+)$/, jobPage],
  [/^\/batches$/, batchesPage],
  [/^\/batches\/([0-9a-f]+)$/, batchPage],
  [/^\/view\/([0-9a-f]+)$/, viewerPage],
  [/^\/hairline\/([0-9a-f]+)$/, hairlinePage],
];

let current = null;
let keyProblem = null;

async function route() {
  current?.abort();
  current = new AbortController();
  const path = location.hash.replace(/^#/, "").split("?")[0];
  const query = new URLSearchParams(location.hash.split("?")[1] ?? "");
  const main = document.getElementById("page");
  main.replaceChildren();
  clearMessage();
  for (const link of document.querySelectorAll("nav a")) {
    link.classList.toggle("active", path.startsWith(link.getAttribute("href").slice(1)));
  }
  const match = ROUTES.map(([pattern, page]) => [pattern.exec(path), page]).find(([found]) => found);
  if (!match) {
    showMessage(`no page ${path}`);
    return;
  }
  const [found, page] = match;
  if (!apiKey()) showMessage("Enter an API key (top right) to use hairport.", "info");
  else if (keyProblem) showMessage(keyProblem);
  try {
    await page(main, { params: found.slice(1), query, signal: current.signal });
  } catch (error) {
    showMessage(error.message ?? String(error));
  }
}

async function useKey(event) {
  event.preventDefault();
  const input = document.getElementById("api-key");
  setApiKey(input.value.trim());
  input.value = "";
  await checkKey();
  route();
}

async function checkKey() {
  const state = document.getElementById("key-state");
  if (!apiKey()) {
    state.textContent = "no key";
    keyProblem = null;
    return;
  }
  try {
    await get("/v1/jobs?limit=1");
    state.textContent = "key accepted";
    state.dataset.state = "ok";
    keyProblem = null;
  } catch (error) {
    state.textContent = "key refused";
    state.dataset.state = "refused";
    keyProblem = error.message;
  }
}

document.getElementById("key-form").addEventListener("submit", useKey);
window.addEventListener("hashchange", route);
checkKey().then(route);
