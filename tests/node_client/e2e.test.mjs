// A Filigree client written against proto/filigree/v1/filigree.proto, with
// another gRPC implementation (@grpc/grpc-js + @grpc/proto-loader) and Draco's
// official WASM decoder (draco3d): uploads a mesh, drives rigid poses, decodes
// the frames and checks them vertex by vertex, the access rules and the
// standard health service.
//
// Frames come in both formats. FRAME_FORMAT_SINGLE (the default: clients
// written before chunked frames) is decoded by decodeDeltas below, written
// from the proto alone. FRAME_FORMAT_CHUNKED is decoded by the web viewer's
// own code (web_viewer/src/frame.ts: chunk checks, KeyedDeltas), so that the
// viewer's reading of chunks, runs and keyframes is checked against the real
// server, and compared with the single format frame by frame.
//
// Environment:
//   FILIGREE_SERVER  path of the filigree-server binary
//   FILIGREE_ROOT    the repository root (for the proto and tests/data)
//
// The last suite starts its own server with --tls-cert/--tls-key (certificates
// made by the openssl CLI at run time) and checks grpc-js over TLS.
//
// Run with `node --test` (Node 18 or newer); run.sh installs the packages first.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync, spawn } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { createInterface } from 'node:readline';

import * as grpc from '@grpc/grpc-js';
import * as protoLoader from '@grpc/proto-loader';
import draco3d from 'draco3d';
import healthCheck from 'grpc-health-check';
import ts from 'typescript';

const SERVER = process.env.FILIGREE_SERVER;
const ROOT = process.env.FILIGREE_ROOT;
const MESH = ROOT && join(ROOT, 'tests', 'data', 'bunny_small.obj');
const CHUNK_BYTES = 16 * 1024;
const BASE_VERTICES = 150;
const REST_VERTICES = 1839;
const LIFT = 0.1;  // the pose moves every base vertex by (0, LIFT, 0)
const CHUNKED = 'FRAME_FORMAT_CHUNKED';

// One set of loader options for every proto: field names as in the .proto,
// 64-bit integers as decimal strings (sent as strings too), enums as names,
// unset fields present with their defaults, `kind` naming the oneof member set.
const LOADER_OPTIONS = { keepCase: true, longs: String, enums: String, defaults: true, oneofs: true };

const HOOK_TIMEOUT_MS = 30_000;
const TEST_TIMEOUT_MS = 60_000;
const STOP_TIMEOUT_MS = 20_000;

// ------------------------------------------------------------------ helpers

