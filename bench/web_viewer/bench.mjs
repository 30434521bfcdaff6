// The web viewer under load, in Debian's Chromium (headless, SwiftShader):
// a session of a generated mesh (a bumpy sphere, ~134k and ~1M vertices)
// driven at 30 Hz by the CLI, watched by the page with a normal canvas and a
// 64×64 one (software GL rasterises on the CPU: the small canvas isolates the
// page's own work). Prints a table; not a test.
//
//   node bench/web_viewer/bench.mjs [--sizes 134k,1m] [--seconds 10] [--trace-out DIR] [--no-trace]
//   node bench/web_viewer/bench.mjs --detail [--sizes 1m] [--budgets 16384,65536,262144,full] [--canvas full|64] [--seconds 10]
//
// The first form measures full detail (detail=full). --detail measures the
// levels of detail instead: one page per budget (detail=BUDGET) on the
// normal canvas (--canvas 64: the 64×64 one), driven as above; per budget the
// level drawn, frames arrived/applied/drawn per second, the longest
// main-thread task and the most of our JavaScript in one task (from the
// trace, split as below), the draw call, and then, still driven, a switch
// chosen in the panel (to Full; on the full row to 65,536): the time to the
// new level's third frame, the page's own time for the swap, and the longest
// task meanwhile.
//
// Needs the viewer build (web_viewer/build.sh), filigree-server and the CLI
// (FILIGREE_SERVER, FILIGREE_CLI as in web_viewer/test/harness.mjs), chromium.
//
// What each column means:
//   arrived/applied/drawn   frames per second off the stream, finished by the
//                           session worker and swapped in, drawn (new versions)
//   long tasks              main-thread tasks over 50 ms while driven: count,
//                           share of the time, longest (PerformanceObserver)
//   JS/applied              main-thread JavaScript per applied frame, the draw
//                           calls' time excluded: CDP ScriptDuration (which
//                           includes the bench's own calls into the page) /
//                           our JavaScript in the trace (below)
//   draw                    renderer.render per draw (uploads + draw calls; on
//                           a real GPU the rasterising is not the main thread's)
//   click, drag step        from the input event's time stamp to its handler
//                           (input delay) and to the next animation frame
//   load                    page open → first frame drawn; the longest task meanwhile
//
// From a Chrome trace of the same window (the page's renderer main thread,
// top-level tasks):
//   tasks > 50 ms           all of them / those holding over 50 ms of our JavaScript
//   longest task of our JS  the most JavaScript of ours in one task (wall time),
//                           with that task's CPU time on the thread: far less
//                           means the thread waited or was not scheduled
//   longest task            the longest task split into our JavaScript / the
//                           draw call / everything else, and in parentheses
//                           how much of that is the compositor reading the
//                           WebGL canvas back (GLES2::ReadPixels: software
//                           compositing, on this thread, after each draw;
//                           it waits for the GPU process to finish the draw),
//                           then the task's CPU time on the thread
// "Our JavaScript" is the union of the script events (FunctionCall,
// EvaluateScript, FireAnimationFrame, TimerFire, EventDispatch,
// HandlePostMessage, v8 execution, microtasks…; nested ones counted once)
// without the GC and forced style/layout inside them, without the bench's own
// calls (Playwright's, which arrive as DevTools messages) and without the draw
// call. The draw call is renderer.render, which the page adds to
// __filigree.drawMsTotal; the bench marks each as a User Timing measure
// 'filigree-draw' through that field (the page itself is not changed).
// Tracing costs the renderer some time too (--no-trace: without it, and
// without these columns).
//
// After the table, the targets: at ~134k vertices, ≥ 95 % of arriving frames
// applied, ≤ 3 ms of JavaScript per applied frame, no task of our JavaScript
// over 50 ms, a click answered in ≤ 100 ms; at ~1M, no task of ours over
// 200 ms once loaded, a click in ≤ 200 ms, progress shown while loading. They
// are judged on the 64×64 canvas row, the page's own work (software GL
// rasterises on the CPU, so the full canvas measures SwiftShader too).
//
//   --trace-out DIR   also write each trace there (open in DevTools' Performance panel)

