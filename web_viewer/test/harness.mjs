// What the browser test (browser.test.mjs) and the screenshot script
// (screenshots.mjs) share: a real filigree-server serving the viewer build
// and gRPC-Web, the `filigree` CLI, and Debian's Chromium.
//
// Environment:
//   FILIGREE_SERVER  the filigree-server binary (default: build/server/filigree-server of this repository)
//   FILIGREE_CLI     the filigree CLI (default: ../client/filigree beside the server's directory)
//   CHROMIUM         the browser (default /usr/bin/chromium)

import assert from 'node:assert/strict';
import { execFile, spawn } from 'node:child_process';
import { closeSync, existsSync, openSync, readFileSync, writeFileSync, writeSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { createInterface } from 'node:readline';
import { fileURLToPath } from 'node:url';

const HERE = dirname(fileURLToPath(import.meta.url));
export const ROOT = resolve(HERE, '..', '..');
export const WEB_ROOT = resolve(HERE, '..', 'dist');
export const SERVER = resolve(process.env.FILIGREE_SERVER ?? join(ROOT, 'build', 'server', 'filigree-server'));
export const CLI = resolve(process.env.FILIGREE_CLI ?? join(dirname(SERVER), '..', 'client', 'filigree'));
export const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
// TOOLCHAIN.md, Browser.
export const CHROMIUM_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync', '--enable-unsafe-swiftshader'];

// What must exist before anything starts; throws with what is missing.
export function checkTools() {
  for (const [path, what] of [[SERVER, 'filigree-server (set FILIGREE_SERVER)'], [CLI, 'the filigree CLI (set FILIGREE_CLI)'],
    [CHROMIUM, 'a browser: apt-get install chromium, or set CHROMIUM'], [join(WEB_ROOT, 'index.html'), 'the viewer build: run npm run build']]) {
    if (!existsSync(path)) throw new Error(`${path} is missing: ${what}`);
  }
}

// Starts filigree-server with gRPC-Web and the viewer; `addresses` resolves
// with both once it has printed `listening on H:P` and `http on H:P`.
// `extraArgs`: more options (--tls-cert/--tls-key: HTTPS on the same port).
// `at`: { grpc, http } addresses to listen on (default: free ports).
export function startServer(dataDir, extraArgs = [], at = { grpc: '127.0.0.1:0', http: '127.0.0.1:0' }) {
  const child = spawn(SERVER, ['--listen', at.grpc, '--http', at.http, '--web-root', WEB_ROOT,
    '--data-dir', dataDir, '--log-level', 'warn', ...extraArgs], { stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const exited = new Promise((done) => {
    child.on('exit', (code, signal) => done({ code, signal }));
    child.on('error', (error) => done({ code: null, signal: null, error }));
  });
  // If this process dies without stopping it, the server goes with it.
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

// SIGTERM, then SIGKILL after `timeoutMs`; resolves with { code, signal }, or null if it had to be killed.
export async function stopServer(server, timeoutMs) {
  if (server.child.exitCode !== null || server.child.signalCode !== null) return server.exited;
  server.child.kill('SIGTERM');
  let timer;
  const stopped = await Promise.race([server.exited,
    new Promise((done) => { timer = setTimeout(() => done(null), timeoutMs); })]);
  clearTimeout(timer);
  if (stopped === null) server.child.kill('SIGKILL');
  return stopped;
}

// stopServer, failing the test unless the server exited 0 within `timeoutMs`.
export async function stopServerCleanly(server, timeoutMs) {
  const stopped = await stopServer(server, timeoutMs);
  assert.ok(stopped, `filigree-server did not exit within ${timeoutMs} ms of SIGTERM`);
  assert.equal(stopped.code, 0, `filigree-server exits 0 on SIGTERM: ${server.stderr()}`);
}

// Runs the CLI; resolves with its stdout, rejects with its stderr.
export function cli(args, timeoutMs = 60_000) {
  return new Promise((done, fail) => {
    execFile(CLI, args, { timeout: timeoutMs }, (error, stdout, stderr) => {
      if (error) fail(new Error(`filigree ${args[0]} failed: ${error.message}\n${stderr}`));
      else done(stdout);
    });
  });
}

// Resolves once `filigree health` says the server at `grpcAddress` serves;
// rejects after `timeoutMs`. Each check waits for its answer (up to 1 s):
// this waits on the condition, not a guessed time.
export async function waitForHealth(grpcAddress, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    try {
      await cli(['health', '--server', grpcAddress, '--timeout', '1'], 5000);
      return;
    } catch (error) {
      if (Date.now() > deadline) throw new Error(`${grpcAddress} not healthy within ${timeoutMs} ms: ${error.message}`);
      // A refused connection answers at once: a short pause keeps this from spinning.
      await new Promise((done) => setTimeout(done, 50));
    }
  }
}

// Writes an ellipsoid with semi-axes `axes` ([x, y, z]) as an OBJ, sampled
// densest around the horizontal direction `front` (a unit axis, ±x/±y/±z, not
// along `up`): most of its vertex normals face that way. `up` ('y' or 'z') is
// the polar axis.
export function writeEllipsoidObj(path, axes, up, front, rings = 24, segments = 48) {
  const [ax, ay, az] = axes;
  // An orthonormal frame: u (the polar axis), f (front), s = u × f.
  const u = up === 'z' ? [0, 0, 1] : [0, 1, 0];
  const f = front;
  const s = [u[1] * f[2] - u[2] * f[1], u[2] * f[0] - u[0] * f[2], u[0] * f[1] - u[1] * f[0]];
  const lines = [];
  const point = (theta, phi) => {
    // Unit sphere in the (f, s, u) frame, then scaled per world axis.
    const c = [Math.sin(theta) * Math.cos(phi), Math.sin(theta) * Math.sin(phi), Math.cos(theta)];
    const w = [0, 1, 2].map((k) => c[0] * f[k] + c[1] * s[k] + c[2] * u[k]);
    return [w[0] * ax, w[1] * ay, w[2] * az];
  };
  lines.push(`v ${point(0, 0).join(' ')}`);
  for (let r = 1; r < rings; ++r) {
    for (let k = 0; k < segments; ++k) {
      const t = 2 * (k / segments) - 1;                 // −1 … 1, 0 at the front
      const phi = Math.PI * t * (0.3 + 0.7 * t * t);     // 3× denser at the front than on average
      lines.push(`v ${point((Math.PI * r) / rings, phi).join(' ')}`);
    }
  }
  lines.push(`v ${point(Math.PI, 0).join(' ')}`);
  const top = 1;
  const bottom = 2 + (rings - 1) * segments;
  const at = (r, k) => 2 + (r - 1) * segments + (k % segments);
  // Outward winding (counter-clockwise seen from outside) in the right-handed (f, s, u) frame.
  const face = (a, b, c) => lines.push(`f ${a} ${b} ${c}`);
  for (let k = 0; k < segments; ++k) {
    face(top, at(1, k), at(1, k + 1));
    for (let r = 1; r < rings - 1; ++r) {
      face(at(r, k), at(r + 1, k), at(r + 1, k + 1));
      face(at(r, k), at(r + 1, k + 1), at(r, k + 1));
    }
    face(at(rings - 1, k), bottom, at(rings - 1, k + 1));
  }
  writeFileSync(path, `${lines.join('\n')}\n`);
}

// Uploads a mesh; resolves with { session_id, editor_token, viewer_token, … }.
// `extraArgs`: more CLI options (--tls-ca for a TLS server).
export async function upload(grpcAddress, mesh, name, extraArgs = []) {
  const session = fields(await cli(['upload', mesh, '--server', grpcAddress, '--name', name, ...extraArgs]));
  if (!session.session_id || !session.editor_token || !session.viewer_token) throw new Error('upload printed no session and tokens');
  return session;
}

// The editor token in a file only this user can read: tokens never go on a command line.
function tokenFile(session) {
  const file = join(tmpdir(), `filigree-token-${session.session_id}`);
  writeFileSync(file, `${session.editor_token}\n`, { mode: 0o600 });
  return file;
}

// The CLI's arguments to drive a procedural motion.
export const driveArgs = (grpcAddress, session, motion, frames, rate, name) => ['drive', '--server', grpcAddress,
  '--session', session.session_id, '--token-file', tokenFile(session), '--motion', motion, '--frames', String(frames),
  '--rate', String(rate), '--name', name];

// `key: value` lines.
export function fields(text) {
  return Object.fromEntries(text.split('\n').map((l) => /^(\w+):\s*(.*)$/.exec(l)).filter(Boolean).map((m) => [m[1], m[2]]));
}

// The bounding-box diagonal of an .obj or .off file.
export function diagonal(path) {
  const text = readFileSync(path, 'latin1');
  const rows = path.endsWith('.off')
    ? (() => {
      const lines = text.split('\n').map((l) => l.trim()).filter((l) => l && !l.startsWith('#'));
      const count = Number(lines[1].split(/\s+/)[0]);
      return lines.slice(2, 2 + count).map((l) => l.split(/\s+/).map(Number));
    })()
    : text.split('\n').map((l) => l.trim().split(/\s+/)).filter((f) => f[0] === 'v').map((f) => f.slice(1, 4).map(Number));
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const row of rows) {
    for (let k = 0; k < 3; ++k) { lo[k] = Math.min(lo[k], row[k]); hi[k] = Math.max(hi[k], row[k]); }
  }
  return Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

// window.__filigree without its functions (what page.evaluate can return).
export const hookState = (page) => page.evaluate(() =>
  Object.fromEntries(Object.entries(window.__filigree).filter(([, v]) => typeof v !== 'function')));

// Opens `url` in a new context of `browser`; the page's uncaught errors are
// added to `errors`.
export async function openPage(browser, url, errors, viewport = { width: 1100, height: 700 }) {
  const context = await browser.newContext({ viewport });
  const page = await context.newPage();
  page.on('pageerror', (error) => errors.push(`${url}: ${error.message}`));
  await page.goto(url);
  return page;
}

// page.waitForFunction; on a timeout the error says what the page showed
// (its hook state and the start of its text).
export const waitShowing = (page, fn, arg, timeout) => page.waitForFunction(fn, arg, { timeout }).catch(async (error) => {
  throw new Error(`${error.message}\nthe page: ${JSON.stringify(await hookState(page).catch(() => null))}\n` +
    `its text: ${(await page.textContent('body').catch(() => '')).replace(/\s+/g, ' ').slice(0, 1500)}`);
});

// A bumpy UV sphere as binary PLY (smaller and faster to parse than OBJ).
export function writeBumpySphere(path, rings, segments) {
  const n = (rings - 1) * segments + 2;
  const faces = 2 * segments * (rings - 1);
  const header = `ply\nformat binary_little_endian 1.0\nelement vertex ${n}\nproperty float x\nproperty float y\n` +
    `property float z\nelement face ${faces}\nproperty list uchar uint vertex_indices\nend_header\n`;
  const vertices = new Float32Array(3 * n);
  const put = (i, theta, phi) => {
    const r = 1 + 0.04 * Math.sin(7 * theta) * Math.cos(5 * phi) + 0.008 * Math.sin(41 * theta) * Math.cos(37 * phi);
    vertices[3 * i] = r * Math.sin(theta) * Math.cos(phi);
    vertices[3 * i + 1] = r * Math.cos(theta) * 1.6;  // taller than wide: a body standing along y
    vertices[3 * i + 2] = r * Math.sin(theta) * Math.sin(phi);
  };
  put(0, 0, 0);
  for (let r = 1; r < rings; ++r) for (let k = 0; k < segments; ++k) put(1 + (r - 1) * segments + k, (Math.PI * r) / rings, (2 * Math.PI * k) / segments);
  put(n - 1, Math.PI, 0);
  const at = (r, k) => 1 + (r - 1) * segments + (k % segments);
  const face = Buffer.alloc(13);
  const fd = openSync(path, 'w');
  writeSync(fd, header);
  writeSync(fd, Buffer.from(vertices.buffer));
  const chunk = [];
  const flush = () => { writeSync(fd, Buffer.concat(chunk)); chunk.length = 0; };
  const tri = (a, b, c) => {
    const f = Buffer.from(face);
    f[0] = 3;
    f.writeUInt32LE(a, 1); f.writeUInt32LE(b, 5); f.writeUInt32LE(c, 9);
    chunk.push(f);
    if (chunk.length >= 65536) flush();
  };
  for (let k = 0; k < segments; ++k) {
    tri(0, at(1, k + 1), at(1, k));
    for (let r = 1; r < rings - 1; ++r) {
      tri(at(r, k), at(r, k + 1), at(r + 1, k + 1));
      tri(at(r, k), at(r + 1, k + 1), at(r + 1, k));
    }
    tri(at(rings - 1, k), at(rings - 1, k + 1), n - 1);
  }
  flush();
  closeSync(fd);
  return n;
}
