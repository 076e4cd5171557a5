// One session's page: its trajectory (GetTrajectory's pages) and plane map,
// then live over server-sent events from the session's event log (the one
// WatchSession reads): PoseUpdate.frame_poses append or replace poses by frame
// index, plane events refresh the plane map, state changes the header.
import { call, el, idOf, labelsText, num, planeShare, sourceOf, TERMINAL, timeMs } from './api.js';
import { drawSeries, drawSide, drawTopDown } from './draw.js';

const STATS_MS = 2000;
const PLANES_MS = 1000;
const OVERLAY_MS = 1000;
const OVERLAYS = ['mv', 'planes'];
const name = new URLSearchParams(window.location.search).get('name') || '';
const points = new Map();  // frame index -> {t, x, y, z, kind, segment, revision}
const stats = { fps: [], lag: [], tracked: [] };
let planes = [];
let metric = false;
let segment = 0;
let session = null;
let source = null;
let drawPending = false;
let planeTimer = null;
const metrics = (window.slapseMetrics = {
  events: 0,
  latenciesMs: [],
  points: 0,
  lastSequence: 0,
  sequences: [],  // every event's sequence, in arrival order
  opens: 0,  // event-stream connections opened (a reconnect adds one)
  overlays: { mv: { loads: 0, frames: [] }, planes: { loads: 0, frames: [] } },
});
let overlayEvents = -1;  // metrics.events when the overlays were last fetched

function status(text, error = false) {
  const s = document.getElementById('status');
  s.textContent = text;
  s.classList.toggle('error', error);
}

function put(framePose, seg) {
  const p = framePose.world_from_cam || {};
  points.set(num(framePose.frame_index ?? framePose.anchor_index), {
    t: num(framePose.timestamp_s),
    x: num(p.tx),
    y: num(p.ty),
    z: num(p.tz),
    kind: (framePose.quality && framePose.quality.kind) || 'KIND_UNSPECIFIED',
    segment: seg,
    revision: num(framePose.revision),
  });
}

function draw() {
  drawPending = false;
  const pts = Array.from(points.entries())
    .sort((a, b) => a[1].segment - b[1].segment || a[0] - b[0])
    .map((e) => e[1]);
  const unit = metric ? 'm' : 'first steps';
  const drawn = drawTopDown(document.getElementById('top'), pts, planes, unit) || 0;
  drawSide(document.getElementById('side'), pts, planes, unit);
  drawSeries(document.getElementById('stats'), [
    { name: 'fps', colour: '#1764ab', values: stats.fps, digits: 1 },
    { name: 'lag ms', colour: '#c0162b', values: stats.lag, digits: 0 },
    { name: 'tracked', colour: '#2e8540', values: stats.tracked, digits: 2 },
  ]);
  document.getElementById('points').textContent = pts.length;
  document.getElementById('plane-count').textContent = `${planes.length} (${drawn} drawn)`;
  document.getElementById('top').dataset.points = pts.length;
  metrics.points = pts.length;
  if (metrics.firstRenderMs === undefined) metrics.firstRenderMs = performance.now();
}

function redraw() {
  if (!drawPending) {
    drawPending = true;
    requestAnimationFrame(draw);
  }
}