import { spawn } from 'node:child_process';
import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { cpus, loadavg, tmpdir } from 'node:os';
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
const SIZES = { '134k': [260, 516], '300k': [388, 776], '1m': [708, 1416] };  // rings, segments: (rings − 1)·segments + 2 vertices
const DETAIL = args.includes('--detail');
const sizes = option('sizes', DETAIL ? '1m' : '134k,1m').split(',');
const BUDGETS = option('budgets', '16384,65536,262144,full').split(',');
const DETAIL_CANVAS = option('canvas', 'full');
const SECONDS = Number(option('seconds', '10'));
const TRACE_OUT = option('trace-out', null);
const TRACE = !args.includes('--no-trace');

// What the trace records (Debian's Chromium): top-level tasks, the DevTools
// timeline's script/layout/paint events, v8, blink, the compositor and GPU
// client calls (GLES2::ReadPixels), User Timing.
const TRACE_CATEGORIES = ['toplevel', 'devtools.timeline', 'disabled-by-default-devtools.timeline', 'v8', 'v8.execute',
  'blink', 'blink.user_timing', 'gpu', 'cc', '__metadata'];
const TASK_EVENTS = new Set(['RunTask', 'ThreadControllerImpl::RunTask']);
const SCRIPT_EVENTS = new Set(['FunctionCall', 'EvaluateScript', 'FireAnimationFrame', 'FireIdleCallback', 'TimerFire',
  'EventDispatch', 'HandlePostMessage', 'XHRReadyStateChange', 'XHRLoad', 'RunMicrotasks', 'v8.callFunction', 'v8.run',
  'v8.compile', 'v8.compileModule', 'v8.evaluateModule', 'V8.Execute']);
// Not ours even when inside a script event: garbage collection, style and layout.
const NOT_SCRIPT = (name) => /^(MinorGC|MajorGC|V8\.GC|BlinkGC|CppGC)/.test(name) ||
  ['UpdateLayoutTree', 'Layout', 'Document::UpdateStyleAndLayout'].includes(name);
const READBACK = 'GLES2::ReadPixels';
const DEVTOOLS = 'DevTools message (the bench)';

