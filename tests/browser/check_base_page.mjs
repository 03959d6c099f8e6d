// Loads the base station page in headless chromium (Playwright), waits until it has drawn the map and
// the robots, checks canvas pixels where a map tile and a robot are known to be, saves a screenshot.
//   node check_base_page.mjs --url http://127.0.0.1:PORT/ --out DIR [--tiles N] [--robots N] [--regions N]
//        [--visited N] [--failed N] [--objects N] [--probe x,y,r,g,b ...] [--robot-probe id,r,g,b ...] [--timeout-s S]
// Exit 0 when every check passed, 1 otherwise (the reason on stderr), 2 on bad arguments.
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import path from 'node:path';

function parse(argv) {
  const a = { tiles: 1, robots: 1, regions: 0, visited: 0, failed: 0, objects: 0, probes: [], robotProbes: [], timeout: 20 };
  for (let i = 2; i < argv.length; i++) {
    const k = argv[i], v = argv[i + 1];
    if (k === '--help') { console.log('usage: node check_base_page.mjs --url URL --out DIR [--tiles N] [--robots N] [--regions N] [--visited N] [--failed N] [--objects N] [--probe x,y,r,g,b] [--robot-probe id,r,g,b] [--timeout-s S]'); process.exit(0); }
    if (v === undefined) { console.error(`check_base_page: ${k} needs a value`); process.exit(2); }
    i++;
    if (k === '--url') a.url = v;
    else if (k === '--out') a.out = v;
    else if (k === '--tiles') a.tiles = +v;
    else if (k === '--robots') a.robots = +v;
    else if (k === '--regions') a.regions = +v;
    else if (k === '--visited') a.visited = +v;
    else if (k === '--failed') a.failed = +v;
    else if (k === '--objects') a.objects = +v;
    else if (k === '--timeout-s') a.timeout = +v;
    else if (k === '--probe') a.probes.push(v.split(',').map(Number));
    else if (k === '--robot-probe') a.robotProbes.push(v.split(',').map(Number));
    else { console.error(`check_base_page: unknown option ${k}`); process.exit(2); }
  }
  if (!a.url || !a.out) { console.error('check_base_page: --url and --out are required'); process.exit(2); }
  return a;
}

const args = parse(process.argv);
const exe = process.env.AG_CHROMIUM || '/usr/bin/chromium';
const t0 = Date.now();
const log = (m) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1)} s] ${m}`);
let browser;
let failed = false;
const fail = (m) => { console.error('FAIL: ' + m); failed = true; };
try {
  browser = await chromium.launch({ executablePath: exe, headless: true, args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'] });
  log(`chromium ${browser.version()} started`);
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(args.url, { waitUntil: 'load', timeout: args.timeout * 1000 });
  log(`loaded ${args.url}`);
  const want = { tiles: args.tiles, robots: args.robots, regions: args.regions, visited: args.visited, failed: args.failed, objects: args.objects };
  try {
    await page.waitForFunction((w) => {
      const s = window.agStats;
      return s && s.connected && s.tiles >= w.tiles && s.drawnTiles >= w.tiles && s.robots >= w.robots && s.drawnRobots >= w.robots &&
        s.regions >= w.regions && s.drawnRegions >= w.regions && s.visited >= w.visited && s.failed >= w.failed && s.objects >= w.objects;
    }, want, { timeout: args.timeout * 1000, polling: 100 });
  } catch (e) {
    fail(`the page did not draw ${JSON.stringify(want)} within ${args.timeout} s`);
  }
  // Let one more animation frame run so that what was counted is on the canvas.
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const stats = await page.evaluate(() => ({ ...window.agStats }));
  log('agStats ' + JSON.stringify(stats));
  const pixel = (x, y) => page.evaluate(([wx, wy]) => {
    const c = document.getElementById('map');
    const [px, py] = window.agView.toCanvas(wx, wy);
    const d = c.getContext('2d').getImageData(Math.round(px), Math.round(py), 1, 1).data;
    return { px: Math.round(px), py: Math.round(py), rgb: [d[0], d[1], d[2]] };
  }, [x, y]);
  const close = (a, b) => a.every((v, i) => Math.abs(v - b[i]) <= 8);
  for (const [x, y, r, g, b] of args.probes) {
    const p = await pixel(x, y);
    log(`map (${x}, ${y}) -> canvas (${p.px}, ${p.py}) rgb ${p.rgb}`);
    if (!close(p.rgb, [r, g, b])) fail(`map point (${x}, ${y}) is drawn rgb(${p.rgb}), expected rgb(${r},${g},${b})`);
  }
  for (const [id, r, g, b] of args.robotProbes) {
    // In one task: draw the current state, then read a point 3 px ahead of the arrow's centre (inside it).
    const p = await page.evaluate((rid) => {
      const s = window.agState && window.agState();
      const rob = s && s.robots.find((q) => q.id === rid && q.has_pose);
      if (!rob) return null;
      window.agView.redraw();
      const [px, py] = window.agView.toCanvas(rob.x, rob.y);
      const qx = Math.round(px + 3 * Math.cos(rob.yaw)), qy = Math.round(py - 3 * Math.sin(rob.yaw));
      const d = document.getElementById('map').getContext('2d').getImageData(qx, qy, 1, 1).data;
      return { at: [rob.x, rob.y], px: qx, py: qy, rgb: [d[0], d[1], d[2]] };
    }, id);
    if (!p) { fail(`robot ${id} has no pose on the page`); continue; }
    const at = p.at;
    log(`robot ${id} at (${at[0].toFixed(1)}, ${at[1].toFixed(1)}) -> canvas (${p.px}, ${p.py}) rgb ${p.rgb}`);
    if (!close(p.rgb, [r, g, b])) fail(`robot ${id}'s arrow is drawn rgb(${p.rgb}), expected rgb(${r},${g},${b})`);
  }
  fs.mkdirSync(args.out, { recursive: true });
  const shot = path.join(args.out, 'base_station_page.png');
  await page.screenshot({ path: shot });
  log(`screenshot ${shot}`);
  if (errors.length) fail('page errors: ' + errors.join(' | '));
} catch (e) {
  fail(String(e && e.stack || e));
} finally {
  if (browser) await browser.close();
}
process.exit(failed ? 1 : 0);
