// The REST API client: every request carries the signed-in user's Bearer token, and every failure
// becomes an ApiError with a sentence a rule author can read.

const TOKEN_KEY = "printeps.workbench.token";

export function getToken() {
  return localStorage.getItem(TOKEN_KEY) || "";
}

export function setToken(token) {
  if (token) localStorage.setItem(TOKEN_KEY, token);
  else localStorage.removeItem(TOKEN_KEY);
}

export class ApiError extends Error {
  constructor(status, body, message) {
    super(message);
    this.status = status;
    this.body = body;
  }

  /** Compile/fact errors the server listed ({"errors": [...]}), else []. */
  get errors() {
    return this.body && Array.isArray(this.body.errors) ? this.body.errors : [];
  }
}

/** One request; resolves with the decoded JSON body or rejects with an ApiError. `extraHeaders`
 * adds request headers (e.g. `Prefer: respond-async` to get a build job instead of waiting). */
export async function api(method, path, body, extraHeaders = {}) {
  const headers = { Accept: "application/json", ...extraHeaders };
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  const init = { method, headers };
  if (body !== undefined) {
    headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch {
    throw new ApiError(0, null, "The gateway cannot be reached. Is it running?");
  }
  const text = await response.text();
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = text;
  }
  if (!response.ok) throw new ApiError(response.status, data, describe(response.status, data));
  return data;
}

/** Plain wording for a failed request, using what the server said when it said something. */
export function describe(status, data) {
  const said = serverMessage(data);
  if (status === 401) return "Please sign in: " + (said || "your token is missing or not accepted.");
  if (status === 403) return "Your role may not do this" + (said ? `: ${said}` : ".");
  if (status === 404) return said || "Not found.";
  if (status === 413) return "Too big for the gateway" + (said ? `: ${said}` : ".");
  return said || `The gateway answered with error ${status}.`;
}

function serverMessage(data) {
  if (!data) return "";
  if (typeof data === "string") return data.slice(0, 300);
  if (typeof data.error === "string") return data.error;
  if (typeof data.message === "string") return data.message;
  if (typeof data.detail === "string") return data.detail;
  if (Array.isArray(data.detail)) {
    return data.detail.map((d) => `${(d.loc || []).join(".")}: ${d.msg}`).join("; ");
  }
  if (data.detail && typeof data.detail === "object") return serverMessage(data.detail);
  if (Array.isArray(data.errors) && data.errors.length) return `${data.errors.length} problem(s) found.`;
  return "";
}

/** The path of a rule set resource; names are always encoded, never trusted as path pieces. */
export function rulesetPath(name, rest = "") {
  return `/api/rulesets/${encodeURIComponent(name)}${rest}`;
}