// Installed before the page's own scripts: long tasks, the delay of clicks
// and pointer moves, and the page's draws as User Timing measures
// 'filigree-draw' (they land in the trace): the page adds each
// renderer.render time to __filigree.drawMsTotal right after the draw, so an
// accessor on that field marks [end − time, end].
function instrument() {
  const bench = window.__bench = { longtasks: [], inputs: [] };
  let hook;
  Object.defineProperty(window, '__filigree', {
    configurable: true,
    get: () => hook,
    set: (value) => {
      hook = value;
      let total = value.drawMsTotal ?? 0;
      Object.defineProperty(value, 'drawMsTotal', {
        configurable: true,
        enumerable: true,
        get: () => total,
        set: (next) => {
          const ms = next - total;
          total = next;
          if (ms > 0) {
            const end = performance.now();
            performance.measure('filigree-draw', { start: end - ms, end });
            performance.clearMeasures('filigree-draw');  // the trace has it; keep the buffer empty
          }
        },
      });
    },
  });
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
const count = (x) => (Number.isFinite(x) ? String(x) : '–');

// `detail`: the page's detail= (full detail by default: what this bench
// measured before levels of detail; --detail passes each budget).
async function measure(browser, baseUrl, grpc, session, small, label, detail = 'full') {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 } });
  const page = await context.newPage();
  await page.addInitScript(instrument);
  const cdp = await context.newCDPSession(page);
  await cdp.send('Performance.enable');
  const opened = Date.now();
  await page.goto(`${baseUrl}/?session=${session.session_id}&detail=${detail}#token=${session.viewer_token}`);
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

  // --detail: long enough for the switch after the window too (the driver is stopped after it).
  const driver = spawn(CLI, driveArgs(grpc, session, 'bend', Math.round(30 * (SECONDS + (DETAIL ? 300 : 4))), 30,
    small ? 'bench-64' : 'bench'),
    { stdio: 'ignore' });
  const driverDone = new Promise((done) => driver.on('exit', done));
  await page.waitForFunction(() => window.__filigree.framesApplied >= 3, null, { timeout: 120_000 });
  // At the level asked for (as the server rounds the budget), a few of its frames in.
  await page.waitForFunction(() => window.__filigree.levelVertices === window.__filigree.detailTarget
    && window.__filigree.framesAtLevel >= 3, null, { timeout: 180_000 });
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
  if (TRACE) await startTrace(cdp);
  await page.evaluate(() => performance.mark('filigree-bench-start'));
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
  await page.evaluate(() => performance.mark('filigree-bench-end'));
  let tasks = { traceLong: NaN, traceLongOurs: NaN, ourLongest: NaN, longestTask: null, traceJs: NaN, during: null };
  if (TRACE) {
    const trace = await endTrace(cdp);
    if (TRACE_OUT) {
      mkdirSync(TRACE_OUT, { recursive: true });
      writeFileSync(join(TRACE_OUT, `viewer-${label}-${small ? '64x64' : 'full'}.json`), trace.text);
    }
    tasks = taskSplit(trace.events);
    if (tasks.traceDraws === 0 && b.draws > a.draws) {
      process.stderr.write('bench: no draw in the trace though the page drew: the draw call is counted as JavaScript ' +
        '(the bench marks draws when the page assigns window.__filigree; see instrument())\n');
    }
  }
  const window_ = await page.evaluate(([t0, t1, i0, i1]) => ({
    longtasks: window.__bench.longtasks.filter((t) => t.start >= t0 && t.start < t1),
    inputs: window.__bench.inputs.slice(i0, i1),
  }), [a.now, b.now, a.inputs, b.inputs]);
  const level = await page.evaluate(() => ({ vertices: window.__filigree.levelVertices, full: window.__filigree.fullVertexCount }));
  const switched = DETAIL ? await measureSwitch(page, cdp, level.vertices === level.full ? '65536' : 'full') : null;
  driver.kill('SIGTERM');
  await driverDone;
  await context.close();

  const seconds = (b.now - a.now) / 1000;
  const applied = b.applied - a.applied;
  const clicks = window_.inputs.filter((x) => x.type === 'click');
  const moves = window_.inputs.filter((x) => x.type === 'pointermove');
  const longSum = window_.longtasks.reduce((s, t) => s + t.duration, 0);
  // The slowest click to its next frame, and what the main thread ran meanwhile.
  const worst = clicks.filter((c) => c.painted !== null).sort((x, y) => y.painted - x.painted)[0];
  const clickWorst = worst && tasks.during ? tasks.during(worst.at - worst.delay, worst.at - worst.delay + worst.painted) : null;
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
    traceJsPerApplied: tasks.traceJs / Math.max(1, applied),
    drawPerDraw: (b.drawMs - a.drawMs) / Math.max(1, b.draws - a.draws),
    clickDelay: Math.max(...clicks.map((c) => c.delay)),
    clickPaint: Math.max(...clicks.map((c) => c.painted ?? NaN)),
    moveDelay: median(moves.map((m) => m.delay)),
    movePaint: Math.max(...moves.map((m) => m.painted ?? NaN)),
    loadMs, loadLongest, stages: [...stages].join('→'),
    ...tasks,
    clickWorst,
    level: level.vertices,
    switched,
  };
}

// While driven: another level chosen in the panel (`to`); the time to the
// new level's third frame swapped in, the page's own time for the swap
// (hook.levelSwapMs), and from a trace of that time the longest main-thread
// task split as in taskSplit.
async function measureSwitch(page, cdp, to) {
  if (TRACE) await startTrace(cdp);
  await page.evaluate(() => performance.mark('filigree-bench-start'));
  const swaps = await page.evaluate(() => window.__filigree.levelSwaps);
  const t0 = Date.now();
  await page.selectOption('#detail', to);
  await page.waitForFunction((s) => window.__filigree.levelSwaps > s && window.__filigree.framesAtLevel >= 3, swaps,
    { timeout: 180_000 });
  const ms = Date.now() - t0;
  await page.evaluate(() => performance.mark('filigree-bench-end'));
  const h = await page.evaluate(() => ({ vertices: window.__filigree.levelVertices, swapMs: window.__filigree.levelSwapMs }));
  const tasks = TRACE ? taskSplit((await endTrace(cdp)).events) : null;
  return { to: h.vertices, ms, swapMs: h.swapMs, longestTask: tasks?.longestTask ?? null, ourLongest: tasks?.ourLongest ?? NaN };
}

