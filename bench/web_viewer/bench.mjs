// The web viewer under load, in Debian's Chromium (headless, SwiftShader):
// a session of a generated mesh (a bumpy sphere, ~134k and ~1M vertices)
// driven at 30 Hz by the CLI, watched by the page with a normal canvas and a
// 64×64 one (software GL rasterises on the CPU: the small canvas isolates the
// page's own work). Prints a table; not a test.
//
//   node bench/web_viewer/bench.mjs [--sizes 134k,1m] [--seconds 10]
//
// Needs the viewer build (web_viewer/build.sh), filigree-server and the CLI
// (FILIGREE_SERVER, FILIGREE_CLI as in web_viewer/test/harness.mjs), chromium.
//
// What each column means:
//   arrived/applied/drawn   frames per second off the stream, finished by the
//                           session worker and swapped in, drawn (new versions)
//   long tasks              main-thread tasks over 50 ms while driven: count,
//                           share of the time, longest (PerformanceObserver)
//   JS/applied              main-thread JavaScript per applied frame (CDP
//                           ScriptDuration), the draw calls' time excluded
//   draw                    renderer.render per draw (uploads + draw calls; on
//                           a real GPU the rasterising is not the main thread's)
//   click, drag step        from the input event's time stamp to its handler
//                           (input delay) and to the next animation frame
//   load                    page open → first frame drawn; the longest task meanwhile

import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { chromium } from '../../web_viewer/node_modules/playwright-core/index.mjs';
import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, driveArgs, startServer, stopServer, upload, writeBumpySphere,
} from '../../web_viewer/test/harness.mjs';

const args = process.argv.slice(2);
const option = (name, fallback) => {
  const i = args.indexOf(`--${name}`);
  return i >= 0 ? args[i + 1] : fallback;
};
const SIZES = { '134k': [260, 516], '1m': [708, 1416] };  // rings, segments: (rings − 1)·segments + 2 vertices
const sizes = option('sizes', '134k,1m').split(',');
const SECONDS = Number(option('seconds', '10'));

// Installed before the page's own scripts: long tasks, and the delay of clicks and pointer moves.
function instrument() {
  const bench = window.__bench = { longtasks: [], inputs: [] };
  new PerformanceObserver((list) => {
    for (const e of list.getEntries()) bench.longtasks.push({ start: e.startTime, duration: e.duration });
  }).observe({ type: 'longtask', buffered: true });
  for (const type of ['click', 'pointermove']) {
    window.addEventListener(type, (event) => {
      const handled = performance.now();
      const record = { type, delay: handled - event.timeStamp, painted: null, at: handled };
      bench.inputs.push(record);
      requestAnimationFrame(() => { record.painted = performance.now() - event.timeStamp; });
    }, { capture: true });
  }
}

const median = (xs) => (xs.length === 0 ? NaN : [...xs].sort((a, b) => a - b)[Math.floor(xs.length / 2)]);
const fmt = (x, digits = 1) => (Number.isFinite(x) ? x.toFixed(digits) : '–');