// Starts filigree-server on a free loopback port; resolves with the address
// once it prints "listening on HOST:PORT" on stdout, rejects if it exits first.
function startServer(binary, dataDir, extraArgs = []) {
  const child = spawn(binary, ['--listen', '127.0.0.1:0', '--data-dir', dataDir, '--log-level', 'warn', ...extraArgs], {
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const exited = new Promise((resolve) => {
    child.on('exit', (code, signal) => resolve({ code, signal }));
    child.on('error', (error) => resolve({ code: null, signal: null, error }));
  });
  // Should this process exit without finishing `after`, the server and its
  // data directory go with it.
  const killOnExit = () => {
    child.kill('SIGKILL');
    try { rmSync(dataDir, { recursive: true, force: true }); } catch { /* best effort */ }
  };
  // A signal (the test runner or a timeout stopping this process) skips the
  // 'exit' event unless handled.
  const onSignal = (signal) => {
    killOnExit();
    process.exit(128 + (signal === 'SIGINT' ? 2 : signal === 'SIGHUP' ? 1 : 15));
  };
  const signals = ['SIGTERM', 'SIGINT', 'SIGHUP'];
  process.on('exit', killOnExit);
  for (const s of signals) process.on(s, onSignal);
  exited.then(() => {
    process.off('exit', killOnExit);
    for (const s of signals) process.off(s, onSignal);
  });
  const address = new Promise((resolve, reject) => {
    const lines = createInterface({ input: child.stdout });
    lines.on('line', (line) => {
      const m = /^listening on (\S+:\d+)$/.exec(line);
      if (m) resolve(m[1]);
    });
    child.on('error', reject);
    exited.then(({ code, signal, error }) =>
      reject(new Error(`filigree-server exited (code ${code}, signal ${signal}${error ? `, ${error.message}` : ''}) ` +
                       `before listening: ${stderr}`)));
  });
  return { child, address, exited };
}

// SIGTERM, bounded: a server that does not stop is killed and the caller fails;
// it must exit 0 (drained), not by a signal.
async function stopServer(server) {
  if (!server || server.child.pid === undefined || server.child.exitCode !== null || server.child.signalCode !== null)
    return;
  server.child.kill('SIGTERM');
  let timer;
  const stopped = await Promise.race([
    server.exited,
    new Promise((resolve) => { timer = setTimeout(() => resolve(null), STOP_TIMEOUT_MS); }),
  ]);
  clearTimeout(timer);
  if (stopped === null) server.child.kill('SIGKILL');
  assert.ok(stopped, `filigree-server did not exit within ${STOP_TIMEOUT_MS} ms of SIGTERM`);
  assert.equal(stopped.signal, null, 'filigree-server was not killed by a signal');
  assert.equal(stopped.code, 0, 'filigree-server exits 0 on SIGTERM');
}

function metadata(entries) {
  const md = new grpc.Metadata();
  for (const [key, value] of Object.entries(entries)) md.set(key, value);
  return md;
}

// Resolves with the status of a finished call, rejects with the call's error.
function callStatus(call) {
  return new Promise((resolve, reject) => {
    call.on('error', reject);
    call.on('status', (status) => { if (status.code === grpc.status.OK) resolve(status); });
  });
}

// Reads a server stream to its end: resolves with every message once both the
// end of the stream and an OK status are seen; rejects on an error status.
function collect(call) {
  const messages = [];
  call.on('data', (m) => messages.push(m));
  const ended = new Promise((resolve) => call.on('end', resolve));
  return Promise.all([callStatus(call), ended]).then(() => messages);
}

// Resolves with the first message of a stream that satisfies `accept`;
// rejects if the stream ends or fails first.
function firstMessage(call, accept) {
  return new Promise((resolve, reject) => {
    call.on('data', (m) => { if (accept(m)) resolve(m); });
    call.on('error', reject);
    call.on('end', () => reject(new Error('the stream ended before the expected message')));
  });
}

// Rejects unless the call fails with `code`; resolves with the error.
// Cancels a server stream and checks it ends with CANCELLED.
async function cancelAndExpectCancelled(call) {
  const cancelled = expectCode(new Promise((resolve, reject) => {
    call.on('error', reject);
    call.on('end', resolve);
  }), grpc.status.CANCELLED);
  call.cancel();
  await cancelled;
}

function expectCode(promise, code) {
  return promise.then(
    () => assert.fail(`expected status ${code}, the call succeeded`),
    (err) => {
      assert.equal(err.code, code, `expected status ${code}, got ${err.code}: ${err.details}`);
      return err;
    });
}

function unary(client, method, request, md) {
  return new Promise((resolve, reject) => {
    client[method](request, md, (err, response) => (err ? reject(err) : resolve(response)));
  });
}

// Writes with back-pressure: waits for 'drain' when the stream asks to.
function write(call, message) {
  return new Promise((resolve) => { if (call.write(message)) resolve(); else call.once('drain', resolve); });
}

// The `v x y z` positions of an OBJ file, flat.
function objVertices(bytes) {
  const out = [];
  for (const line of bytes.toString('latin1').split('\n')) {
    const f = line.trim().split(/\s+/);
    if (f[0] === 'v') out.push(Number(f[1]), Number(f[2]), Number(f[3]));
  }
  return out;
}

// The length of the bounding-box diagonal of flat x y z positions.
function diagonal(positions) {
  let sum = 0;
  for (let k = 0; k < 3; ++k) {
    const axis = positions.filter((_, i) => i % 3 === k);
    sum += (Math.max(...axis) - Math.min(...axis)) ** 2;
  }
  return Math.sqrt(sum);
}

// Checks the quantization fields of a frame of a session with default
// options: the bits are picked per frame so that max_error ≤ 5e-5 of the
// rest mesh's diagonal, and max_error is within the quantization bound.
function checkQuantization(frame, restPositions) {
  assert.ok(frame.quantization_bits >= 8 && frame.quantization_bits <= 24, `bits ${frame.quantization_bits}`);
  const bound = frame.delta_range / (2 ** frame.quantization_bits - 1) / 2;
  assert.ok(frame.max_error <= bound * (1 + 1e-6) + 1e-12,
    `max_error ${frame.max_error} ≤ delta_range / (2^bits − 1) / 2 = ${bound}`);
  const allowed = 5e-5 * diagonal(restPositions);
  assert.ok(frame.max_error <= allowed * (1 + 1e-6), `max_error ${frame.max_error} ≤ 5e-5 of the diagonal = ${allowed}`);
}

// Opens a Drive stream (default format: single frames), sends one full pose
// (pose_id 1), returns the first frame that includes it, then half-closes and
// waits for the OK status.
async function driveFullPose(client, md, sessionId, positions, openCalls) {
  const call = client.Drive(md);
  openCalls.push(call);
  const frame = firstMessage(call, (f) => f.pose_id === '1');
  const status = callStatus(call);
  await write(call, { pose_id: '1', session_id: sessionId, indices: [], positions, client_name: 'node-e2e' });
  const result = await frame;
  call.end();
  await status;
  return result;
}

// Decodes Frame.deltas (a Draco point cloud, one float32×3 attribute) into a
// Float32Array of 3·vertex_count values; an empty buffer means all zeros.
function decodeDeltas(M, frame) {
  const n = frame.vertex_count;
  if (frame.deltas.length === 0) return new Float32Array(3 * n);
  const bytes = new Int8Array(frame.deltas.buffer, frame.deltas.byteOffset, frame.deltas.byteLength);
  // Draco header: "DRACO", major, minor, encoder type (0 point cloud), method
  // (0 sequential: decoded point i is encoded point i, so vertex i).
  assert.equal(Buffer.from(frame.deltas.subarray(0, 5)).toString('latin1'), 'DRACO');
  assert.equal(frame.deltas[7], 0, 'geometry type is a point cloud');
  assert.equal(frame.deltas[8], 0, 'point cloud encoding is sequential');
  const decoder = new M.Decoder();
  const cloud = new M.PointCloud();
  const values = new M.DracoFloat32Array();
  try {
    const status = decoder.DecodeArrayToPointCloud
      ? decoder.DecodeArrayToPointCloud(bytes, bytes.byteLength, cloud)
      : (() => {  // older draco3d API
          const buffer = new M.DecoderBuffer();
          buffer.Init(bytes, bytes.byteLength);
          try { return decoder.DecodeBufferToPointCloud(buffer, cloud); } finally { M.destroy(buffer); }
        })();
    assert.ok(status.ok(), `Draco decoding failed: ${status.error_msg()}`);
    assert.equal(cloud.num_points(), n, 'one point per original vertex');
    assert.equal(cloud.num_attributes(), 1, 'one attribute');
    const attribute = decoder.GetAttribute(cloud, 0);
    assert.equal(attribute.num_components(), 3, 'the attribute is float×3');
    assert.ok(decoder.GetAttributeFloatForAllPoints(cloud, attribute, values), 'reading the attribute');
    assert.equal(values.size(), 3 * n);
    const out = new Float32Array(3 * n);
    for (let i = 0; i < out.length; ++i) out[i] = values.GetValue(i);
    return out;
  } finally {
    M.destroy(values);
    M.destroy(cloud);
    M.destroy(decoder);
  }
}

// ------------------------------------------------------------------ chunked frames

// The web viewer's web_viewer/src/frame.ts as a module. It imports nothing at
// run time, so its TypeScript transpiled alone is the whole module.
async function loadFrameModule(root) {
  const path = join(root, 'web_viewer', 'src', 'frame.ts');
  const { outputText } = ts.transpileModule(readFileSync(path, 'utf8'), {
    fileName: path,
    compilerOptions: { module: ts.ModuleKind.ESNext, target: ts.ScriptTarget.ES2022 },
  });
  return import(`data:text/javascript;base64,${Buffer.from(outputText).toString('base64')}`);
}

// A grpc-js Frame (field names as in the .proto, 64-bit integers as strings)
// as frame.ts reads it (ChunkedFrameData).
function chunkedFrame(frame) {
  return {
    version: BigInt(frame.version),
    keyframeVersion: BigInt(frame.keyframe_version),
    vertexCount: frame.vertex_count,
    chunks: frame.chunks.map((c) => ({
      firstVertex: c.first_vertex, vertexCount: c.vertex_count, runs: c.runs, deltas: c.deltas,
    })),
  };
}

const isKeyframe = (frame) => frame.version === frame.keyframe_version;
const describeFrame = (frame) => (isKeyframe(frame) ? `v${frame.version} keyframe`
  : `v${frame.version} sparse on v${frame.keyframe_version} (${frame.stats?.present_vertices} present)`);

// Checks what a chunked frame says about itself: chunks with sane bits, the
// error within 5e-5 of the rest mesh's diagonal (default options), and the
// present vertices the server reports are the ones the chunks carry.
function checkChunkedFrame(F, frame, restPositions) {
  assert.ok(F.isChunked(chunkedFrame(frame)), `frame ${frame.version} is chunked`);
  assert.equal(frame.deltas.length, 0, 'a chunked frame has no single buffer');
  for (const chunk of frame.chunks) {
    if (chunk.deltas.length === 0) continue;
    assert.ok(chunk.quantization_bits >= 8 && chunk.quantization_bits <= 24, `chunk bits ${chunk.quantization_bits}`);
  }
  const allowed = 5e-5 * diagonal(restPositions);
  assert.ok(frame.max_error <= allowed * (1 + 1e-6), `max_error ${frame.max_error} ≤ 5e-5 of the diagonal = ${allowed}`);
  if (frame.stats) {
    const present = F.presentCounts(chunkedFrame(frame).chunks, frame.vertex_count).reduce((a, b) => a + b, 0);
    assert.equal(frame.stats.present_vertices, present, `frame ${frame.version}: stats.present_vertices`);
  }
}

// Follows a stream of frames: applies each one in arrival order (nothing is
// missed between two waits) and lets a test wait for the next frame, after
// those already waited for, that satisfies a predicate (next), or for the
// first such frame of the stream (first). An error of `apply` fails the wait.
function followFrames(call, apply) {
  const frames = [];
  let seen = 0;
  let failure = null;
  let waiter = null;
  const settle = () => {
    if (!waiter) return;
    const at = frames.findIndex((f, i) => i >= waiter.from && waiter.accept(f));
    const w = waiter;
    if (at >= 0) {
      waiter = null;
      if (w.advance) seen = at + 1;
      w.resolve(frames[at]);
    } else if (failure) {
      waiter = null;
      w.reject(failure);
    }
  };
  const wait = (accept, from, advance) =>
    new Promise((resolve, reject) => { waiter = { accept, from, advance, resolve, reject }; settle(); });
  call.on('data', (frame) => {
    if (failure) return;
    try {
      apply(frame);
      frames.push(frame);
    } catch (error) {
      failure = new Error(`frame ${frame.version} (${describeFrame(frame)}) could not be applied: ${error.message}`);
    }
    settle();
  });
  call.on('error', (error) => { failure ??= error; settle(); });
  call.on('end', () => { failure ??= new Error('the stream ended before the expected frame'); settle(); });
  return {
    frames,
    next: (accept) => wait(accept, seen, true),
    first: (accept) => wait(accept, 0, false),
  };
}

// The largest |a − b| over two arrays of deltas, and where.
function worstDifference(a, b) {
  let worst = 0;
  let at = -1;
  for (let i = 0; i < a.length; ++i) {
    const d = Math.abs(a[i] - b[i]);
    if (d > worst) [worst, at] = [d, Math.floor(i / 3)];
  }
  return { worst, vertex: at };
}

// ------------------------------------------------------------------ tests

describe('filigree-server from a grpc-js client', { timeout: 5 * TEST_TIMEOUT_MS }, () => {
  let server;       // { child, address, exited }
  let dataDir;
  let client;       // filigree.v1.Filigree
  let health;       // grpc.health.v1.Health
  let draco;        // the draco3d decoder module
  let F;            // web_viewer/src/frame.ts
  const openCalls = [];  // streams to cancel in `after` if a test left them open
  // Set by the tests in order; a later test fails at once if an earlier one did.
  let created;      // CreateSessionResponse.Created
  let drivenFrame;  // the Drive frame with pose_id 1

  const sessionMd = (token) => metadata({ 'x-session-id': created.info.session_id, 'x-filigree-token': token });
  const needSession = () => assert.ok(created, 'needs the session made by the CreateSession test');

  // Checks a chunked frame and applies it to `keyed` with the viewer's code;
  // returns the deltas after it (a copy: the next frame changes them in place).
  const applyChunked = (keyed, frame) => {
    checkChunkedFrame(F, frame, created.info.rest.positions);
    F.decodeAndApply(draco, keyed, chunkedFrame(frame));
    return keyed.deltas.slice();
  };

  // The deltas of a chunked GetState: its keyframe first when its frame is
  // relative to one, into a KeyedDeltas that held nothing.
  const chunkedStateDeltas = (state) => {
    const frames = F.framesOfState(state);
    assert.ok(isKeyframe(frames[0]), `GetState starts with a keyframe (${frames.map(describeFrame).join(', ')})`);
    if (!isKeyframe(state.frame)) {
      assert.equal(state.keyframe?.version, state.frame.keyframe_version, 'the keyframe of the frame');
    }
    const keyed = new F.KeyedDeltas(REST_VERTICES);
    let deltas;
    for (const frame of frames) deltas = applyChunked(keyed, frame);
    return deltas;
  };

  // A Drive stream in the chunked format; every frame is applied in order.
  // pose(request) sends one and resolves with { frame, deltas } of the frame
  // that includes it; reached(version) with those of the first frame of at
  // least that version.
  const openChunkedDrive = (md) => {
    const call = client.Drive(md);
    openCalls.push(call);
    const keyed = new F.KeyedDeltas(REST_VERTICES);
    const deltasOf = new Map();
    const stream = followFrames(call, (frame) => deltasOf.set(frame, applyChunked(keyed, frame)));
    const status = callStatus(call);
    status.catch(() => {});  // awaited by close(); a failed test must not leave it unhandled
    let first = true;
    return {
      stream,
      async pose(request) {
        const next = stream.next((f) => f.pose_id === request.pose_id);
        // The first request names the session and the format of the stream.
        await write(call, first
          ? { session_id: created.info.session_id, client_name: 'node-e2e', frame_format: CHUNKED, ...request }
          : request);
        first = false;
        const frame = await next;
        return { frame, deltas: deltasOf.get(frame) };
      },
      async reached(version) {
        const frame = await stream.first((f) => BigInt(f.version) >= BigInt(version));
        return { frame, deltas: deltasOf.get(frame) };
      },
      async close() {
        call.end();
        await status;
      },
    };
  };

  // Compares the current frame as a chunked Drive stream decoded it with the
  // same version in the single format (GetState, default format, decoded by
  // the proto-only decoder). The server may compute a frame after the one
  // that included a pose: the versions are matched, not assumed.
  const compareWithSingle = async (drive) => {
    for (;;) {
      const state = await unary(client, 'GetState', { session_id: created.info.session_id },
        sessionMd(created.viewer_token));
      assert.equal(state.frame.chunks.length, 0, 'GetState without frame_format answers a single frame');
      const { frame, deltas } = await drive.reached(state.version);
      if (frame.version !== state.version) continue;  // a newer frame came meanwhile: ask again
      const single = decodeDeltas(draco, state.frame);
      const { worst, vertex } = worstDifference(deltas, single);
      const tolerance = frame.max_error + state.frame.max_error + 1e-6;
      assert.ok(worst <= tolerance, `frame ${describeFrame(frame)}: vertex ${vertex} differs from the single format ` +
        `by ${worst} > ${tolerance}`);
      return frame;
    }
  };

  before(async () => {
    assert.ok(SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    assert.ok(ROOT, 'set FILIGREE_ROOT to the repository root');
    dataDir = mkdtempSync(join(tmpdir(), 'filigree-node-e2e-'));
    server = startServer(SERVER, dataDir);
    const address = await server.address;

    const filigree = grpc.loadPackageDefinition(protoLoader.loadSync('filigree/v1/filigree.proto', {
      ...LOADER_OPTIONS, includeDirs: [join(ROOT, 'proto')],
    }));
    const healthPkg = grpc.loadPackageDefinition(protoLoader.loadSync(healthCheck.protoPath, LOADER_OPTIONS));
    // A fixed frame window, as the C++ client's (filigree/channel_arguments.h).
    client = new filigree.filigree.v1.Filigree(address, grpc.credentials.createInsecure(), { 'grpc-node.flow_control_window': 4 << 20 });
    health = new healthPkg.grpc.health.v1.Health(address, grpc.credentials.createInsecure());
    draco = await draco3d.createDecoderModule({});
    F = await loadFrameModule(ROOT);
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    for (const call of openCalls) call.cancel();
    client?.close();
    health?.close();
    try {
      await stopServer(server);
    } finally {
      if (dataDir) rmSync(dataDir, { recursive: true, force: true });
    }
  }, { timeout: HOOK_TIMEOUT_MS });

  it('answers the standard health check with SERVING', { timeout: TEST_TIMEOUT_MS }, async () => {
    const response = await unary(health, 'Check', { service: '' }, new grpc.Metadata());
    assert.equal(response.status, 'SERVING');
  });

  it('creates a session from an OBJ uploaded in 16 KiB chunks', { timeout: TEST_TIMEOUT_MS }, async () => {
    const bytes = readFileSync(MESH);
    const call = client.CreateSession(new grpc.Metadata());
    openCalls.push(call);
    const responses = collect(call);
    await write(call, {
      begin: {
        format: 'obj',
        total_bytes: String(bytes.length),
        options: { base_vertices: BASE_VERTICES },
        client_name: 'node-e2e',
      },
    });
    for (let offset = 0; offset < bytes.length; offset += CHUNK_BYTES) {
      await write(call, { chunk: bytes.subarray(offset, offset + CHUNK_BYTES) });
    }
    call.end();
    const messages = await responses;

    const progress = messages.filter((m) => m.kind === 'progress');
    const createdMessages = messages.filter((m) => m.kind === 'created');
    assert.ok(progress.length > 0, 'Progress messages before Created');
    for (const p of progress) {
      assert.ok(p.progress.stage.length > 0, 'a progress stage is named');
      assert.ok(p.progress.fraction >= 0 && p.progress.fraction <= 1, `fraction ${p.progress.fraction} in [0, 1]`);
    }
    assert.equal(createdMessages.length, 1, 'exactly one Created');
    assert.equal(messages.at(-1).kind, 'created', 'Created is the last message');

    const c = createdMessages[0].created;
    assert.ok(c.editor_token.length > 0, 'an editor token');
    assert.ok(c.viewer_token.length > 0, 'a viewer token');
    assert.notEqual(c.editor_token, c.viewer_token);
    assert.ok(c.info.session_id.length > 0, 'a session id');
    assert.match(c.info.mesh_hash, /^[0-9a-f]{16}$/);
    assert.equal(c.info.version, '0');
    assert.equal(c.info.base.positions.length, 3 * BASE_VERTICES);
    assert.equal(c.info.base.original_ids.length, BASE_VERTICES);
    assert.ok(c.info.base.faces.length > 0 && c.info.base.faces.length % 3 === 0);
    assert.equal(c.info.rest.vertex_count, REST_VERTICES);
    assert.equal(c.info.rest.positions.length, 3 * REST_VERTICES);
    // Session vertex i is uploaded vertex uploaded_ids[i] (nothing to repair
    // in this mesh, so a permutation), at that vertex's position.
    const uploaded = objVertices(bytes);
    assert.equal(uploaded.length, 3 * REST_VERTICES);
    assert.equal(c.info.rest.uploaded_ids.length, REST_VERTICES);
    assert.equal(new Set(c.info.rest.uploaded_ids).size, REST_VERTICES, 'uploaded_ids is a permutation');
    c.info.rest.uploaded_ids.forEach((id, i) => {
      assert.ok(id < REST_VERTICES);
      for (let k = 0; k < 3; ++k) {
        assert.equal(c.info.rest.positions[3 * i + k], Math.fround(uploaded[3 * id + k]),
          `session vertex ${i} is at uploaded vertex ${id}`);
      }
    });
    // Base vertex i is original vertex original_ids[i], at the same rest position.
    c.info.base.original_ids.forEach((id, i) => {
      assert.ok(id < REST_VERTICES);
      for (let k = 0; k < 3; ++k) assert.equal(c.info.base.positions[3 * i + k], c.info.rest.positions[3 * id + k]);
    });
    created = c;
  });

  it('joins the session with the viewer token', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    const info = await unary(client, 'JoinSession', { session_id: created.info.session_id },
      sessionMd(created.viewer_token));
    assert.equal(info.session_id, created.info.session_id);
    assert.equal(info.mesh_hash, created.info.mesh_hash);
    assert.equal(info.rest.vertex_count, REST_VERTICES);
    assert.deepEqual(info.base.positions, created.info.base.positions);
  });

  // The default format, as clients written before chunked frames read it.
  it('drives a translated base and decodes a rigidly translated mesh (single frames)', { timeout: TEST_TIMEOUT_MS },
    async () => {
      needSession();
      const positions = created.info.base.positions.map((v, i) => (i % 3 === 1 ? v + LIFT : v));
      drivenFrame = await driveFullPose(client, sessionMd(created.editor_token), created.info.session_id, positions,
        openCalls);

      assert.equal(drivenFrame.vertex_count, REST_VERTICES);
      assert.ok(BigInt(drivenFrame.version) >= 1n, `version ${drivenFrame.version} ≥ 1`);
      assert.ok(drivenFrame.deltas.length > 0, 'a moved mesh has deltas');
      assert.equal(drivenFrame.chunks.length, 0, 'a stream that did not ask for chunks gets none');
      assert.equal(drivenFrame.keyframe_version, '0');
      checkQuantization(drivenFrame, created.info.rest.positions);
      const change = drivenFrame.changes.find((ch) => ch.client_name === 'node-e2e');
      assert.ok(change, 'the frame names this client among the changes');
      assert.equal(change.pose_id, '1');
      assert.equal(change.vertex_count, BASE_VERTICES, 'a full pose moves every base vertex');

      const deltas = decodeDeltas(draco, drivenFrame);
      const tolerance = drivenFrame.max_error + 1e-5;
      const expected = [0, LIFT, 0];
      let worst = 0;
      for (let i = 0; i < deltas.length; ++i) worst = Math.max(worst, Math.abs(deltas[i] - expected[i % 3]));
      assert.ok(worst <= tolerance,
        `every delta is (0, ${LIFT}, 0): worst coordinate error ${worst} > ${tolerance}`);
    });

  it('sends a late watcher with the viewer token the current frame at once', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    assert.ok(drivenFrame, 'needs the frame of the Drive test');
    const call = client.Watch({ session_id: created.info.session_id, after_version: '0' },
      sessionMd(created.viewer_token));
    openCalls.push(call);
    const frame = await firstMessage(call, () => true);
    assert.equal(frame.version, drivenFrame.version, 'the current frame is the driven one');
    assert.equal(frame.vertex_count, REST_VERTICES);
    assert.deepEqual(Buffer.from(frame.deltas), Buffer.from(drivenFrame.deltas));
    await cancelAndExpectCancelled(call);
  });

  it('sends a late chunked watcher the current frame, its keyframe first', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    needSession();
    assert.ok(drivenFrame, 'needs the frame of the Drive test');
    const call = client.Watch({ session_id: created.info.session_id, after_version: '0', frame_format: CHUNKED },
      sessionMd(created.viewer_token));
    openCalls.push(call);
    const keyed = new F.KeyedDeltas(REST_VERTICES);
    const deltasOf = new Map();
    const stream = followFrames(call, (frame) => deltasOf.set(frame, applyChunked(keyed, frame)));
    // Decoding it at all means the keyframe came first: a sparse frame without it is a FrameError.
    const frame = await stream.next((f) => f.version === drivenFrame.version);
    assert.ok(isKeyframe(stream.frames[0]), 'a new stream starts with a keyframe');
    assert.equal(frame.vertex_count, REST_VERTICES);
    const single = decodeDeltas(draco, drivenFrame);
    const { worst, vertex } = worstDifference(deltasOf.get(frame), single);
    const tolerance = frame.max_error + drivenFrame.max_error + 1e-6;
    assert.ok(worst <= tolerance, `vertex ${vertex} differs from the single frame by ${worst} > ${tolerance}`);
    t.diagnostic(`chunked watch: ${stream.frames.map(describeFrame).join(', ')}; ${frame.chunks.length} chunks`);

    await cancelAndExpectCancelled(call);
  });

  it('reports the driven pose in GetState', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    assert.ok(drivenFrame, 'needs the frame of the Drive test');
    const state = await unary(client, 'GetState', { session_id: created.info.session_id },
      sessionMd(created.viewer_token));
    assert.equal(state.version, drivenFrame.version);
    assert.equal(state.pose.length, 3 * BASE_VERTICES);
    state.pose.forEach((v, i) => {
      const rest = created.info.base.positions[i];
      assert.ok(Math.abs(v - (i % 3 === 1 ? rest + LIFT : rest)) <= 1e-5, `pose[${i}] = ${v}`);
    });
    // The default format: one buffer, no keyframe.
    assert.equal(state.frame.version, drivenFrame.version);
    assert.equal(state.frame.chunks.length, 0);
    assert.equal(state.keyframe, null);
    assert.deepEqual(Buffer.from(state.frame.deltas), Buffer.from(drivenFrame.deltas));
  });

  it('answers a chunked GetState with the current frame, its keyframe when it is sparse', { timeout: TEST_TIMEOUT_MS },
    async () => {
      needSession();
      assert.ok(drivenFrame, 'needs the frame of the Drive test');
      const state = await unary(client, 'GetState', { session_id: created.info.session_id, frame_format: CHUNKED },
        sessionMd(created.viewer_token));
      assert.equal(state.version, drivenFrame.version);
      assert.equal(state.frame.version, drivenFrame.version);
      assert.equal(state.pose.length, 3 * BASE_VERTICES);
      const deltas = chunkedStateDeltas(state);
      const tolerance = state.frame.max_error + 1e-5;
      const expected = [0, LIFT, 0];
      let worst = 0;
      for (let i = 0; i < deltas.length; ++i) worst = Math.max(worst, Math.abs(deltas[i] - expected[i % 3]));
      assert.ok(worst <= tolerance, `every delta is (0, ${LIFT}, 0): worst coordinate error ${worst} > ${tolerance}`);
    });

  // A rigid motion of the whole base moves the whole mesh rigidly too; unlike
  // the translation, a rotation moves every vertex differently, so this also
  // checks that a decoded vertex is the right original vertex, chunk by chunk.
  it('drives a rotated base and decodes a rigidly rotated mesh from chunked frames, vertex by vertex',
    { timeout: TEST_TIMEOUT_MS }, async (t) => {
      needSession();
      const base = created.info.base.positions;
      const rest = created.info.rest.positions;
      const m = base.length / 3;
      const centre = [0, 1, 2].map((k) => base.filter((_, i) => i % 3 === k).reduce((a, b) => a + b, 0) / m);
      const angle = Math.PI / 6;  // 30° about the y axis through the base's centroid
      const [c, s] = [Math.cos(angle), Math.sin(angle)];
      const rotate = (p, i) => {
        const [x, y, z] = [p[3 * i] - centre[0], p[3 * i + 1], p[3 * i + 2] - centre[2]];
        return [centre[0] + c * x + s * z, y, centre[2] - s * x + c * z];
      };
      const positions = [];
      for (let i = 0; i < m; ++i) positions.push(...rotate(base, i));

      const drive = openChunkedDrive(sessionMd(created.editor_token));
      const { frame, deltas } = await drive.pose({ pose_id: '1', indices: [], positions });
      await drive.close();
      assert.equal(frame.vertex_count, REST_VERTICES);
      assert.ok(isKeyframe(drive.stream.frames[0]), 'a new stream starts with a keyframe');
      const tolerance = frame.max_error + 1e-5;
      let worst = 0;
      let worstVertex = -1;
      for (let i = 0; i < REST_VERTICES; ++i) {
        const expected = rotate(rest, i);
        for (let k = 0; k < 3; ++k) {
          const error = Math.abs(rest[3 * i + k] + deltas[3 * i + k] - expected[k]);
          if (error > worst) [worst, worstVertex] = [error, i];
        }
      }
      assert.ok(worst <= tolerance,
        `rest + delta is the rotated rest position: vertex ${worstVertex} is off by ${worst} > ${tolerance}`);
      t.diagnostic(`chunked drive: ${drive.stream.frames.map(describeFrame).join(', ')}`);
    });

  // Moves of part of the mesh: the server may send sparse frames (only the
  // vertices that moved since the keyframe), one after the other; each must
  // decode to the mesh the single format gives for the same version.
  it('drives local moves in chunked frames: each decodes to what the single format gives, a requested keyframe too',
    { timeout: TEST_TIMEOUT_MS }, async (t) => {
      needSession();
      const base = created.info.base.positions;
      const m = base.length / 3;
      const byHeight = [...Array(m).keys()].sort((a, b) => base[3 * a + 1] - base[3 * b + 1]);
      const tenth = Math.ceil(m / 10);
      const shifted = (vertices, dx) => {
        const set = new Set(vertices);
        return base.map((v, i) => (i % 3 === 0 && set.has(Math.floor(i / 3)) ? v + dx : v));
      };
      const dx = 0.05 * diagonal(created.info.rest.positions);
      // Rest; the top tenth of the base moved; then the bottom tenth instead
      // (the vertices the top's move changed go back to the keyframe's).
      const poses = [base, shifted(byHeight.slice(-tenth), dx), shifted(byHeight.slice(0, tenth), -dx)];

      const drive = openChunkedDrive(sessionMd(created.editor_token));
      for (let k = 0; k < poses.length; ++k) {
        await drive.pose({ pose_id: String(k + 1), indices: [], positions: poses[k] });
        await compareWithSingle(drive);
      }
      // GetState in the chunked format decodes to the same mesh, from nothing.
      const state = await unary(client, 'GetState', { session_id: created.info.session_id, frame_format: CHUNKED },
        sessionMd(created.viewer_token));
      const fromState = chunkedStateDeltas(state);
      const same = await drive.reached(state.frame.version);
      assert.equal(same.frame.version, state.frame.version, 'the Drive stream got the frame GetState answers');
      const { worst, vertex } = worstDifference(fromState, same.deltas);
      assert.ok(worst <= 2 * same.frame.max_error + 1e-6, `GetState's vertex ${vertex} differs by ${worst}`);

      // request_keyframe: the frame that includes the request is a keyframe.
      const forced = await drive.pose({ pose_id: String(poses.length + 1), indices: [], positions: poses.at(-1),
        request_keyframe: true });
      assert.ok(isKeyframe(forced.frame), `a keyframe was asked for: ${describeFrame(forced.frame)}`);
      await compareWithSingle(drive);
      await drive.close();
      t.diagnostic(`chunked drive: ${drive.stream.frames.map(describeFrame).join(', ')}`);
    });

  it('refuses a Drive with the viewer token (PERMISSION_DENIED)', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    const call = client.Drive(sessionMd(created.viewer_token));
    openCalls.push(call);
    const failed = expectCode(new Promise((resolve, reject) => {
      call.on('data', () => reject(new Error('a viewer got a Drive frame')));
      call.on('error', reject);
      call.on('end', resolve);
    }), grpc.status.PERMISSION_DENIED);
    call.write({ pose_id: '1', session_id: created.info.session_id, positions: created.info.base.positions });
    call.end();
    await failed;
  });

  it('refuses a JoinSession without a token (UNAUTHENTICATED)', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    await expectCode(unary(client, 'JoinSession', { session_id: created.info.session_id },
      metadata({ 'x-session-id': created.info.session_id })), grpc.status.UNAUTHENTICATED);
  });

  it('refuses a wrong token as it refuses an unknown session (NOT_FOUND)', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    await expectCode(unary(client, 'JoinSession', { session_id: created.info.session_id },
      sessionMd('not-a-token')), grpc.status.NOT_FOUND);
  });

  it('answers NOT_FOUND for an unknown session', { timeout: TEST_TIMEOUT_MS }, async () => {
    needSession();
    await expectCode(unary(client, 'JoinSession', { session_id: 'no-such-session' },
      metadata({ 'x-session-id': 'no-such-session', 'x-filigree-token': created.viewer_token })),
    grpc.status.NOT_FOUND);
  });
});

