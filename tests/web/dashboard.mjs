// Drives Debian's headless Chromium (playwright-core) through a running slapse
// dashboard; run by tests/dashboard_test.cc, which starts the server, the
// camera and the sessions. Each step asserts; a failure exits 1 with why.
//   node dashboard.mjs '{"url": "http://127.0.0.1:PORT", "live": "sessions/..",
//                        "upload": "sessions/..", "out": "/tmp/dir"}'
//     the fleet, a live session (its overlays, an event stream cut and
//     resumed), stop and delete; the browser reaches the server through a TCP
//     relay here, so the test can cut its connections as a network would.
//   node dashboard.mjs '{"mode": "auth", "url": ..., "token": "..", "mine": "sessions/..",
//                        "theirs": "sessions/..", "out": "/tmp/dir"}'
//     the login form: a wrong token refused, the right one shows only its
//     tenant's sessions.
// Prints one JSON line of measurements (load time, update latency) on stdout.
import net from 'node:net';
import { chromium } from 'playwright-core';

const args = JSON.parse(process.argv[2]);
const TIMEOUT_MS = 60000;  // bounds a broken setup only; nothing is timed against it

function check(condition, what) {
  if (!condition) throw new Error(`check failed: ${what}`);
}

function quantile(xs, q) {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : NaN;
}

async function fleetStates(page) {
  return page.$$eval('#fleet tbody tr', (rows) =>
    Object.fromEntries(rows.map((r) => [r.dataset.name, r.dataset.state])));
}

// A TCP relay on a free loopback port to `url`'s host and port; cut()
// closes every connection through it (the browser sees the server go away).
function startRelay(url) {
  const target = new URL(url);
  const pairs = new Set();
  const server = net.createServer((client) => {
    const upstream = net.connect(Number(target.port), target.hostname);
    const pair = [client, upstream];
    pairs.add(pair);
    const drop = () => {
      client.destroy();
      upstream.destroy();
      pairs.delete(pair);
    };
    for (const s of pair) {
      s.on('error', drop);
      s.on('close', drop);
    }
    client.pipe(upstream);
    upstream.pipe(client);
  });
  return new Promise((resolve) => {
    server.listen(0, '127.0.0.1', () =>
      resolve({
        url: `http://127.0.0.1:${server.address().port}`,
        cut: () => {
          const n = pairs.size;
          for (const [a, b] of [...pairs]) {
            a.destroy();
            b.destroy();
          }
          pairs.clear();
          return n;
        },
        close: () => server.close(),
      }));
  });
}

// Waits until `kind`'s overlay image has loaded `loads` times, and returns
// what the page recorded (frames shown, naturalWidth).
async function overlayLoads(page, kind, loads) {
  await page.waitForFunction(([k, n]) => {
    const img = document.getElementById(`overlay-${k}`);
    return window.slapseMetrics.overlays[k].loads >= n && img.complete && img.naturalWidth > 0;
  }, [kind, loads]);
  return page.evaluate((k) => ({
    ...window.slapseMetrics.overlays[k],
    naturalWidth: document.getElementById(`overlay-${k}`).naturalWidth,
    alt: document.getElementById(`overlay-${k}`).alt,
  }), kind);
}

async function launch() {
  return chromium.launch({
    executablePath: process.env.SLAPSE_CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
  });
}