// Tracing over the measured window, read back as a stream.
async function startTrace(cdp) {
  await cdp.send('Tracing.start', {
    transferMode: 'ReturnAsStream',
    traceConfig: { recordMode: 'recordAsMuchAsPossible', includedCategories: TRACE_CATEGORIES, excludedCategories: ['*'] },
  });
}

async function endTrace(cdp) {
  const complete = new Promise((done) => cdp.once('Tracing.tracingComplete', done));
  await cdp.send('Tracing.end');
  const { stream, dataLossOccurred } = await complete;
  if (dataLossOccurred) process.stderr.write('bench: the trace buffer overflowed; some events are missing\n');
  const chunks = [];
  for (;;) {
    const { data, base64Encoded, eof } = await cdp.send('IO.read', { handle: stream, size: 1 << 22 });
    chunks.push(Buffer.from(data, base64Encoded ? 'base64' : 'utf8'));
    if (eof) break;
  }
  await cdp.send('IO.close', { handle: stream });
  const text = Buffer.concat(chunks).toString('utf8');
  const parsed = JSON.parse(text);
  return { text, events: Array.isArray(parsed) ? parsed : parsed.traceEvents };
}

// Sorted, disjoint [start, end] intervals.
function union(intervals) {
  const sorted = [...intervals].sort((x, y) => x[0] - y[0]);
  const out = [];
  for (const [s, e] of sorted) {
    if (e <= s) continue;
    if (out.length > 0 && s <= out[out.length - 1][1]) out[out.length - 1][1] = Math.max(out[out.length - 1][1], e);
    else out.push([s, e]);
  }
  return out;
}
const total = (list) => list.reduce((sum, [s, e]) => sum + e - s, 0);
function intersect(x, y) {  // both from union()
  const out = [];
  for (let i = 0, j = 0; i < x.length && j < y.length;) {
    const s = Math.max(x[i][0], y[j][0]);
    const e = Math.min(x[i][1], y[j][1]);
    if (s < e) out.push([s, e]);
    if (x[i][1] < y[j][1]) ++i; else ++j;
  }
  return out;
}
const minus = (x, y) => {  // both from union()
  const out = [];
  for (const [s, e] of x) {
    let at = s;
    for (const [cs, ce] of y) {
      if (ce <= at || cs >= e) continue;
      if (cs > at) out.push([at, cs]);
      at = Math.max(at, ce);
    }
    if (at < e) out.push([at, e]);
  }
  return out;
};