// ------------------------------------------------------------------ TLS

// A throwaway CA in `dir` (valid for a day) and, with `signer`, a server
// certificate for 127.0.0.1 and localhost signed by it; EC keys (fast).
function makeCert(dir, name, signer) {
  const openssl = (...args) => execFileSync('openssl', args, { cwd: dir, stdio: ['ignore', 'ignore', 'pipe'] });
  const newKey = ['-newkey', 'ec', '-pkeyopt', 'ec_paramgen_curve:prime256v1', '-nodes', '-subj', `/CN=${name}`,
    '-keyout', `${name}.key`];
  if (!signer) {
    openssl('req', '-x509', ...newKey, '-days', '1', '-out', `${name}.pem`);
    return;
  }
  openssl('req', ...newKey, '-out', `${name}.csr`);
  writeFileSync(join(dir, `${name}.ext`), 'subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n');
  openssl('x509', '-req', '-in', `${name}.csr`, '-CA', `${signer}.pem`, '-CAkey', `${signer}.key`, '-set_serial', '1',
    '-days', '1', '-out', `${name}.pem`, '-extfile', `${name}.ext`);
}

describe('filigree-server with --tls-cert from a grpc-js client', { timeout: 5 * TEST_TIMEOUT_MS }, () => {
  let server;
  let dataDir;
  let certDir;
  let address;
  let filigree;     // the loaded filigree package
  let healthPkg;
  const clients = [];

  // A client of the TLS server with `credentials`; closed in `after`. The
  // name checked in the certificate (and sent as SNI) is localhost: an IP
  // address is no valid SNI (RFC 6066).
  const connect = (Service, credentials) => {
    const c = new Service(address, credentials, { 'grpc.ssl_target_name_override': 'localhost' });
    clients.push(c);
    return c;
  };
  const trusting = () => grpc.credentials.createSsl(readFileSync(join(certDir, 'test-ca.pem')));
  // Fail fast: a refused connection is UNAVAILABLE at once, not after the default wait.
  const deadline = () => ({ deadline: Date.now() + 10_000 });

  before(async () => {
    assert.ok(SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    assert.ok(ROOT, 'set FILIGREE_ROOT to the repository root');
    certDir = mkdtempSync(join(tmpdir(), 'filigree-node-tls-'));
    makeCert(certDir, 'test-ca');
    makeCert(certDir, 'other-ca');
    makeCert(certDir, 'server', 'test-ca');
    dataDir = mkdtempSync(join(tmpdir(), 'filigree-node-tls-data-'));
    server = startServer(SERVER, dataDir,
      ['--tls-cert', join(certDir, 'server.pem'), '--tls-key', join(certDir, 'server.key')]);
    address = await server.address;
    filigree = grpc.loadPackageDefinition(protoLoader.loadSync('filigree/v1/filigree.proto', {
      ...LOADER_OPTIONS, includeDirs: [join(ROOT, 'proto')],
    })).filigree.v1;
    healthPkg = grpc.loadPackageDefinition(protoLoader.loadSync(healthCheck.protoPath, LOADER_OPTIONS)).grpc.health.v1;
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    for (const c of clients) c.close();
    try {
      await stopServer(server);
    } finally {
      for (const dir of [dataDir, certDir]) if (dir) rmSync(dir, { recursive: true, force: true });
    }
  }, { timeout: HOOK_TIMEOUT_MS });

  it('talks gRPC over TLS with credentials.createSsl(ca): health, an upload, a join', { timeout: TEST_TIMEOUT_MS },
    async () => {
      const health = connect(healthPkg.Health, trusting());
      assert.equal((await unary(health, 'Check', { service: '' }, new grpc.Metadata())).status, 'SERVING');

      const client = connect(filigree.Filigree, trusting());
      const bytes = readFileSync(MESH);
      const call = client.CreateSession(new grpc.Metadata());
      const responses = collect(call);
      await write(call, { begin: { format: 'obj', total_bytes: String(bytes.length),
        options: { base_vertices: BASE_VERTICES }, client_name: 'node-tls' } });
      for (let offset = 0; offset < bytes.length; offset += CHUNK_BYTES) {
        await write(call, { chunk: bytes.subarray(offset, offset + CHUNK_BYTES) });
      }
      call.end();
      const created = (await responses).find((m) => m.kind === 'created')?.created;
      assert.ok(created, 'a Created message over TLS');
      assert.equal(created.info.rest.vertex_count, REST_VERTICES);

      const id = created.info.session_id;
      const info = await unary(client, 'JoinSession', { session_id: id },
        metadata({ 'x-session-id': id, 'x-filigree-token': created.viewer_token }));
      assert.equal(info.session_id, id);
      const list = await unary(client, 'ListSessions', {}, new grpc.Metadata());
      assert.deepEqual(list.sessions.map((s) => s.session_id), [id]);
    });

  it('fails a plaintext client, and one that does not trust the CA, cleanly with UNAVAILABLE', { timeout: TEST_TIMEOUT_MS },
    async () => {
      const plaintext = connect(healthPkg.Health, grpc.credentials.createInsecure());
      const err = await expectCode(new Promise((resolve, reject) => {
        plaintext.Check({ service: '' }, new grpc.Metadata(), deadline(), (e, r) => (e ? reject(e) : resolve(r)));
      }), grpc.status.UNAVAILABLE);
      assert.ok(err.details.length > 0, 'the error says something');

      const otherCa = grpc.credentials.createSsl(readFileSync(join(certDir, 'other-ca.pem')));
      const untrusting = connect(healthPkg.Health, otherCa);
      await expectCode(new Promise((resolve, reject) => {
        untrusting.Check({ service: '' }, new grpc.Metadata(), deadline(), (e, r) => (e ? reject(e) : resolve(r)));
      }), grpc.status.UNAVAILABLE);

      // The server is unharmed: a trusting client on a new connection is served.
      const health = connect(healthPkg.Health, trusting());
      assert.equal((await unary(health, 'Check', { service: '' }, new grpc.Metadata())).status, 'SERVING');
      assert.equal(server.child.exitCode, null, 'the server still runs');
    });
});