function showSession(s) {
  session = s;
  document.title = `slapse · ${idOf(s.name)}`;
  document.getElementById('title').textContent = idOf(s.name);
  const state = document.getElementById('state');
  state.textContent = s.state;
  state.className = `state s-${s.state}`;
  const facts = [
    ['Source', sourceOf(s)],
    ['Codec', s.stream_report ? s.stream_report.codec : ''],
    ['Frames', num(s.stats.frames)],
    ['fps', num(s.stats.fps).toFixed(1)],
    ['Lag', `${num(s.stats.lag_ms).toFixed(0)} ms`],
    ['Tracked steps', `${num(s.stats.tracked_pairs)} / ${num(s.stats.anchor_pairs)}`],
    ['Scale held by planes', planeShare(s.stats)],
    ['Planes', num(s.stats.planes)],
    ['Reconnects', num(s.stats.reconnects)],
    ['Labels', labelsText(s.labels) || '—'],
    ['Created', s.create_time || ''],
  ];
  if (s.ingest_url) facts.push(['Ingest URL', s.ingest_url]);
  if (s.state_message) facts.push(['Message', s.state_message]);
  if (s.error && s.error.message) facts.push(['Error', s.error.message]);
  document.getElementById('facts').replaceChildren(...facts.flatMap(([k, v]) => [el('dt', {}, k), el('dd', {}, v)]));
  document.getElementById('stop').disabled = TERMINAL.has(s.state);
  const t = Date.now() / 1000;
  stats.fps.push({ t, v: num(s.stats.fps) });
  stats.lag.push({ t, v: num(s.stats.lag_ms) });
  const pairs = num(s.stats.anchor_pairs);
  stats.tracked.push({ t, v: pairs ? num(s.stats.tracked_pairs) / pairs : 0 });
  redraw();
}

async function loadPlanes() {
  planeTimer = null;
  const all = [];
  let token = '';
  do {
    const page = await call('/api/planes', { name, page_size: '10000', page_token: token });
    for (const p of page.planes || []) {
      const n = p.normal_world || {};
      all.push({
        normal: { x: num(n.x), y: num(n.y), z: num(n.z) },
        distance: num(p.distance),
        first_seen_s: num(p.first_seen_s),
        last_seen_s: num(p.last_seen_s),
        segment: num(p.segment),
      });
    }
    token = page.next_page_token;
  } while (token);
  planes = all;
  redraw();
}

// Every page of the trajectory; returns the first page's last_sequence (the
// events after it are what the snapshot may lack; replaying one it has
// replaces a pose with itself).
async function loadTrajectory() {
  let token = '';
  let cursor = null;
  do {
    const page = await call('/api/trajectory', { name, page_size: '10000', page_token: token });
    if (cursor === null) cursor = num(page.last_sequence);
    metric = page.metric;
    for (const p of page.points || []) {
      put(p, num(p.segment));
      segment = Math.max(segment, num(p.segment));
    }
    token = page.next_page_token;
  } while (token);
  redraw();
  return cursor;
}

function onEvent(msg) {
  const e = JSON.parse(msg.data);
  metrics.events += 1;
  metrics.lastSequence = num(e.sequence);
  metrics.sequences.push(metrics.lastSequence);
  if (e.pose) {
    if (e.pose.emit_time) metrics.latenciesMs.push(Date.now() - timeMs(e.pose.emit_time));
    metric = e.pose.metric;
    for (const fp of e.pose.frame_poses || []) put(fp, segment);
    redraw();
  } else if (e.plane) {
    if (!planeTimer) planeTimer = setTimeout(() => loadPlanes().catch((x) => status(x.message, true)), PLANES_MS);
  } else if (e.state_change) {
    refreshSession();
  } else if (e.reconnecting) {
    status(`reconnecting (attempt ${e.reconnecting.attempt}): ${e.reconnecting.reason}`);
  }
}