// The token login: / is the sign-in form, a wrong token says so, the right
// one shows the fleet of its tenant only.
async function authScenario() {
  const browser = await launch();
  const out = {};
  try {
    const context = await browser.newContext({ viewport: { width: 1280, height: 860 } });
    const page = await context.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    page.setDefaultTimeout(TIMEOUT_MS);
    // A session page without a token is the sign-in form too, with no data.
    await page.goto(`${args.url}/session.html?name=${encodeURIComponent(args.mine)}`);
    await page.waitForSelector('form[action="/login"] input[name="token"]');
    check(!(await page.content()).includes(args.mine), 'no session name on the sign-in page');
    const api = await page.evaluate(async () => (await fetch('/api/sessions')).status);
    check(api === 401, `the API without a token is 401, got ${api}`);
    await page.goto(`${args.url}/`);
    await page.waitForSelector('form[action="/login"] input[name="token"]');
    check(await page.isHidden('#failed'), 'no refusal shown before a try');
    await page.screenshot({ path: `${args.out}/dashboard-login.png` });
    // A wrong token: back on the form, which says it was refused.
    await page.fill('input[name="token"]', 'not-the-token-0123456789');
    await Promise.all([page.waitForURL(/login=failed/), page.click('form[action="/login"] button')]);
    await page.waitForSelector('#failed:not([hidden])');
    out.refused_message = await page.textContent('#failed');
    check(out.refused_message.includes('not valid'), `refusal message: ${out.refused_message}`);
    check((await context.cookies()).every((c) => c.name !== 'slapse_token'), 'no cookie for a wrong token');
    // The right token: the fleet of its tenant, the other tenant's session absent.
    await page.fill('input[name="token"]', args.token);
    await Promise.all([page.waitForURL((u) => u.search === ''), page.click('form[action="/login"] button')]);
    await page.waitForFunction(() => document.querySelectorAll('#fleet tbody tr').length >= 1);
    const rows = await fleetStates(page);
    out.rows = rows;
    check(args.mine in rows, `own session listed: ${JSON.stringify(rows)}`);
    check(!(args.theirs in rows), `other tenant's session absent: ${JSON.stringify(rows)}`);
    check(Object.keys(rows).length === 1, `one row: ${JSON.stringify(rows)}`);
    const cookie = (await context.cookies()).find((c) => c.name === 'slapse_token');
    check(cookie && cookie.httpOnly && cookie.sameSite === 'Strict', `HttpOnly SameSite=Strict cookie: ${JSON.stringify(cookie)}`);
    check(await page.evaluate(() => document.cookie === ''), 'the token is not readable by scripts');
    // Their session's page: the API says not found, nothing of it shows.
    await page.goto(`${args.url}/session.html?name=${encodeURIComponent(args.theirs)}`);
    await page.waitForFunction(() => document.querySelector('#status.error'));
    out.theirs_message = await page.textContent('#status');
    check(/no session .* on this server/.test(out.theirs_message), `their session is unknown to this tenant: ${out.theirs_message}`);
    check(errors.length === 0, `no page errors: ${errors.join('; ')}`);
  } finally {
    await browser.close();
  }
  console.log(JSON.stringify(out));
}