// The page's renderer main thread between the bench's two marks: each
// top-level task split into our JavaScript, the draw call and the rest (µs).
function taskSplit(events) {
  const mark = (name) => events.find((e) => e.name === name && e.cat?.includes('blink.user_timing'));
  const from = mark('filigree-bench-start');
  const to = mark('filigree-bench-end');
  if (!from || !to) throw new Error('the trace lacks the bench marks (blink.user_timing)');
  const { pid, tid } = from;  // marks are made on the page's main thread (CrRendererMain)
  const main = events.filter((e) => e.pid === pid && e.tid === tid && e.ts >= from.ts - 5e6 && e.ts <= to.ts + 5e6);
  // Complete events, and begin/end pairs made complete.
  const spans = [];
  const open = [];
  for (const e of main) {
    if (e.ph === 'X' && e.dur !== undefined) {
      // The bench's own calls (Playwright's evaluations and actionability checks) arrive over DevTools.
      const name = e.name === 'Receive mojo message' &&
        e.args?.chrome_mojo_event_info?.mojo_interface_tag === 'blink.mojom.DevToolsSession' ? DEVTOOLS : e.name;
      spans.push({ name, start: e.ts, end: e.ts + e.dur, cpu: e.tdur });
    }
    else if (e.ph === 'B') open.push(e);
    else if (e.ph === 'E' && open.length > 0) {
      const b = open.pop();
      spans.push({ name: b.name, start: b.ts, end: e.ts });
    }
  }
  // The draws: async measures ('b'/'e' by id), on the same thread.
  const drawBegin = new Map();
  const draws = [];
  for (const e of main) {
    if (e.name !== 'filigree-draw') continue;
    const id = e.id ?? e.id2?.local ?? e.id2?.global;
    if (e.ph === 'b') drawBegin.set(id, e.ts);
    else if (e.ph === 'e' && drawBegin.has(id)) {
      draws.push([drawBegin.get(id), e.ts]);
      drawBegin.delete(id);
    }
  }
  const tasks = [];
  let outerEnd = -Infinity;
  for (const s of spans.filter((x) => TASK_EVENTS.has(x.name)).sort((x, y) => x.start - y.start || y.end - x.end)) {
    if (s.start < outerEnd) continue;  // nested in the one before
    outerEnd = s.end;
    if (s.start >= from.ts && s.start < to.ts) tasks.push({ ...s, inner: [] });
  }
  let i = 0;
  const inner = spans.filter((x) => !TASK_EVENTS.has(x.name)).sort((x, y) => x.start - y.start);
  for (const task of tasks) {
    while (i < inner.length && inner[i].start < task.start) ++i;
    for (let k = i; k < inner.length && inner[k].start < task.end; ++k) task.inner.push(inner[k]);
  }
  const drawUnion = union(draws);
  // Each task as intervals: all of it, our script (with the draw), the draw, the readback outside our script.
  const parts = tasks.map((task) => {
    const clip = (list) => intersect(union(list), [[task.start, task.end]]);
    const script = minus(clip(task.inner.filter((x) => SCRIPT_EVENTS.has(x.name)).map((x) => [x.start, x.end])),
      union(task.inner.filter((x) => NOT_SCRIPT(x.name) || x.name === DEVTOOLS).map((x) => [x.start, x.end])));
    return {
      all: [[task.start, task.end]], cpu: task.cpu / 1000, script, draw: intersect(script, drawUnion),
      readback: minus(clip(task.inner.filter((x) => x.name === READBACK).map((x) => [x.start, x.end])), script),
    };
  });
  // Our JavaScript (draw apart), the draw, the rest and its readback, in ms, of the tasks' time within [from, to] (µs).
  const splitOf = (list, from = -Infinity, to = Infinity) => {
    const within = (x) => total(intersect(x, [[from, to]])) / 1000;
    let dur = 0;
    let js = 0;
    let draw = 0;
    let readback = 0;
    for (const p of list) {
      dur += within(p.all);
      draw += within(p.draw);
      js += within(p.script) - within(p.draw);
      readback += within(p.readback);
    }
    return { dur, js, draw, other: dur - js - draw, readback };
  };
  const split = parts.map((p) => ({ ...splitOf([p]), cpu: p.cpu }));
  const long = split.filter((t) => t.dur > 50);
  const longest = split.reduce((x, t) => (x === null || t.dur > x.dur ? t : x), null);
  // performance.now() (ms) → trace time (µs), by the start mark.
  const toTrace = (ms) => from.ts + (ms - from.args.data.startTime) * 1000;
  return {
    // What the main thread ran between two performance.now() times.
    during: (a, b) => {
      const [ta, tb] = [toTrace(a), toTrace(b)];
      return { ...splitOf(parts.filter((p) => p.all[0][1] > ta && p.all[0][0] < tb), ta, tb), ms: b - a };
    },
    traceLong: long.length,
    traceLongOurs: long.filter((t) => t.js > 50).length,
    ourLongest: Math.max(0, ...split.map((t) => t.js)),
    // The thread's CPU time in that task (the rest of its wall time it waited or was not scheduled).
    ourLongestCpu: split.reduce((x, t) => (x === null || t.js > x.js ? t : x), null)?.cpu ?? NaN,
    longestTask: longest,
    traceJs: split.reduce((sum, t) => sum + t.js, 0),
    traceDraws: draws.length,
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
      if (DETAIL) {
        for (const budget of BUDGETS) {
          const r = await measure(browser, `http://${http}`, grpc, session, DETAIL_CANVAS === '64', `${size}-${budget}`, budget);
          rows.push({ vertices: n, budget, ...r });
          process.stderr.write(`bench: ${n} at ${budget} (${r.level} vertices) done\n`);
        }
        continue;
      }
      for (const small of [false, true]) {
        const r = await measure(browser, `http://${http}`, grpc, session, small, size);
        rows.push({ vertices: n, ...r });
        process.stderr.write(`bench: ${n} ${r.canvas} done\n`);
      }
    }
  } finally {
    await browser?.close();
    await stopServer(server, 20_000);
    rmSync(work, { recursive: true, force: true });
  }
  if (DETAIL) {
    printDetail(rows);
    return;
  }
  const header = ['vertices', 'canvas', 'arrived/s', 'applied/s', 'drawn/s', 'applied %', 'long tasks', 'long %',
    'longest ms', 'tasks > 50 ms: all / our JS > 50', 'longest task of our JS ms (task CPU)', 'longest task: JS / draw / other (readback); CPU ms',
    'JS/applied ms: CDP / trace', 'own/applied ms', 'draw ms', 'click delay/paint ms', 'drag step delay/paint ms',
    'load s', 'load longest ms', 'progress shown'];
  const split = (t) => (t ? `${fmt(t.js)} / ${fmt(t.draw)} / ${fmt(t.other, 0)} (${fmt(t.readback, 0)}); ${fmt(t.cpu, 0)}` : '–');
  const table = rows.map((r) => [r.vertices.toLocaleString('en-US'), r.canvas, fmt(r.arrived), fmt(r.applied), fmt(r.drawn),
    fmt(100 * r.appliedShare, 0), String(r.longCount), fmt(100 * r.longShare), fmt(r.longest, 0),
    `${count(r.traceLong)} / ${count(r.traceLongOurs)}`, `${fmt(r.ourLongest)} (${fmt(r.ourLongestCpu)})`, split(r.longestTask), `${fmt(r.jsPerApplied, 2)} / ${fmt(r.traceJsPerApplied, 2)}`,
    fmt(r.ownPerApplied, 2), fmt(r.drawPerDraw), `${fmt(r.clickDelay)}/${fmt(r.clickPaint)}`,
    `${fmt(r.moveDelay)}/${fmt(r.movePaint)}`, fmt(r.loadMs / 1000), fmt(r.loadLongest, 0), r.stages]);
  const widths = header.map((h, i) => Math.max(h.length, ...table.map((row) => row[i].length)));
  const line = (cells) => `| ${cells.map((c, i) => c.padEnd(widths[i])).join(' | ')} |`;
  console.log(line(header));
  console.log(`|${widths.map((w) => '-'.repeat(w + 2)).join('|')}|`);
  for (const row of table) console.log(line(row));
  console.log();
  printTargets(rows);
  const [one, five, fifteen] = loadavg();
  console.log(`\nLoad average at the end: ${fmt(one, 2)}, ${fmt(five, 2)}, ${fmt(fifteen, 2)} ` +
    `(${cpus().length} cores; the server, the CLI driver and Chromium share them).`);
}

