// The viewer in a real browser against a real filigree-server: Debian's
// Chromium (headless, SwiftShader WebGL) driven by playwright-core, the page
// served by the server itself (--web-root dist) and talking gRPC-Web to it;
// the session is made and driven with the `filigree` CLI.
//
// Environment:
//   FILIGREE_SERVER  the filigree-server binary (required)
//   FILIGREE_CLI     the filigree CLI (default: ../client/filigree beside the server's directory)
//   CHROMIUM         the browser (default /usr/bin/chromium)
// Needs `npm run build` first (dist/); run-tests.sh does both.
//
// No sleeps: every wait is on a condition in the page or on a process, with a timeout.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFile, spawn } from 'node:child_process';
import { existsSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { createInterface } from 'node:readline';
import { fileURLToPath } from 'node:url';

import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const ROOT = resolve(HERE, '..', '..');
const WEB_ROOT = resolve(HERE, '..', 'dist');
const MESH = join(ROOT, 'tests', 'data', 'bunny_small.obj');
const SERVER = process.env.FILIGREE_SERVER && resolve(process.env.FILIGREE_SERVER);
const CLI = resolve(process.env.FILIGREE_CLI ?? join(dirname(SERVER ?? '.'), '..', 'client', 'filigree'));
const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
// TOOLCHAIN.md, Browser.
const CHROMIUM_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync', '--enable-unsafe-swiftshader'];

const HOOK_TIMEOUT_MS = 60_000;
const TEST_TIMEOUT_MS = 90_000;
const WAIT_MS = 30_000;          // for a condition in the page
const STOP_TIMEOUT_MS = 20_000;

// ------------------------------------------------------------------ helpers

// Starts filigree-server with gRPC-Web and the viewer; resolves with both
// addresses once it has printed `listening on H:P` and `http on H:P`.
function startServer(dataDir) {
  const child = spawn(SERVER, ['--listen', '127.0.0.1:0', '--http', '127.0.0.1:0', '--web-root', WEB_ROOT,
    '--data-dir', dataDir, '--log-level', 'warn'], { stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const exited = new Promise((done) => {
    child.on('exit', (code, signal) => done({ code, signal }));
    child.on('error', (error) => done({ code: null, signal: null, error }));
  });
  // If this process dies without running `after`, the server goes with it.
  const kill = () => child.kill('SIGKILL');
  process.on('exit', kill);
  exited.then(() => process.off('exit', kill));
  const addresses = new Promise((done, fail) => {
    const found = {};
    createInterface({ input: child.stdout }).on('line', (line) => {
      const m = /^(listening|http) on (\S+:\d+)$/.exec(line);
      if (m) found[m[1]] = m[2];
      if (found.listening && found.http) done({ grpc: found.listening, http: found.http });
    });
    exited.then(({ code, signal, error }) => fail(new Error(
      `filigree-server exited (code ${code}, signal ${signal}${error ? `, ${error.message}` : ''}) before ` +
      `printing both addresses: ${stderr}`)));
  });
  return { child, exited, addresses, stderr: () => stderr };
}

// Runs the CLI; resolves with its stdout, rejects with its stderr.
function cli(args, timeoutMs = 60_000) {
  return new Promise((done, fail) => {
    execFile(CLI, args, { timeout: timeoutMs }, (error, stdout, stderr) => {
      if (error) fail(new Error(`filigree ${args[0]} failed: ${error.message}\n${stderr}`));
      else done(stdout);
    });
  });
}

// `key: value` lines.
function fields(text) {
  return Object.fromEntries(text.split('\n').map((l) => /^(\w+):\s*(.*)$/.exec(l)).filter(Boolean).map((m) => [m[1], m[2]]));
}

function diagonal(objText) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const line of objText.split('\n')) {
    const f = line.trim().split(/\s+/);
    if (f[0] !== 'v') continue;
    for (let k = 0; k < 3; ++k) { lo[k] = Math.min(lo[k], Number(f[k + 1])); hi[k] = Math.max(hi[k], Number(f[k + 1])); }
  }
  return Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

function png(data) {
  return PNG.sync.read(typeof data === 'string' ? Buffer.from(data.replace(/^data:image\/png;base64,/, ''), 'base64') : data);
}

// The variance of the pixels' luminance: 0 for a uniform (blank) image.
function luminanceVariance(image) {
  let sum = 0;
  let sumSq = 0;
  const n = image.width * image.height;
  for (let i = 0; i < n; ++i) {
    const [r, g, b] = image.data.subarray(4 * i, 4 * i + 3);
    const y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    sum += y;
    sumSq += y * y;
  }
  return sumSq / n - (sum / n) ** 2;
}

// The fraction of pixels whose colour differs by more than `tolerance` in a channel.
function changedFraction(a, b, tolerance = 16) {
  assert.equal(a.width, b.width);
  assert.equal(a.height, b.height);
  let changed = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    if (Math.abs(a.data[i] - b.data[i]) > tolerance || Math.abs(a.data[i + 1] - b.data[i + 1]) > tolerance
        || Math.abs(a.data[i + 2] - b.data[i + 2]) > tolerance) ++changed;
  }
  return changed / (a.width * a.height);
}

const hookState = (page) => page.evaluate(() => {
  const { capture, ...plain } = window.__filigree;  // eslint-disable-line no-unused-vars
  return plain;
});

// ------------------------------------------------------------------ tests

describe('the web viewer in Chromium against filigree-server', { timeout: 10 * TEST_TIMEOUT_MS }, () => {
  let server;
  let dataDir;
  let baseUrl;       // http://H:P of the server's HTTP face
  let grpcAddress;
  let browser;
  let session;       // { session_id, editor_token, viewer_token }
  let meshDiagonal;
  const pageErrors = [];

  // A new page (own context) at `query`; page errors are collected and fail the suite.
  async function open(query) {
    const context = await browser.newContext({ viewport: { width: 800, height: 600 } });
    const page = await context.newPage();
    page.on('pageerror', (error) => pageErrors.push(`${query}: ${error.message}`));
    await page.goto(`${baseUrl}/${query}`);
    return page;
  }

  const viewerUrl = (token, extra = '') => `?session=${session.session_id}&token=${token}${extra}`;

  const waitFor = (page, fn, arg) => page.waitForFunction(fn, arg, { timeout: WAIT_MS });

  before(async () => {
    assert.ok(SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    assert.ok(existsSync(CLI), `the filigree CLI is not at ${CLI} (set FILIGREE_CLI)`);
    assert.ok(existsSync(CHROMIUM), `no browser at ${CHROMIUM}: apt-get install chromium, or set CHROMIUM`);
    assert.ok(existsSync(join(WEB_ROOT, 'index.html')), `no viewer build in ${WEB_ROOT}: run npm run build`);
    meshDiagonal = diagonal(readFileSync(MESH, 'latin1'));

    dataDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-test-'));
    server = startServer(dataDir);
    const addresses = await server.addresses;
    grpcAddress = addresses.grpc;
    baseUrl = `http://${addresses.http}`;
    session = fields(await cli(['upload', MESH, '--server', grpcAddress, '--name', 'browser-test']));
    assert.ok(session.session_id && session.editor_token && session.viewer_token, 'upload printed a session and tokens');

    browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    await browser?.close();
    if (server && server.child.exitCode === null && server.child.signalCode === null) {
      server.child.kill('SIGTERM');
      let timer;
      const stopped = await Promise.race([server.exited,
        new Promise((done) => { timer = setTimeout(() => done(null), STOP_TIMEOUT_MS); })]);
      clearTimeout(timer);
      if (stopped === null) server.child.kill('SIGKILL');
      assert.ok(stopped, `filigree-server did not exit within ${STOP_TIMEOUT_MS} ms of SIGTERM`);
      assert.equal(stopped.code, 0, `filigree-server exits 0 on SIGTERM: ${server.stderr()}`);
    }
    if (dataDir) rmSync(dataDir, { recursive: true, force: true });
    assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
  }, { timeout: HOOK_TIMEOUT_MS });

  it('shows how to use the page when no session is named', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open('');
    await waitFor(page, () => window.__filigree?.state === 'usage');
    assert.ok(await page.isVisible('#usage'));
    assert.match(await page.textContent('#usage'), /\?session=SESSION_ID&token=TOKEN/);
    await page.context().close();
  });

  it('explains a wrong token in the page', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open(viewerUrl('not-a-token'));
    await waitFor(page, () => window.__filigree?.state === 'error');
    assert.ok(await page.isVisible('#error'));
    assert.match(await page.textContent('#error'), /token was refused for session/);
    await page.context().close();
  });

  it('explains an unknown session in the page', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open(`?session=no-such-session&token=${session.viewer_token}`);
    await waitFor(page, () => window.__filigree?.state === 'error');
    assert.match(await page.textContent('#error'), /Session no-such-session does not exist/);
    await page.context().close();
  });

  it('renders the mesh, follows a driven session and returns to rest', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const page = await open(viewerUrl(session.viewer_token));
    await waitFor(page, () => window.__filigree?.framesApplied >= 1 && window.__filigree.framesRendered >= 1);
    const joined = await hookState(page);
    assert.equal(joined.state, 'live');
    assert.equal(joined.vertexCount, 1839);
    assert.equal(joined.error, null);

    // The canvas as the browser composited it is not blank.
    const shot = png(await page.locator('#view canvas').screenshot());
    const variance = luminanceVariance(shot);
    assert.ok(variance > 100, `the canvas shows a mesh (luminance variance ${variance.toFixed(1)})`);
    const rest = png(await page.evaluate(() => window.__filigree.capture()));

    // Armed before the drive starts: resolves, in the same task as the frame
    // that is applied, with the image of the first clearly bent frame.
    const bentThreshold = 0.15 * meshDiagonal;
    const bentCapture = page.evaluate((threshold) => new Promise((done) => {
      const look = () => {
        if (window.__filigree.displacement <= threshold) return;
        window.removeEventListener('filigree:frame', look);
        done({ image: window.__filigree.capture(), version: window.__filigree.version });
      };
      window.addEventListener('filigree:frame', look);
    }), bentThreshold);

    await cli(['drive', '--server', grpcAddress, '--session', session.session_id, '--token', session.editor_token,
      '--motion', 'bend', '--frames', '30', '--rate', '30', '--name', 'browser-test-bend']);

    let timer;
    const bent = await Promise.race([bentCapture, new Promise((_, fail) => {
      timer = setTimeout(() => fail(new Error(`no frame moved a vertex by more than ${bentThreshold}`)), WAIT_MS);
    })]).finally(() => clearTimeout(timer));
    assert.ok(bent.version > joined.version, `version ${bent.version} > ${joined.version}`);
    const moved = changedFraction(rest, png(bent.image));
    assert.ok(moved > 0.01, `the bent mesh looks different: ${(100 * moved).toFixed(2)}% of pixels changed`);

    // The bend ends where it started: once the last frame is in, the mesh is
    // back at rest (deltas replace the previous frame, they do not accumulate).
    await waitFor(page, ([before, eps]) => window.__filigree.framesReceived >= before + 5
      && window.__filigree.displacement <= eps, [joined.framesReceived, 1e-3 * meshDiagonal]);
    const done = await hookState(page);
    assert.ok(done.version > bent.version, `version grows: ${done.version} > ${bent.version}`);
    assert.ok(done.framesApplied > joined.framesApplied);
    const back = changedFraction(rest, png(await page.evaluate(() => window.__filigree.capture())));
    assert.ok(back < 0.002, `back at rest: ${(100 * back).toFixed(2)}% of pixels differ from the start`);

    t.diagnostic(`canvas luminance variance ${variance.toFixed(0)}; bent frame v${bent.version}: ` +
      `${(100 * moved).toFixed(1)}% of pixels changed; back at rest v${done.version}: ${(100 * back).toFixed(2)}%; ` +
      `frames received ${done.framesReceived - joined.framesReceived}, skipped ${done.framesSkipped}`);
    assert.match(await page.textContent('#changes'), /browser-test-bend: pose \d+, \d+ base vertices/);
    assert.match(await page.textContent('#stats'), /bytes\/frame\s*\d+ \(/);
    await page.context().close();
  });

  it('refuses a threshold change with the viewer token, readably', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open(viewerUrl(session.viewer_token));
    await waitFor(page, () => window.__filigree?.state === 'live');
    await page.fill('#threshold', '2');
    await page.click('#options button[type=submit]');
    await waitFor(page, () => /editor token/.test(document.querySelector('#options-status').textContent));
    await page.context().close();
  });

  it('changes the threshold and times an own pose with the editor token', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const page = await open(viewerUrl(session.editor_token));
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1);
    await page.fill('#threshold', '2');
    await page.click('#options button[type=submit]');
    await waitFor(page, () => /^T is now 2\b/.test(document.querySelector('#options-status').textContent));

    await page.click('#round-trip');
    await waitFor(page, () => window.__filigree.roundTripMs !== null);
    const { roundTripMs } = await hookState(page);
    assert.ok(roundTripMs > 0 && roundTripMs < WAIT_MS, `round trip ${roundTripMs} ms`);
    t.diagnostic(`SubmitPose → frame: ${roundTripMs.toFixed(1)} ms`);
    await waitFor(page, () => /web-viewer: pose 1, \d+ base vertices/.test(document.querySelector('#changes').textContent));
    await page.context().close();
  });
});