async function main() {
  if (args.mode === 'auth') return authScenario();
  const relay = await startRelay(args.url);
  const browser = await launch();
  const out = {};
  try {
    const context = await browser.newContext({ viewport: { width: 1280, height: 860 } });
    const page = await context.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    page.setDefaultTimeout(TIMEOUT_MS);

    // The fleet: both sessions, with their states.
    const t0 = Date.now();
    await page.goto(`${relay.url}/`);
    await page.waitForFunction((n) => document.querySelectorAll('#fleet tbody tr').length >= n, 2);
    out.fleet_load_ms = Date.now() - t0;
    out.fleet_first_render_ms = await page.evaluate(() => window.slapseMetrics.firstRenderMs);
    await page.waitForFunction(([live, upload]) => {
      const state = (n) => document.querySelector(`#fleet tbody tr[data-name="${n}"]`)?.dataset.state;
      return state(live) === 'RUNNING' && state(upload) === 'FINISHED';
    }, [args.live, args.upload]);
    const states = await fleetStates(page);
    check(Object.keys(states).length === 2, `two rows, got ${JSON.stringify(states)}`);
    const liveRow = page.locator(`#fleet tbody tr[data-name="${args.live}"]`);
    check((await liveRow.locator('td').nth(0).textContent()) === 'rtsp_push', 'live row source rtsp_push');
    check((await liveRow.textContent()).includes('site=north'), 'live row shows its labels');
    // The finished upload shows the share of its steps that planes measured.
    const uploadRow = page.locator(`#fleet tbody tr[data-name="${args.upload}"]`);
    check(/\d+ %/.test(await uploadRow.textContent()), 'upload row shows its scale support');

    // The filter box passes an AIP-160 filter: only the upload is left.
    await page.fill('#filter', 'source = upload');
    await page.press('#filter', 'Enter');
    await page.waitForFunction(() => document.querySelectorAll('#fleet tbody tr').length === 1);
    check(Object.keys(await fleetStates(page))[0] === args.upload, 'filter keeps the upload');
    // A bad filter shows the server's INVALID_ARGUMENT message.
    await page.fill('#filter', 'state = = RUNNING');
    await page.press('#filter', 'Enter');
    await page.waitForFunction(() => document.querySelector('#status.error'));
    out.bad_filter_message = await page.textContent('#status');
    await page.fill('#filter', '');
    await page.press('#filter', 'Enter');
    await page.waitForFunction(() => document.querySelectorAll('#fleet tbody tr').length === 2);
    // Sorting by a column header (keyboard: focus + Enter) orders by fps descending.
    await page.focus('#fleet thead button:text("fps")');
    await page.keyboard.press('Enter');
    await page.keyboard.press('Enter');
    await page.waitForFunction(() => document.querySelector('th[aria-sort="descending"]'));
    await page.screenshot({ path: `${args.out}/dashboard-fleet.png` });

    // One session: the trajectory grows while the camera streams.
    const t1 = Date.now();
    await page.click(`#fleet a[href*="${encodeURIComponent(args.live)}"]`);
    await page.waitForURL(/session\.html/);
    await page.waitForFunction(() => Number(document.getElementById('top').dataset.points || 0) > 0);
    out.session_load_ms = Date.now() - t1;
    out.session_first_render_ms = await page.evaluate(() => window.slapseMetrics.firstRenderMs);
    const before = await page.evaluate(() => window.slapseMetrics.points);
    await page.waitForFunction((n) => window.slapseMetrics.points > n + 20, before);
    await page.waitForFunction(() => window.slapseMetrics.latenciesMs.length >= 10);
    const after = await page.evaluate(() => window.slapseMetrics.points);
    out.points_before = before;
    out.points_after = after;
    const lat = await page.evaluate(() => window.slapseMetrics.latenciesMs);
    out.update_events = lat.length;
    out.update_latency_ms_median = quantile(lat, 0.5);
    out.update_latency_ms_p95 = quantile(lat, 0.95);

    // The newest anchor's overlays: loaded (a decoded PNG) and updated as
    // the camera streams (a later frame each time).
    for (const kind of ['mv', 'planes']) {
      const first = await overlayLoads(page, kind, 1);
      const later = await overlayLoads(page, kind, first.loads + 2);
      check(later.naturalWidth > 0, `${kind} overlay decoded`);
      const frames = later.frames;
      check(frames[frames.length - 1] > frames[0], `${kind} overlay updates: frames ${frames}`);
      check(later.alt.includes(String(frames[frames.length - 1])), `${kind} alt names its frame: ${later.alt}`);
      out[`overlay_${kind}_frames`] = frames.length;
      out[`overlay_${kind}_width_px`] = later.naturalWidth;
    }

    // The event stream cut (every connection through the relay closed): the
    // page reconnects by itself with Last-Event-ID and goes on where it was,
    // nothing lost or repeated.
    const opensBefore = await page.evaluate(() => window.slapseMetrics.opens);
    const seqBefore = await page.evaluate(() => window.slapseMetrics.lastSequence);
    out.connections_cut = relay.cut();
    check(out.connections_cut > 0, 'the relay had connections to cut');
    await page.waitForFunction((n) => window.slapseMetrics.opens > n, opensBefore);
    await page.waitForFunction((s) => window.slapseMetrics.lastSequence > s + 5, seqBefore);
    const seqs = await page.evaluate(() => window.slapseMetrics.sequences);
    for (let i = 1; i < seqs.length; i += 1) {
      check(seqs[i] === seqs[i - 1] + 1, `events in sequence across the cut: ${seqs[i - 1]} then ${seqs[i]}`);
    }
    out.events_across_cut = seqs.length;
    // The screenshot shows a pair with planes if one comes within 15 more
    // loads (a pair may have none: the picture then says "0 planes").
    for (let i = 0; i < 15; i += 1) {
      const loads = await page.evaluate(() => window.slapseMetrics.overlays.planes.loads);
      const m = await overlayLoads(page, 'planes', loads + 1);
      out.overlay_planes_shown = m.counts[m.counts.length - 1];
      if (out.overlay_planes_shown > 0) break;
    }
    await page.screenshot({ path: `${args.out}/dashboard-session.png`, fullPage: true });
    await page.setViewportSize({ width: 768, height: 1024 });
    await page.screenshot({ path: `${args.out}/dashboard-session-tablet.png`, fullPage: true });
    await page.setViewportSize({ width: 1280, height: 860 });

    // Downloads: the TUM file has a line per pose.
    const tum = await page.evaluate(async () => (await fetch(document.getElementById('dl-tum').href)).text());
    const tumPoses = tum.split('\n').filter((l) => l && !l.startsWith('#')).length;
    check(tumPoses >= after, `TUM download has >= ${after} poses, got ${tumPoses}`);

    // Stop from the page, with its confirmation dialog.
    await page.click('#stop');
    await page.waitForSelector('#confirm[open]');
    await page.click('#confirm-ok');
    await page.waitForFunction(() => document.getElementById('state').textContent === 'STOPPED');
    check(await page.isDisabled('#stop'), 'stop is disabled once stopped');
    // The event stream ends (event: end) and the page's trajectory equals the server's.
    await page.waitForFunction(() => window.slapseMetrics.ended === true);
    const served = await page.evaluate(async (name) => {
      let n = 0;
      let token = '';
      do {
        const p = await (await fetch(`/api/trajectory?${new URLSearchParams({ name, page_token: token })}`)).json();
        n += (p.points || []).length;
        token = p.next_page_token;
      } while (token);
      return n;
    }, args.live);
    const shown = await page.evaluate(() => window.slapseMetrics.points);
    check(served === shown, `page shows ${shown} poses, server has ${served}`);
    out.final_points = shown;

    // Delete the finished upload from its page: Cancel keeps it, Yes deletes it
    // and returns to the fleet, which then has only the stopped session.
    await page.goto(`${relay.url}/session.html?name=${encodeURIComponent(args.upload)}`);
    await page.waitForFunction(() => document.getElementById('state').textContent === 'FINISHED');
    check(await page.isDisabled('#stop'), 'a finished session cannot be stopped');
    await page.click('#delete');
    await page.click('#confirm button[value="cancel"]');
    const kept = await page.evaluate(async (name) =>
      (await fetch(`/api/session?${new URLSearchParams({ name })}`)).status, args.upload);
    check(kept === 200, `Cancel keeps the session (HTTP ${kept})`);
    await page.click('#delete');
    await page.click('#confirm-ok');
    await page.waitForURL((u) => u.pathname === '/');
    await page.waitForFunction(() => document.querySelectorAll('#fleet tbody tr').length === 1);
    const left = await fleetStates(page);
    check(left[args.live] === 'STOPPED' && !(args.upload in left), `fleet after delete: ${JSON.stringify(left)}`);
    check(errors.length === 0, `no page errors: ${errors.join('; ')}`);
  } finally {
    await browser.close();
    relay.close();
  }
  console.log(JSON.stringify(out));
}

main().catch((e) => {
  console.error(e.stack || String(e));
  process.exit(1);
});