// The --detail table: a row per budget.
function printDetail(rows) {
  const split = (t) => (t ? `${fmt(t.dur, 0)}: ${fmt(t.js)} / ${fmt(t.draw)} / ${fmt(t.other, 0)} (${fmt(t.readback, 0)})` : '–');
  const header = ['vertices', 'budget', 'level', 'canvas', 'arrived/s', 'applied/s', 'drawn/s', 'applied %',
    'longest task ms: JS / draw / other (readback)', 'longest task of our JS ms', 'tasks > 50 ms', 'draw ms',
    'switch to', 'switch ms', 'swap task ms', 'longest task while switching: JS / draw / other (readback)'];
  const table = rows.map((r) => [r.vertices.toLocaleString('en-US'), r.budget, r.level.toLocaleString('en-US'), r.canvas,
    fmt(r.arrived), fmt(r.applied), fmt(r.drawn), fmt(100 * r.appliedShare, 0), split(r.longestTask), fmt(r.ourLongest),
    count(r.traceLong), fmt(r.drawPerDraw), r.switched ? r.switched.to.toLocaleString('en-US') : '–',
    r.switched ? fmt(r.switched.ms, 0) : '–', r.switched ? fmt(r.switched.swapMs) : '–', split(r.switched?.longestTask)]);
  const widths = header.map((h, i) => Math.max(h.length, ...table.map((row) => row[i].length)));
  const line = (cells) => `| ${cells.map((c, i) => c.padEnd(widths[i])).join(' | ')} |`;
  console.log(line(header));
  console.log(`|${widths.map((w) => '-'.repeat(w + 2)).join('|')}|`);
  for (const row of table) console.log(line(row));
  const [one, five, fifteen] = loadavg();
  console.log(`\nLoad average at the end: ${fmt(one, 2)}, ${fmt(five, 2)}, ${fmt(fifteen, 2)} ` +
    `(${cpus().length} cores; the server, the CLI driver and Chromium share them).`);
}