// The newest anchor frame's overlays (GET /api/overlay, PNG): fetched while
// the page is visible, when events came since the last fetch (the server
// keeps frames only while someone asks, and draws each anchor once).
async function loadOverlay(kind) {
  const img = document.getElementById(`overlay-${kind}`);
  const note = document.getElementById(`overlay-${kind}-note`);
  // As wide as the picture is shown (device pixels), so nothing is drawn in vain.
  const shown = Math.round((img.clientWidth || img.parentElement.clientWidth) * (window.devicePixelRatio || 1));
  const width = String(Math.min(1280, Math.max(160, shown)));
  const res = await fetch(`/api/overlay?${new URLSearchParams({ name, kind, max_width_px: width })}`, {
    credentials: 'same-origin',
  });
  if (!res.ok) {
    if (res.status === 401) window.location.assign('/');
    const body = await res.json().catch(() => ({}));
    note.textContent = res.status === 503 && session && TERMINAL.has(session.state)
      ? 'none: frames are kept only while a page watches a running session'
      : body.message || `HTTP ${res.status}`;
    return;
  }
  const frame = res.headers.get('X-Slapse-Frame');
  const count = Number(res.headers.get('X-Slapse-Count'));
  const what = kind === 'mv' ? `${count} motion vectors` : `${count} plane${count === 1 ? '' : 's'}`;
  const url = URL.createObjectURL(await res.blob());
  img.onload = () => {
    const m = metrics.overlays[kind];
    m.loads += 1;
    m.frames.push(Number(frame));
    m.counts = [...(m.counts || []), count];
    m.naturalWidth = img.naturalWidth;
    if (img.dataset.url) URL.revokeObjectURL(img.dataset.url);
    img.dataset.url = url;
  };
  img.src = url;
  img.hidden = false;
  img.dataset.frame = frame;
  img.alt = kind === 'mv'
    ? `Motion vectors of frame ${frame}: ${what}`
    : `Planes extracted on the anchor pair ending at frame ${frame}: ${what}`;
  note.textContent = `frame ${frame}, ${what}`;
}

function refreshOverlays() {
  if (document.visibilityState !== 'visible' || metrics.events === overlayEvents) return;
  if (session && TERMINAL.has(session.state) && overlayEvents >= 0) return;
  overlayEvents = metrics.events;
  for (const kind of OVERLAYS) loadOverlay(kind).catch((e) => status(e.message, true));
}

function watch(after) {
  // EventSource reconnects by itself and sends Last-Event-ID: the server
  // resumes after it, so nothing is lost or repeated.
  source = new EventSource(`/api/events?${new URLSearchParams({ name, after: String(after) })}`);
  source.onmessage = onEvent;
  source.addEventListener('end', () => {
    source.close();
    metrics.ended = true;
    status('the session has ended');
    refreshSession();
    loadPlanes();
  });
  source.addEventListener('failure', (m) => {
    source.close();
    status(JSON.parse(m.data).message, true);
  });
  source.onopen = () => {
    metrics.opens += 1;
    status('live');
  };
  source.onerror = () => {
    if (source.readyState === EventSource.CONNECTING) status('connection lost; reconnecting…');
  };
}

async function refreshSession() {
  try {
    showSession(await call('/api/session', { name }));
  } catch (e) {
    status(e.message, true);
  }
}

function confirmThen(text, action) {
  const dialog = document.getElementById('confirm');
  document.getElementById('confirm-text').textContent = text;
  dialog.returnValue = '';
  dialog.onclose = () => {
    if (dialog.returnValue === 'ok') action();
  };
  dialog.showModal();
}

function wireButtons() {
  document.getElementById('stop').addEventListener('click', () =>
    confirmThen(`Stop ${idOf(name)}? Its stream is closed; results stay.`, async () => {
      try {
        showSession(await call('/api/stop', { name }, 'POST'));
        status('stopped');
      } catch (e) {
        status(e.message, true);
      }
    }));
  document.getElementById('delete').addEventListener('click', () =>
    confirmThen(`Delete ${idOf(name)} and all its results? This cannot be undone.`, async () => {
      try {
        await call('/api/delete', { name }, 'POST');
        window.location.assign('/');
      } catch (e) {
        status(e.message, true);
      }
    }));
  for (const f of ['tum', 'kitti', 'json']) {
    document.getElementById(`dl-${f}`).href = `/api/download?${new URLSearchParams({ name, format: f })}`;
  }
}

async function main() {
  wireButtons();
  try {
    await refreshSession();
    const [cursor] = await Promise.all([loadTrajectory(), loadPlanes()]);
    watch(cursor);
    refreshOverlays();
    setInterval(refreshOverlays, OVERLAY_MS);
    setInterval(() => {
      if (session && !TERMINAL.has(session.state)) refreshSession();
    }, STATS_MS);
  } catch (e) {
    status(e.message, true);
  }
}

window.addEventListener('resize', redraw);
main();
