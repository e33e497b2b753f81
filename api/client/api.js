// Fetch helpers for the contact-sim HTTP API (see /openapi.yaml). Every error of the server is
// an RFC 9457 problem+json document; it is thrown as an ApiProblem so callers can show
// `detail` and, for an invalid scene (422), the `errors[]` entries with their JSON pointers.

export class ApiProblem extends Error {
  constructor(status, problem) {
    super(problem.detail || problem.title || `HTTP ${status}`);
    this.status = status;
    this.title = problem.title || '';
    this.type = problem.type || 'about:blank';
    /** [{pointer, message}] for invalid scenes, else []. */
    this.errors = Array.isArray(problem.errors) ? problem.errors : [];
  }
}

async function request(method, path, body) {
  const init = { method, headers: { Accept: 'application/json' } };
  if (body instanceof ArrayBuffer || ArrayBuffer.isView(body) || body instanceof Blob) {
    init.headers['Content-Type'] = 'application/octet-stream';
    init.body = body;
  } else if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = typeof body === 'string' ? body : JSON.stringify(body);
  }
  let resp;
  try {
    resp = await fetch(path, init);
  } catch (e) {
    throw new ApiProblem(0, { title: 'network error', detail: `cannot reach the server (${e.message})` });
  }
  if (resp.status === 204) return { status: 204, body: null };
  const text = await resp.text();
  let data = null;
  if (text) {
    try {
      data = JSON.parse(text);
    } catch {
      data = text;
    }
  }
  if (!resp.ok) {
    const problem = data && typeof data === 'object' ? data : { detail: String(data || resp.statusText) };
    throw new ApiProblem(resp.status, problem);
  }
  return { status: resp.status, body: data, headers: resp.headers };
}

export const getJson = async (path) => (await request('GET', path)).body;
export const getText = async (path) => (await request('GET', path)).body;

export const presets = () => getJson('/presets');
export const preset = (name) => getJson(`/presets/${encodeURIComponent(name)}`);
export const listJobs = (limit = 50) => getJson(`/jobs?limit=${limit}`);
export const job = (id) => getJson(`/jobs/${id}`);
export const summary = (id) => getJson(`/jobs/${id}/summary`);

/** Submits a scene document or {preset, overrides}; `body` may be the raw editor text. */
export const submit = async (body) => (await request('POST', '/jobs', body)).body;
export const cancel = async (id) => (await request('POST', `/jobs/${id}/cancel`)).body;
export const remove = async (id) => request('DELETE', `/jobs/${id}`);

/**
 * Uploads a gmsh .msh file (its bytes): {status: 201 (new) or 200 (the same bytes were
 * uploaded before), body: {id, ..., summary figures}}. A file the server refuses is an
 * ApiProblem with the server's detail.
 */
export const uploadMesh = (bytes) => request('POST', '/meshes', bytes);

/**
 * Fields of one stored step. Only what the viewer draws is asked for (sigma, three numbers
 * per triangle, is left out: von Mises is its scalar summary).
 */
export function fields(id, step, withMesh) {
  const q = new URLSearchParams({ step: String(step), fields: 'u,w,zeta,von_mises,contact' });
  if (withMesh) q.set('mesh', '1');
  return getJson(`/jobs/${id}/fields?${q}`);
}

/**
 * The step numbers of a succeeded simulation that can be shown: 0 (the initial state, t = 0)
 * and the stored ones. The summary lists every computed step but not which were stored
 * (output.every / last), so they are read from the ParaView collection, whose DataSet entries
 * reference /jobs/{id}/fields/{n}.vtu.
 */
export async function storedSteps(id) {
  const xml = await getText(`/jobs/${id}/result.pvd`);
  const doc = new DOMParser().parseFromString(xml, 'application/xml');
  const steps = [];
  for (const ds of doc.querySelectorAll('DataSet')) {
    const m = /\/fields\/(\d+)\.vtu$/.exec(ds.getAttribute('file') || '');
    if (m) steps.push({ n: Number(m[1]), t: Number(ds.getAttribute('timestep')) });
  }
  steps.sort((a, b) => a.n - b.n);
  return steps;
}

/**
 * Follows a job's Server-Sent Events: "progress" while it runs and one final "status"
 * (data: {status, step, steps, last_residual, eta_s}). The stream is closed after the final
 * status, otherwise EventSource would reconnect to a finished stream forever.
 */
export function follow(id, onEvent, onEnd) {
  const es = new EventSource(`/jobs/${id}/events`);
  let ended = false;
  const end = () => {
    if (ended) return;
    ended = true;
    es.close();
    onEnd?.();
  };
  const handle = (final) => (ev) => {
    let data;
    try {
      data = JSON.parse(ev.data);
    } catch {
      return;
    }
    onEvent(data);
    if (final) end();
  };
  es.addEventListener('progress', handle(false));
  es.addEventListener('status', handle(true));
  // A stream that fails (server restart, deleted job) is handed back to the caller, which
  // falls back to polling instead of letting EventSource retry blindly.
  es.onerror = end;
  return { close: end };
}
