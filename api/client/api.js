// Fetch helpers for the contact-sim HTTP API (see /openapi.yaml). Every error of the server is
// an RFC 9457 problem+json document; it is thrown as an ApiProblem so callers can show
// `detail` and, for an invalid scene (422), the `errors[]` entries with their JSON pointers.

import { fmtBytes } from './util.js';

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

// ---- API keys ---------------------------------------------------------------------------
// A server started with --auth required answers 401 with `WWW-Authenticate: Bearer` until a
// request carries `Authorization: Bearer <key>`. The key is asked for once (one dialog for
// all the requests waiting on it) and kept in this tab's sessionStorage: it goes in a header
// on every request, event streams included, never in a URL (URLs land in logs and history).
// A server without auth never answers 401, so nothing is asked and no header is sent.

const KEY_STORE = 'contact-sim-api-key';
let asking = null; // the pending dialog's promise, shared by every request that got a 401
let declined = false; // the user cancelled the dialog: not asked again until askApiKey()

export function apiKey() {
  try {
    return sessionStorage.getItem(KEY_STORE) || null;
  } catch {
    return null;
  }
}

function setApiKey(key) {
  try {
    if (key) sessionStorage.setItem(KEY_STORE, key);
    else sessionStorage.removeItem(KEY_STORE);
  } catch {
    // Storage refused (private mode): the key lives as long as the page.
  }
  memoryKey = key;
}
let memoryKey = null;

/** The headers `init` needs with the key, if there is one. */
function withKey(headers = {}) {
  const key = apiKey() || memoryKey;
  return key ? { ...headers, Authorization: `Bearer ${key}` } : headers;
}

/** Whether a response asks for a bearer token. */
const wantsKey = (resp) => resp.status === 401 && /^\s*bearer\b/i.test(resp.headers.get('WWW-Authenticate') || '');

/**
 * Asks the user for an API key (a modal dialog); resolves true with a key stored, false when
 * the user gave up. `refused`: the last key sent was not accepted.
 */
function askKey(refused) {
  if (asking) return asking;
  asking = new Promise((resolve) => {
    const dialog = document.createElement('dialog');
    dialog.id = 'auth-dialog';
    dialog.setAttribute('aria-labelledby', 'auth-title');
    dialog.innerHTML = `
      <form method="dialog">
        <h2 id="auth-title">API key needed</h2>
        <p class="hint" id="auth-why"></p>
        <div class="field">
          <label for="auth-key">API key</label>
          <input id="auth-key" type="password" autocomplete="off" spellcheck="false" required>
        </div>
        <div class="buttons">
          <button type="submit" class="primary" value="ok">Use this key</button>
          <button type="submit" value="cancel" formnovalidate>Cancel</button>
        </div>
      </form>`;
    dialog.querySelector('#auth-why').textContent = refused
      ? 'The server refused the key: it is unknown or revoked. Enter another one.'
      : 'This server requires an API key (ask its administrator). It is kept in this tab only and sent in a header with every request.';
    document.body.append(dialog);
    dialog.addEventListener('close', () => {
      const key = dialog.returnValue === 'ok' ? dialog.querySelector('#auth-key').value.trim() : '';
      dialog.remove();
      if (key) setApiKey(key);
      declined = !key;
      asking = null;
      if (declined) document.dispatchEvent(new CustomEvent('api-key-declined'));
      resolve(!!key);
    });
    dialog.showModal();
  });
  return asking;
}

/**
 * fetch() with the API key: on a 401 asking for a bearer token the user is asked for a key
 * and the request is made again with it. The answer is the last response (a 401 when the
 * user gave up).
 */
export async function authFetch(path, init = {}) {
  for (;;) {
    const sent = apiKey() || memoryKey;
    const resp = await fetch(path, { ...init, headers: withKey(init.headers) });
    if (!wantsKey(resp)) return resp;
    // A key sent and refused is forgotten (a revoked key must not be sent again).
    if (sent && (apiKey() || memoryKey) === sent) setApiKey(null);
    // Another request may have got a key meanwhile: use it without asking again.
    if (!sent && (apiKey() || memoryKey)) continue;
    if (declined || !(await askKey(!!sent))) return resp;
  }
}

/** Asks for a key again (after the dialog was cancelled); true when one was given. */
export function askApiKey() {
  declined = false;
  return askKey(false);
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
    resp = await authFetch(path, init);
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

/**
 * Makes `a` (a link to a resource of the API) work with a key: without one it is a plain
 * link; with one a click fetches the resource with the key and saves it under the link's
 * download name (a link cannot carry a header).
 */
export function keyedLink(a) {
  a.addEventListener('click', async (ev) => {
    if (!(apiKey() || memoryKey)) return;
    ev.preventDefault();
    const resp = await authFetch(a.getAttribute('href'));
    if (!resp.ok) return;
    const url = URL.createObjectURL(await resp.blob());
    const tmp = document.createElement('a');
    tmp.href = url;
    tmp.download = a.getAttribute('download') || a.getAttribute('href').split('/').pop();
    document.body.append(tmp);
    tmp.click();
    tmp.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60_000);
  });
  return a;
}

/** Sets `img`'s picture from an API resource, fetched with the key when there is one. */
export async function keyedImage(img, path) {
  if (!(apiKey() || memoryKey)) {
    img.src = path;
    return;
  }
  const resp = await authFetch(path);
  if (resp.ok) img.src = URL.createObjectURL(await resp.blob());
}

/**
 * The size in bytes of the resource at `path` (its Content-Length, from a HEAD request), or
 * null when the server does not say (a streamed archive) or refuses.
 */
