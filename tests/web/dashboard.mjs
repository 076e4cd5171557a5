// Drives Debian's headless Chromium (playwright-core) through a running slapse
// dashboard; run by tests/dashboard_test.cc, which starts the server, the
// camera and the sessions. Each step asserts; a failure exits 1 with why.
//   node dashboard.mjs '{"url": "http://127.0.0.1:PORT", "live": "sessions/..",
//                        "upload": "sessions/..", "out": "/tmp/dir"}'
// Prints one JSON line of measurements (load time, update latency) on stdout.
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

async function main() {
  const browser = await chromium.launch({
    executablePath: process.env.SLAPSE_CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
  });
  const out = {};
  try {
    const context = await browser.newContext({ viewport: { width: 1280, height: 860 } });
    const page = await context.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    page.setDefaultTimeout(TIMEOUT_MS);

    // The fleet: both sessions, with their states.
    const t0 = Date.now();
    await page.goto(`${args.url}/`);
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
    await page.goto(`${args.url}/session.html?name=${encodeURIComponent(args.upload)}`);
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
  }
  console.log(JSON.stringify(out));
}

main().catch((e) => {
  console.error(e.stack || String(e));
  process.exit(1);
});
