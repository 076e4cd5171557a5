// The dashboard's calls to slapse's JSON API (server/dashboard.h). JSON is
// protobuf's mapping of the v1 messages: proto field names, int64 as strings.

// Fetches `path` with `params`; resolves to the parsed JSON, or throws an
// Error whose message is the server's ErrorStatus message.
export async function call(path, params = {}, method = 'GET') {
  const query = new URLSearchParams(params).toString();
  const res = await fetch(query ? `${path}?${query}` : path, {
    method,
    credentials: 'same-origin',
    headers: { Accept: 'application/json' },
  });
  const text = await res.text();
  let body = null;
  try {
    body = text ? JSON.parse(text) : null;
  } catch {
    throw new Error(`HTTP ${res.status}: ${text.slice(0, 200)}`);
  }
  if (!res.ok) {
    if (res.status === 401) window.location.assign('/');
    throw new Error(body && body.message ? body.message : `HTTP ${res.status}`);
  }
  return body;
}

export const TERMINAL = new Set(['FINISHED', 'FAILED', 'STOPPED', 'EXPIRED']);
export const STATES = ['CREATED', 'RUNNING', 'FINISHED', 'FAILED', 'STOPPED', 'EXPIRED'];

// The session's source kind, as ListSessions' filter names it.
export function sourceOf(session) {
  for (const kind of ['upload', 'rtsp_pull', 'rtsp_push', 'rtp_sdp']) {
    if (session[kind] !== undefined && session[kind] !== null) return kind;
  }
  return '';
}

// "sessions/{id}" -> "{id}".
export function idOf(name) {
  return name.replace(/^sessions\//, '');
}

// A number from a JSON number or an int64 string ("NaN" too).
export function num(x) {
  return x === undefined || x === null ? 0 : Number(x);
}

// The share of tracked steps whose length a plane measured
// (SessionStats.plane_steps), as text; "weak" as the server judged it
// (scale_support_weak: the scale drifts with the speed).
export function planeShare(stats) {
  const tracked = num(stats.tracked_pairs);
  if (tracked === 0) return '';
  const pct = Math.round((100 * num(stats.plane_steps)) / tracked);
  return stats.scale_support_weak ? `${pct} % (weak)` : `${pct} %`;
}

// Milliseconds since the epoch of an RFC 3339 timestamp (nanoseconds cut to ms).
export function timeMs(rfc3339) {
  if (!rfc3339) return NaN;
  return Date.parse(rfc3339.replace(/(\.\d{3})\d+/, '$1'));
}

// Text node helper: el('td', {class: 'x'}, 'text', child...).
export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}

export function labelsText(labels) {
  return Object.entries(labels || {})
    .map(([k, v]) => `${k}=${v}`)
    .join(', ');
}