export async function contentLength(path) {
  try {
    const resp = await authFetch(path, { method: 'HEAD' });
    const n = Number(resp.headers.get('Content-Length'));
    return resp.ok && resp.headers.has('Content-Length') && Number.isFinite(n) ? n : null;
  } catch {
    return null;
  }
}

/** Appends the size of the resource at `path` to link `a`'s `text` ("summary JSON (12 kB)") once known. */
export async function sizeInto(a, text, path) {
  const bytes = await contentLength(path);
  if (bytes !== null) {
    a.textContent = `${text} (${fmtBytes(bytes)})`;
    a.dataset.bytes = String(bytes);
  }
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
 * per triangle, is left out: von Mises is its scalar summary; the a posteriori indicators
 * come only from jobs that computed them); `only`: just these fields.
 * Always on the boundary surface (surface=1): a 3D job's mesh and fields are those of its
 * outside, a small part of a fine mesh; a 2D job's come whole either way.
 */
export function fields(id, step, withMesh, only = null) {
  const q = new URLSearchParams({ step: String(step), fields: only ? only.join(',') : 'u,w,zeta,von_mises,contact,estimate', surface: '1' });
  if (withMesh) q.set('mesh', '1');
  return getJson(`/jobs/${id}/fields?${q}`);
}

/**
 * The step numbers of a succeeded simulation that can be shown: 0 (the initial state, t = 0)
 * and the stored ones. The summary lists every computed step but not which were stored
 * (output.every / last), so they are read from the ParaView collection, whose DataSet entries
 * name fields/{n}.vtu (relative to the PVD's URL).
 */
export async function storedSteps(id) {
  const xml = await getText(`/jobs/${id}/result.pvd`);
  const doc = new DOMParser().parseFromString(xml, 'application/xml');
  const steps = [];
  for (const ds of doc.querySelectorAll('DataSet')) {
    const m = /(?:^|\/)fields\/(\d+)\.vtu$/.exec(ds.getAttribute('file') || '');
    if (m) steps.push({ n: Number(m[1]), t: Number(ds.getAttribute('timestep')) });
  }
  steps.sort((a, b) => a.n - b.n);
  return steps;
}

/**
 * Follows a job's Server-Sent Events: "progress" while it runs and one final "status"
 * (data: {status, step, steps, last_residual, eta_s}); the stream is closed after the final
 * status. Read with fetch (not EventSource, which cannot send the API key's header): the
 * text/event-stream lines are parsed here (event, data, id, retry; a blank line dispatches).
 * A stream that drops before the final status is reopened like EventSource does (after
 * `retry` ms, with Last-Event-ID when the server gave ids) while it keeps delivering events;
 * a refused stream (404, 409, ...) or MAX_RETRIES reconnections without an event end it and
 * hand it back to the caller (`onEnd`), which falls back to polling.
 */
export function follow(id, onEvent, onEnd) {
  const MAX_RETRIES = 3;
  const ctrl = new AbortController();
  let ended = false;
  let lastId = null;
  let retryMs = 1000;
  let failures = 0;
  const end = () => {
    if (ended) return;
    ended = true;
    ctrl.abort();
    onEnd?.();
  };
  /** Handles one event; true when it was the final status. */
  const dispatch = (type, data) => {
    if (type !== 'progress' && type !== 'status') return false;
    let doc;
    try {
      doc = JSON.parse(data);
    } catch {
      return false;
    }
    onEvent(doc);
    return type === 'status';
  };
  const run = async () => {
    while (!ended) {
      let finished = false;
      try {
        const headers = { Accept: 'text/event-stream' };
        if (lastId !== null) headers['Last-Event-ID'] = lastId;
        const resp = await authFetch(`/jobs/${id}/events`, { headers, signal: ctrl.signal, cache: 'no-store' });
        if (!resp.ok || !/^text\/event-stream/.test(resp.headers.get('Content-Type') || '')) {
          resp.body?.cancel().catch(() => {});
          break; // like EventSource: a refused stream is not retried
        }
        const reader = resp.body.pipeThrough(new TextDecoderStream()).getReader();
        let buf = '';
        let type = '', data = [];
        for (;;) {
          const { value, done } = await reader.read();
          if (done) break;
          buf += value;
          let nl;
          while ((nl = buf.search(/\r\n|\r|\n/)) >= 0) {
            const line = buf.slice(0, nl);
            buf = buf.slice(nl + (buf.startsWith('\r\n', nl) ? 2 : 1));
            if (line === '') {
              if (data.length) {
                failures = 0;
                if (dispatch(type || 'message', data.join('\n'))) finished = true;
              }
              type = '';
              data = [];
              if (finished) break;
              continue;
            }
            if (line.startsWith(':')) continue; // a comment (keep-alive)
            const colon = line.indexOf(':');
            const field = colon < 0 ? line : line.slice(0, colon);
            let value = colon < 0 ? '' : line.slice(colon + 1);
            if (value.startsWith(' ')) value = value.slice(1);
            if (field === 'event') type = value;
            else if (field === 'data') data.push(value);
            else if (field === 'id' && !value.includes('\0')) lastId = value;
            else if (field === 'retry' && /^\d+$/.test(value)) retryMs = Number(value);
          }
          if (finished) break;
        }
        reader.cancel().catch(() => {});
      } catch (e) {
        if (ended || e.name === 'AbortError') return;
      }
      if (finished || ended) break;
      if (++failures > MAX_RETRIES) break;
      await new Promise((r) => setTimeout(r, retryMs));
    }
    end();
  };
  run();
  return { close: end };
}
