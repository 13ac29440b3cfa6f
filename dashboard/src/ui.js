// Small DOM helpers shared by the pages.

/** An element: h("a", {href: "#/"}, "text", child...). Attributes starting with "on" are listeners. */
export function h(tag, attributes = {}, ...children) {
  const element = document.createElement(tag);
  for (const [name, value] of Object.entries(attributes ?? {})) {
    if (value === undefined || value === null || value === false) continue;
    if (name.startsWith("on")) element.addEventListener(name.slice(2), value);
    else if (name === "class") element.className = value;
    else if (name in element && typeof value !== "string") element[name] = value;
    else element.setAttribute(name, value === true ? "" : value);
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    element.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return element;
}

/** Replace an element's children (null, undefined and false skipped, as h() does). */
export function fill(element, ...children) {
  element.replaceChildren(...children.flat().filter((child) => child !== null && child !== undefined && child !== false));
  return element;
}

const messageBox = () => document.getElementById("message");

/** Show an error (an ApiError's message names the API's code) or an info line above the page. */
export function showMessage(text, kind = "error") {
  const box = messageBox();
  box.textContent = text;
  box.className = kind === "info" ? "info" : "";
  box.hidden = false;
}

export function clearMessage() {
  messageBox().hidden = true;
}

/** Run an action; its error is shown, never thrown into the console only. */
export async function guarded(action) {
  try {
    clearMessage();
    return await action();
  } catch (error) {
    showMessage(error.message ?? String(error));
    return undefined;
  }
}

export const when = (seconds) => (seconds ? new Date(seconds * 1000).toLocaleString() : "");
export const short = (id) => (id ? id.slice(0, 10) : "");
export const stateCell = (state) => h("span", { class: `state-${state}`, "data-state": state }, state);

export function table(headings, rows) {
  return h("table", {}, h("thead", {}, h("tr", {}, headings.map((text) => h("th", {}, text)))),
           h("tbody", {}, rows));
}

/** Calls `tick` every `ms` until it returns true or the page changes (the router aborts `signal`). */
export function poll(tick, ms, signal) {
  let timer = null;
  const run = async () => {
    if (signal.aborted) return;
    let done = false;
    try {
      done = await tick();
    } catch (error) {
      showMessage(error.message ?? String(error));
    }
    if (!done && !signal.aborted) timer = setTimeout(run, ms);
  };
  signal.addEventListener("abort", () => clearTimeout(timer));
  run();
}

export function formatNumber(value) {
  if (typeof value !== "number") return String(value);
  if (Number.isInteger(value)) return value.toLocaleString();
  return Math.abs(value) >= 1e-3 && Math.abs(value) < 1e4 ? value.toFixed(4) : value.toExponential(3);
}