// What the main thread ran during the slowest click (from the trace).
function clickLines(own, full) {
  const of = (r) => {
    const w = r?.clickWorst;
    if (!w) return null;
    return `JS ${fmt(w.js)} / draw ${fmt(w.draw)} / other ${fmt(w.other, 0)} (readback ${fmt(w.readback, 0)}) / idle ${fmt(w.ms - w.dur, 0)}`;
  };
  return [own, full].filter((r) => of(r)).map((r) => [`  the slowest click: main thread meanwhile (${r.canvas}), ms`, of(r), null]);
}

// The targets, judged on the 64×64 row of each size (the page's own work);
// the full canvas in parentheses.
function printTargets(rows) {
  console.log('Targets, judged on the 64×64 canvas (the page\'s own work: software GL rasterises on the CPU,');
  console.log('so a full canvas measures SwiftShader as well); the full canvas in parentheses:');
  const verdict = (ok) => (ok === null ? '' : ok ? 'met' : 'NOT MET');
  const check = (x, ok) => (Number.isFinite(x) ? ok(x) : null);  // no verdict without a value (--no-trace)
  for (const vertices of [...new Set(rows.map((r) => r.vertices))]) {
    const own = rows.find((r) => r.vertices === vertices && r.canvas === '64×64');
    const full = rows.find((r) => r.vertices === vertices && r.canvas !== '64×64');
    if (!own) continue;
    const both = (f) => `${f(own)}${full ? ` (${f(full)})` : ''}`;
    const lines = [];
    if (vertices < 500_000) {
      lines.push(['≥ 95 % of arriving frames applied', both((r) => `${fmt(100 * r.appliedShare, 0)} %`), check(own.appliedShare, (x) => x >= 0.95)]);
      // The trace's count when there is one: it leaves the bench's own calls out.
      const js = (r) => (Number.isFinite(r.traceJsPerApplied) ? r.traceJsPerApplied : r.jsPerApplied);
      lines.push(['≤ 3 ms of our JS per applied frame (draw apart)', both((r) => `${fmt(js(r), 2)} ms`), check(js(own), (x) => x <= 3)]);
      lines.push(['no task of our JS over 50 ms', both((r) => `longest ${fmt(r.ourLongest)} ms, task CPU ${fmt(r.ourLongestCpu)}, ${count(r.traceLongOurs)} over`), check(own.ourLongest, (x) => x <= 50)]);
      lines.push(['a click answered (next frame) in ≤ 100 ms', both((r) => `${fmt(r.clickPaint)} ms`), check(own.clickPaint, (x) => x <= 100)]);
      lines.push(...clickLines(own, full));
    } else {
      lines.push(['no task of our JS over 200 ms once loaded', both((r) => `longest ${fmt(r.ourLongest)} ms, task CPU ${fmt(r.ourLongestCpu)}`), check(own.ourLongest, (x) => x <= 200)]);
      lines.push(['a click answered (next frame) in ≤ 200 ms', both((r) => `${fmt(r.clickPaint)} ms`), check(own.clickPaint, (x) => x <= 200)]);
      lines.push(...clickLines(own, full));
      const shown = (r) => r.stages.split('→').filter((x) => x && x !== 'done');
      lines.push(['progress shown while loading', both((r) => shown(r).join('→') || 'none'), shown(own).length > 0]);
    }
    lines.push(['the draw call, apart (per draw; SwiftShader: CPU vertex stage)', both((r) => `${fmt(r.drawPerDraw)} ms`), null]);
    console.log(`${vertices.toLocaleString('en-US')} vertices:`);
    const w = Math.max(...lines.map((l) => l[0].length));
    const v = Math.max(...lines.map((l) => l[1].length));
    for (const [what, value, ok] of lines) console.log(`  ${what.padEnd(w)}  ${value.padEnd(v)}  ${verdict(ok)}`.trimEnd());
  }
}

main().catch((error) => {
  console.error(error);
  process.exit(1);
});
