// The fleet page: the caller's sessions from /api/sessions (ListSessions'
// filter and order_by), sortable by column, refreshed while "live" is on.
import { call, el, idOf, labelsText, num, planeShare, sourceOf, STATES } from './api.js';

const REFRESH_MS = 2000;
// Columns: header, order_by field (null: not sortable), cell text.
const COLUMNS = [
  ['Session', 'name', (s) => idOf(s.name)],
  ['Source', 'source', (s) => sourceOf(s)],
  ['Codec', 'codec', (s) => (s.stream_report ? s.stream_report.codec : '')],
  ['State', 'state', (s) => s.state],
  ['fps', 'stats.fps', (s) => num(s.stats.fps).toFixed(1)],
  ['Lag (ms)', 'stats.lag_ms', (s) => num(s.stats.lag_ms).toFixed(0)],
  ['Frames', 'stats.frames', (s) => num(s.stats.frames)],
  ['Tracked steps', 'stats.tracked_pairs', (s) => `${num(s.stats.tracked_pairs)} / ${num(s.stats.anchor_pairs)}`],
  // A share of tracked_pairs: no counter to sort it by (plane_steps alone would mislead).
  ['Scale held', null, (s) => planeShare(s.stats)],
  ['Planes', 'stats.planes', (s) => num(s.stats.planes)],
  ['Reconnects', 'stats.reconnects', (s) => num(s.stats.reconnects)],
  ['Labels', null, (s) => labelsText(s.labels)],
  ['Last error', null, (s) => (s.error && s.error.message) || ''],
];

const view = { orderField: 'create_time', desc: false, timer: null };

function header() {
  const tr = document.querySelector('#fleet thead tr');
  tr.replaceChildren();
  for (const [title, field] of COLUMNS) {
    if (!field) {
      tr.append(el('th', { scope: 'col' }, title));
      continue;
    }
    const sorted = view.orderField === field;
    const th = el('th', { scope: 'col', 'aria-sort': sorted ? (view.desc ? 'descending' : 'ascending') : 'none' });
    th.append(el('button', {
      type: 'button',
      class: 'sort',
      'data-field': field,
      onclick: () => {
        view.desc = sorted ? !view.desc : false;
        view.orderField = field;
        header();
        // Keyboard users keep their place: the re-drawn header's button.
        document.querySelector(`#fleet thead button[data-field="${field}"]`).focus();
        refresh();
      },
    }, title, sorted ? (view.desc ? ' ▼' : ' ▲') : ''));
    tr.append(th);
  }
}

function row(s) {
  const tr = el('tr', { 'data-name': s.name, 'data-state': s.state });
  COLUMNS.forEach(([title, , text], i) => {
    const value = text(s);
    if (i === 0) {
      tr.append(el('th', { scope: 'row' }, el('a', { href: `/session.html?name=${encodeURIComponent(s.name)}` }, value)));
    } else if (title === 'State') {
      tr.append(el('td', {}, el('span', { class: `state s-${value}` }, value)));
    } else {
      tr.append(el('td', { class: typeof value === 'number' || /^[\d.]+/.test(value) ? 'num' : '' }, value));
    }
  });
  return tr;
}

async function refresh() {
  const status = document.getElementById('status');
  const params = {
    filter: document.getElementById('filter').value.trim(),
    state: document.getElementById('state').value,
    order_by: `${view.orderField}${view.desc ? ' desc' : ''}`,
    page_size: '1000',
  };
  try {
    const list = await call('/api/sessions', params);
    const sessions = list.sessions || [];
    document.querySelector('#fleet tbody').replaceChildren(...sessions.map(row));
    status.textContent = `${sessions.length} session${sessions.length === 1 ? '' : 's'} · updated ${new Date().toLocaleTimeString()}`;
    status.classList.remove('error');
    if (window.slapseMetrics.firstRenderMs === undefined) window.slapseMetrics.firstRenderMs = performance.now();
  } catch (e) {
    status.textContent = e.message;
    status.classList.add('error');
  }
}

function schedule() {
  clearInterval(view.timer);
  if (document.getElementById('live').checked) view.timer = setInterval(refresh, REFRESH_MS);
}

window.slapseMetrics = {};
const select = document.getElementById('state');
for (const s of STATES) select.append(el('option', { value: s }, s));
document.getElementById('query').addEventListener('submit', (e) => {
  e.preventDefault();
  refresh();
});
select.addEventListener('change', refresh);
document.getElementById('live').addEventListener('change', schedule);
header();
refresh();
schedule();
