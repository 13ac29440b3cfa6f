// The HTTP API as the page uses it: the key kept for the tab, problem+json errors as readable messages,
// JSON and multipart requests, binary display payloads.

const KEY_STORAGE = "hairport.apiKey";

export function apiKey() {
  return sessionStorage.getItem(KEY_STORAGE) ?? "";
}

export function setApiKey(key) {
  if (key) sessionStorage.setItem(KEY_STORAGE, key);
  else sessionStorage.removeItem(KEY_STORAGE);
}

/** An error answer of the API: its status, stable code and the detail meant for people. */
export class ApiError extends Error {
  constructor(status, code, detail) {
    super(`${detail} (${code}, HTTP ${status})`);
    this.status = status;
    this.code = code;
    this.detail = detail;
  }
}

function headers(extra = {}) {
  const key = apiKey();
  return key ? { "X-API-Key": key, ...extra } : extra;
}

async function failure(response) {
  let problem = null;
  try {
    problem = await response.json();
  } catch {
    // not JSON: a proxy's page, say
  }
  if (problem && Array.isArray(problem.detail)) {  // a validation error list
    const detail = problem.detail.map((item) => `${(item.loc ?? []).join(".")}: ${item.msg}`).join("; ");
    return new ApiError(response.status, "validation_error", detail);
  }
  return new ApiError(response.status, problem?.code ?? `http_${response.status}`,
                      problem?.detail ?? response.statusText ?? "request failed");
}

/** A request: `json` is sent as JSON, `form` (FormData) as multipart; the answer as JSON, or raw with `as`. */
export async function call(method, path, { json, form, as = "json", idempotencyKey } = {}) {
  const extra = {};
  let body;
  if (json !== undefined) {
    extra["Content-Type"] = "application/json";
    body = JSON.stringify(json);
  } else if (form !== undefined) {
    body = form;
  }
  if (idempotencyKey) extra["Idempotency-Key"] = idempotencyKey;
  let response;
  try {
    response = await fetch(path, { method, headers: headers(extra), body });
  } catch (error) {
    throw new ApiError(0, "unreachable", `hairport did not answer: ${error.message}`);
  }
  if (!response.ok) throw await failure(response);
  if (as === "buffer") return response.arrayBuffer();
  if (as === "blob") return { blob: await response.blob(), response };
  return response.status === 204 ? null : response.json();
}

export const get = (path, options) => call("GET", path, options);
export const post = (path, options) => call("POST", path, options);
export const remove = (path, options) => call("DELETE", path, options);

const DTYPES = { float32: Float32Array, uint32: Uint32Array, uint8: Uint8Array, int32: Int32Array };

/** The display wire format (hairport.solver.display): {header, arrays: {name: TypedArray}}. */
export function decodeDisplay(buffer) {
  const magic = new TextDecoder().decode(new Uint8Array(buffer, 0, 4));
  if (magic !== "HPD1") throw new Error("not a hairport display payload");
  const length = new DataView(buffer).getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 8, length)));
  const base = 8 + length;
  const arrays = {};
  for (const entry of header.arrays) {
    const count = entry.shape.reduce((a, b) => a * b, 1);
    arrays[entry.name] = new DTYPES[entry.dtype](buffer, base + entry.offset, count);
  }
  return { header, arrays };
}

/** Save what a URL answers as a file (downloads carry the key, so a plain link would not do). */
export async function download(path, fallbackName) {
  const { blob, response } = await call("GET", path, { as: "blob" });
  const disposition = response.headers.get("Content-Disposition") ?? "";
  const match = /filename\*?=(?:UTF-8'')?"?([^";]+)"?/i.exec(disposition);
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = match ? decodeURIComponent(match[1]) : fallbackName;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 60_000);
}

let schemaPromise = null;
/** The API's OpenAPI document (option ranges, defaults and choices come from it: one definition). */
export function openapi() {
  schemaPromise ??= fetch("/openapi.json").then((response) => response.json());
  return schemaPromise;
}
