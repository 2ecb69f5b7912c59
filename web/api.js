// pendant: the request layer both pages share (the teach pendant and the analysis page).
// Plain ES module, no build step, no libraries.
//
// A refused request answers {"detail": [{"loc": ["body", ...field], "msg": reason}]}; request()
// throws it as an ApiError carrying that detail, so each page can show every msg beside its field.

/**
 * A request the service refused (status, the response's `detail`), or did not answer (status 0).
 * A 412 (someone changed the slot or session since this page read it) also carries `current`,
 * the value it holds now.
 */
export class ApiError extends Error {
  constructor(status, detail, current) {
    super(typeof detail === "string" ? detail : JSON.stringify(detail));
    this.status = status;
    this.detail = detail;
    this.current = current;
  }
}

// Optimistic concurrency, done for the person at the page: the ETag of each slot and session
// this page has read (or written) is kept, and a later write to it sends it as If-Match. A
// write that would overwrite someone else's change then fails with 412 instead of winning
// silently. Robot motions (jog, approach) are relative commands and go without it.
const RESOURCE = /^\/controllers\/\d+\/(?:tools|bases|sessions|external-kinematics)\/\d+/;
const etags = new Map();

/** The slot or session `path` acts on (`/controllers/1/sessions/5/save` -> `.../sessions/5`). */
export function resourceOf(path) {
  const m = RESOURCE.exec(path.split("?")[0]);
  return m ? m[0] : null;
}

/**
 * `method` `path` on this origin; resolves to the parsed JSON answer (null when empty).
 *
 * Options:
 * - `body`: a value sent as JSON (JSON.stringify);
 * - `bodyText`: a JSON text sent unchanged (what a person pasted: the service judges it);
 * - `onStart`, `onEnd`: called synchronously when the request starts and once when it settles
 *   (success or failure), e.g. to count requests in flight.
 *
 * Throws ApiError(status, detail) for a non-2xx answer, and ApiError(0, [{loc: [], msg}]) when
 * the service did not answer at all (network failure).
 */
export async function request(method, path, { body, bodyText, onStart, onEnd } = {}) {
  if (body !== undefined && bodyText !== undefined) throw new TypeError("request: give body or bodyText, not both");
  onStart?.();
  try {
    const init = { method, headers: {} };
    const resource = resourceOf(path);
    if (method !== "GET" && resource && etags.has(resource)) init.headers["If-Match"] = etags.get(resource);
    const csrf = document.cookie.match(/(?:^|;\s*)pendant_csrf=([^;]*)/);  // web/auth.js's login
    if (csrf && method !== "GET") init.headers["X-CSRF-Token"] = decodeURIComponent(csrf[1]);
    const text = body !== undefined ? JSON.stringify(body) : bodyText;
    if (text !== undefined) {
      init.headers["Content-Type"] = "application/json";
      init.body = text;
    }
    let r;
    try {
      r = await fetch(path, init);
    } catch (err) {
      throw new ApiError(0, [{ loc: [], msg: `the service did not answer (${err.message})` }]);
    }
    const answer = await r.text();
    let data = null;
    try { data = answer ? JSON.parse(answer) : null; } catch { data = answer; }
    const etag = r.headers.get("ETag");
    if (resource && etag) etags.set(resource, etag);
    if (!r.ok) {
      const detail = data && data.detail !== undefined ? data.detail : `${r.status} ${r.statusText}`;
      throw new ApiError(r.status, detail, data && data.current);
    }
    return data;
  } finally {
    onEnd?.();
  }
}