async function measure(browser, baseUrl, grpc, session, small) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 } });
  const page = await context.newPage();
  await page.addInitScript(instrument);
  const cdp = await context.newCDPSession(page);
  await cdp.send('Performance.enable');
  const opened = Date.now();
  await page.goto(`${baseUrl}/?session=${session.session_id}#token=${session.viewer_token}`);
  const stages = new Set();
  // Progress is shown while the mesh loads: sample which stages the page showed.
  for (;;) {
    const s = await page.evaluate(() => ({ stage: window.__filigree?.loadStage, live: window.__filigree?.framesRendered >= 1 && window.__filigree.state === 'live' }));
    if (s.stage) stages.add(s.stage);
    if (s.live) break;
    if (Date.now() - opened > 600_000) throw new Error('the page did not show the session within 10 min');
    await page.waitForTimeout(100);
  }
  const loadMs = Date.now() - opened;
  const loadLongest = await page.evaluate(() => Math.max(0, ...window.__bench.longtasks.map((t) => t.duration)));
  if (small) await page.addStyleTag({ content: '#view { flex: none !important; width: 64px !important; height: 64px !important; }' });

  const driver = spawn(CLI, driveArgs(grpc, session, 'bend', Math.round(30 * (SECONDS + 4)), 30, small ? 'bench-64' : 'bench'),
    { stdio: 'ignore' });
  const driverDone = new Promise((done) => driver.on('exit', done));
  await page.waitForFunction(() => window.__filigree.framesApplied >= 3, null, { timeout: 120_000 });
  await page.waitForTimeout(1000);  // past the first frames

  const snapshot = async () => {
    const { metrics } = await cdp.send('Performance.getMetrics');
    const m = Object.fromEntries(metrics.map((x) => [x.name, x.value]));
    const h = await page.evaluate(() => ({
      now: performance.now(), received: window.__filigree.framesReceived, applied: window.__filigree.framesApplied,
      drawn: window.__filigree.framesDrawn, draws: window.__filigree.draws, drawMs: window.__filigree.drawMsTotal,
      pageMs: window.__filigree.pageMsTotal, inputs: window.__bench.inputs.length,
    }));
    return { ...h, script: m.ScriptDuration * 1000 };
  };
  const a = await snapshot();
  // Inputs while driven: clicks on an overlay checkbox, an orbit drag on the canvas.
  const canvas = await page.locator('#view canvas').boundingBox();
  const steps = Math.max(4, Math.floor(SECONDS / 2));
  for (let i = 0; i < steps; ++i) {
    await page.click('#overlay-base');
    await page.waitForTimeout(500);
    const x = canvas.x + canvas.width / 2;
    const y = canvas.y + canvas.height / 2;
    await page.mouse.move(x, y);
    await page.mouse.down();
    for (let k = 1; k <= 5; ++k) await page.mouse.move(x + 4 * k, y + 2 * k);
    await page.mouse.up();
    await page.waitForTimeout(Math.max(0, (SECONDS * 1000) / steps - 600));
  }
  const b = await snapshot();
  const window_ = await page.evaluate(([t0, t1, i0, i1]) => ({
    longtasks: window.__bench.longtasks.filter((t) => t.start >= t0 && t.start < t1),
    inputs: window.__bench.inputs.slice(i0, i1),
  }), [a.now, b.now, a.inputs, b.inputs]);
  driver.kill('SIGTERM');
  await driverDone;
  await context.close();

  const seconds = (b.now - a.now) / 1000;
  const applied = b.applied - a.applied;
  const clicks = window_.inputs.filter((x) => x.type === 'click');
  const moves = window_.inputs.filter((x) => x.type === 'pointermove');
  const longSum = window_.longtasks.reduce((s, t) => s + t.duration, 0);
  return {
    canvas: small ? '64×64' : `${Math.round(canvas.width)}×${Math.round(canvas.height)}`,
    arrived: (b.received - a.received) / seconds,
    applied: applied / seconds,
    drawn: (b.drawn - a.drawn) / seconds,
    appliedShare: applied / Math.max(1, b.received - a.received),
    longCount: window_.longtasks.length,
    longShare: longSum / (b.now - a.now),
    longest: Math.max(0, ...window_.longtasks.map((t) => t.duration)),
    jsPerApplied: (b.script - a.script - (b.drawMs - a.drawMs)) / Math.max(1, applied),
    ownPerApplied: (b.pageMs - a.pageMs) / Math.max(1, applied),
    drawPerDraw: (b.drawMs - a.drawMs) / Math.max(1, b.draws - a.draws),
    clickDelay: Math.max(...clicks.map((c) => c.delay)),
    clickPaint: Math.max(...clicks.map((c) => c.painted ?? NaN)),
    moveDelay: median(moves.map((m) => m.delay)),
    movePaint: Math.max(...moves.map((m) => m.painted ?? NaN)),
    loadMs, loadLongest, stages: [...stages].join('→'),
  };
}

async function main() {
  checkTools();
  const work = mkdtempSync(join(tmpdir(), 'filigree-viewer-bench-'));
  const server = startServer(join(work, 'data'));
  const rows = [];
  let browser;
  try {
    const { grpc, http } = await server.addresses;
    browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
    for (const size of sizes) {
      const [rings, segments] = SIZES[size];
      const file = join(work, `sphere-${size}.ply`);
      const n = writeBumpySphere(file, rings, segments);
      const t0 = Date.now();
      const session = await upload(grpc, file, `bench-${size}`);
      const uploadS = (Date.now() - t0) / 1000;
      process.stderr.write(`bench: ${n} vertices uploaded and preprocessed in ${uploadS.toFixed(1)} s\n`);
      for (const small of [false, true]) {
        const r = await measure(browser, `http://${http}`, grpc, session, small);
        rows.push({ vertices: n, ...r });
        process.stderr.write(`bench: ${n} ${r.canvas} done\n`);
      }
    }
  } finally {
    await browser?.close();
    await stopServer(server, 20_000);
    rmSync(work, { recursive: true, force: true });
  }
  const header = ['vertices', 'canvas', 'arrived/s', 'applied/s', 'drawn/s', 'applied %', 'long tasks', 'long %',
    'longest ms', 'JS/applied ms', 'own/applied ms', 'draw ms', 'click delay/paint ms', 'drag step delay/paint ms',
    'load s', 'load longest ms', 'progress shown'];
  const table = rows.map((r) => [String(r.vertices), r.canvas, fmt(r.arrived), fmt(r.applied), fmt(r.drawn),
    fmt(100 * r.appliedShare, 0), String(r.longCount), fmt(100 * r.longShare), fmt(r.longest, 0), fmt(r.jsPerApplied, 2),
    fmt(r.ownPerApplied, 2), fmt(r.drawPerDraw), `${fmt(r.clickDelay)}/${fmt(r.clickPaint)}`,
    `${fmt(r.moveDelay)}/${fmt(r.movePaint)}`, fmt(r.loadMs / 1000), fmt(r.loadLongest, 0), r.stages]);
  const widths = header.map((h, i) => Math.max(h.length, ...table.map((row) => row[i].length)));
  const line = (cells) => `| ${cells.map((c, i) => c.padEnd(widths[i])).join(' | ')} |`;
  console.log(line(header));
  console.log(`|${widths.map((w) => '-'.repeat(w + 2)).join('|')}|`);
  for (const row of table) console.log(line(row));
}

main().catch((error) => {
  console.error(error);
  process.exit(1);
});
