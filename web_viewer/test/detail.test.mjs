// Levels of detail in Chromium against a real filigree-server: a bumpy
// sphere of 10,242 vertices (base ~205), pages that watch it at a level
// (detail=2048: a level of 2,048 vertices), at full detail, and on Auto.
//
//   - A page at detail=2048 draws the level: the panel says "Detail: 2,048 of
//     10,242 vertices", and after a drive its positions are a full page's at
//     the same original ids to within the two frames' max_error; picking and
//     a placed handle name original ids (the full page sees the handle on the
//     vertex whose position was pressed).
//   - Choosing Full in the panel mid-drive switches the live stream (SetDetail,
//     no new stream) to full detail, whose frames keep coming; the overlays
//     shown (base mesh, cut, stretch) follow to the full mesh.
//   - Auto with a starting budget (detail=auto:2048) is at full detail while
//     the session rests, at the level while it is driven, and at full detail
//     again once the frames stop, at least a second after the last one.
//
// Environment: FILIGREE_SERVER (required), FILIGREE_CLI, CHROMIUM (harness.mjs).
// Needs the build (dist/). No sleeps: every wait is on a condition, with a timeout.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFile, spawn } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { chromium } from 'playwright-core';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, driveArgs, hookState, openPage, startServer, stopServerCleanly, upload, waitShowing,
  writeBumpySphere,
} from './harness.mjs';

const HOOK_TIMEOUT_MS = 60_000;
const TEST_TIMEOUT_MS = 180_000;
const WAIT_MS = 60_000;
const STOP_TIMEOUT_MS = 20_000;
// 65 rings of 160 segments: 64·160 + 2 = 10,242 vertices; the default base is 2 % of them.
const RINGS = 65;
const SEGMENTS = 160;
const LEVEL = 2048;
// The page's Auto waits this long without a new frame before full detail (detail.ts, IDLE_MS is 1.5 s).
const IDLE_AT_LEAST_MS = 1000;

let browser;
let server;
let dataDir;
let baseUrl;
let grpc;
let mesh;
let vertices;
const pageErrors = [];

const newPage = (url) => openPage(browser, url, pageErrors, { width: 900, height: 650 });
const waitFor = (page, fn, arg, timeout = WAIT_MS) => waitShowing(page, fn, arg, timeout);
const url = (session, token, detail) => `${baseUrl}/?session=${session.session_id}&detail=${detail}#token=${token}`;

// Live with a frame drawn, or the page's first error at once.
async function live(page) {
  await waitFor(page, () => window.__filigree?.error || window.__filigree?.state === 'error'
    || (window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1 && window.__filigree.framesRendered >= 1));
  const state = await hookState(page);
  assert.ok(state.state === 'live' && state.error === null, `the page failed: ${state.error}`);
  return state;
}

// Drives the session with the CLI; resolves when the drive ends.
function drive(session, frames, rate, name) {
  return new Promise((done, fail) => {
    execFile(CLI, driveArgs(grpc, session, 'bend', frames, rate, name), { timeout: 4 * WAIT_MS },
      (error, _stdout, stderr) => (error ? fail(new Error(`filigree drive failed: ${error.message}\n${stderr}`)) : done()));
  });
}

// A drive in the background, stopped by stop().
function driveInBackground(session, frames, rate, name) {
  const child = spawn(CLI, driveArgs(grpc, session, 'bend', frames, rate, name), { stdio: 'ignore' });
  const ended = new Promise((done) => child.on('exit', done));
  return { ended, stop: async () => { child.kill('SIGTERM'); await ended; } };
}

// Both pages drawing the same version, the newest either has seen.
async function sameVersion(a, b) {
  const settled = () => window.__filigree.version === window.__filigree.newestVersion && window.__filigree.framesApplied >= 1;
  for (let attempt = 0; attempt < 50; ++attempt) {
    await waitFor(a, settled);
    await waitFor(b, settled);
    const [va, vb] = [(await hookState(a)).version, (await hookState(b)).version];
    if (va === vb) return va;
    const newer = Math.max(va, vb);
    await waitFor(va < vb ? a : b, (v) => window.__filigree.version >= v, newer);
  }
  throw new Error('the pages never drew the same version');
}

before(async () => {
  assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
  checkTools();
  dataDir = mkdtempSync(join(tmpdir(), 'filigree-detail-'));
  mesh = join(dataDir, 'bumpy-sphere.ply');
  vertices = writeBumpySphere(mesh, RINGS, SEGMENTS);
  assert.equal(vertices, 10242);
  server = startServer(join(dataDir, 'data'));
  const addresses = await server.addresses;
  grpc = addresses.grpc;
  baseUrl = `http://${addresses.http}`;
  browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
}, { timeout: HOOK_TIMEOUT_MS });

after(async () => {
  await browser?.close();
  if (server) await stopServerCleanly(server, STOP_TIMEOUT_MS);
  if (dataDir) rmSync(dataDir, { recursive: true, force: true });
  assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
}, { timeout: HOOK_TIMEOUT_MS });

describe('levels of detail', { timeout: 3 * TEST_TIMEOUT_MS }, () => {
  it('a page at detail=2048 draws the level, where a full page draws the same ids, and picks original ids', { timeout: TEST_TIMEOUT_MS }, async () => {
    const session = await upload(grpc, mesh, 'detail-level');
    const full = await newPage(url(session, session.viewer_token, 'full'));
    const level = await newPage(url(session, session.editor_token, String(LEVEL)));
    await live(full);
    await live(level);
    await waitFor(level, (k) => window.__filigree.levelVertices === k && window.__filigree.vertexCount === k, LEVEL);
    const shown = await hookState(level);
    assert.equal(shown.fullVertexCount, vertices);
    assert.equal(shown.detailMode, 'fixed');
    assert.equal(await level.textContent('#detail-level'), `Detail: 2,048 of ${vertices.toLocaleString('en-US')} vertices`);
    assert.ok(shown.triangleCount > LEVEL && shown.triangleCount < 2 * vertices, `the level's triangles: ${shown.triangleCount}`);
    const fullShown = await hookState(full);
    assert.equal(fullShown.levelVertices, vertices);
    assert.equal(fullShown.vertexCount, vertices);
    assert.equal(await full.textContent('#detail-level'), `Detail: 10,242 of 10,242 vertices`);

    // After a pose (a drive of one frame: the whole bend), both at its frame:
    // the level's vertices are where the full page has the same original ids,
    // to within both frames' max_error.
    await drive(session, 1, 20, 'detail-drive');
    const version = await sameVersion(level, full);
    const ids = await level.evaluate(() => window.__filigree.levelIds());
    assert.equal(ids.length, LEVEL);
    assert.ok(ids.every((id, i) => Number.isInteger(id) && id < vertices && (i === 0 || id > ids[i - 1])), 'ascending original ids');
    const positions = (page) => page.evaluate((list) => ({
      version: window.__filigree.version, maxError: window.__filigree.maxError, displacement: window.__filigree.displacement,
      at: list.map((id) => window.__filigree.vertexPosition(id)),
    }), ids);
    // Read on both pages at one version (a frame arriving in between: read again).
    let [a, b] = [await positions(level), await positions(full)];
    for (let attempt = 0; a.version !== b.version || a.version < version; ++attempt) {
      assert.ok(attempt < 20, `the pages stay at different versions: ${a.version}, ${b.version}`);
      await sameVersion(level, full);
      [a, b] = [await positions(level), await positions(full)];
    }
    const tolerance = a.maxError + b.maxError + 1e-6;
    let worst = 0;
    ids.forEach((id, i) => {
      assert.ok(a.at[i] && b.at[i], `vertex ${id} is drawn on both pages`);
      for (let k = 0; k < 3; ++k) worst = Math.max(worst, Math.abs(a.at[i][k] - b.at[i][k]));
    });
    assert.ok(worst <= tolerance, `level and full positions differ by ${worst} > ${tolerance}`);
    assert.ok(b.displacement > 100 * tolerance, `the drive moved the mesh (${b.displacement}): the comparison is not of rest positions`);

    // Picking names original ids: the vertex pressed is where the full page has that id.
    const vertex = await level.evaluate(() => window.__filigree.nearestVertexToCamera());
    assert.ok(ids.includes(vertex), `the nearest vertex ${vertex} is one of the level's ids`);
    const at = await level.evaluate((v) => window.__filigree.screenPointOfVertex(v), vertex);
    assert.equal(await level.evaluate(({ x, y }) => window.__filigree.vertexAt(x, y), at), vertex);
    const [pa, pb] = [await level.evaluate((v) => window.__filigree.vertexPosition(v), vertex),
      await full.evaluate((v) => window.__filigree.vertexPosition(v), vertex)];
    for (let k = 0; k < 3; ++k) assert.ok(Math.abs(pa[k] - pb[k]) <= tolerance, `vertex ${vertex}: ${pa} on the level, ${pb} in full`);

    // A handle placed on the level is on that original vertex for everyone.
    await level.selectOption('#edit-mode', 'handles');
    await level.mouse.click(at.x, at.y);
    await waitFor(level, () => window.__filigree.handleCount === 1 && window.__filigree.handlesAnswered >= 1
      && !window.__filigree.handlesSending);
    const name = shown.clientName;
    await waitFor(full, (n) => window.__filigree.otherHandles().some((s) => s.name === n), name);
    const spheres = (await full.evaluate(() => window.__filigree.otherHandles())).filter((s) => s.name === name);
    assert.deepEqual(spheres.map((s) => s.vertex), [vertex]);
    const after = await hookState(level);
    assert.equal(after.resyncs, 0);
    assert.equal(after.error, null);
    await level.context().close();
    await full.context().close();
  });

  it('choosing Full in the panel switches the live stream to full detail mid-drive', { timeout: TEST_TIMEOUT_MS }, async () => {
    const session = await upload(grpc, mesh, 'detail-full');
    const page = await newPage(url(session, session.viewer_token, String(LEVEL)));
    await live(page);
    await waitFor(page, (k) => window.__filigree.levelVertices === k, LEVEL);
    const driver = driveInBackground(session, 2000, 20, 'detail-full-drive');
    try {
      const v0 = (await hookState(page)).version;
      await waitFor(page, ([k, v]) => window.__filigree.levelVertices === k && window.__filigree.framesAtLevel >= 3
        && window.__filigree.version > v + 2, [LEVEL, v0]);
      const before = await hookState(page);
      const levelIds = await page.evaluate(() => window.__filigree.levelIds());
      assert.equal(levelIds.length, LEVEL);
      assert.equal(await page.textContent('#detail-level'), 'Detail: 2,048 of 10,242 vertices');
      // The overlays on, drawn over the level: they follow the switch.
      for (const id of ['base', 'cut', 'stretch']) await page.check(`#overlay-${id}`);
      await waitFor(page, () => window.__filigree.stretchMax > 0 && window.__filigree.overlaysVersion > 0);
      await page.selectOption('#detail', 'full');
      // Full detail, and the drive's frames applied at it after the switch.
      await waitFor(page, (n) => window.__filigree.levelVertices === n && window.__filigree.vertexCount === n
        && window.__filigree.framesAtLevel >= 3, vertices);
      const swapped = await hookState(page);
      await waitFor(page, (v) => window.__filigree.overlaysVersion > v && window.__filigree.stretchMax > 0, swapped.version);
      const switched = await hookState(page);
      assert.ok(switched.version > before.version, 'frames kept coming');
      assert.equal(switched.watchStreams, before.watchStreams, 'the same stream (SetDetail), not a new one');
      assert.ok(switched.setDetailAnswers >= 1, 'SetDetail answered');
      assert.equal(switched.detailMode, 'full');
      assert.equal(switched.detailBudget, vertices);
      assert.equal(switched.resyncs, 0);
      assert.equal(switched.reconnects, 0);
      assert.equal(switched.error, null);
      assert.equal(await page.textContent('#detail-level'), 'Detail: 10,242 of 10,242 vertices');
      // The frame sent again at the new level (its keyframe first) is no new change.
      const lines = await page.$$eval('#changes li', (items) => items.map((item) => item.textContent));
      assert.ok(lines.length > 3, `change lines: ${lines.length}`);
      assert.equal(new Set(lines).size, lines.length, `a change listed twice: ${lines.join(' | ')}`);
      // Every vertex drawn: one the level lacks has a position now.
      const ids = new Set(levelIds);
      const missing = Array.from({ length: vertices }, (_, i) => i).find((i) => !ids.has(i));
      assert.equal(await page.evaluate((i) => window.__filigree.vertexPosition(i)?.length ?? null, missing), 3);
    } finally {
      await driver.stop();
    }
    await page.context().close();
  });

  it('Auto refines to full detail when the session rests and goes coarse while it is driven', { timeout: TEST_TIMEOUT_MS }, async () => {
    const session = await upload(grpc, mesh, 'detail-auto');
    const page = await newPage(url(session, session.viewer_token, `auto:${LEVEL}`));
    await live(page);
    // Nothing drives it: full detail.
    await waitFor(page, (n) => window.__filigree.levelVertices === n, vertices);
    const rested = await hookState(page);
    assert.equal(rested.detailMode, 'auto');
    // Driven: the level, and frames applied at it.
    const driver = driveInBackground(session, 2000, 20, 'detail-auto-drive');
    let busy;
    try {
      await waitFor(page, (k) => window.__filigree.levelVertices === k && window.__filigree.framesAtLevel >= 5, LEVEL);
      busy = await hookState(page);
      assert.equal(busy.detailLog.at(-1).reason, 'busy');
    } finally {
      await driver.stop();
    }
    // The frames stop: full detail again, not before a second without a new frame.
    await waitFor(page, (n) => window.__filigree.levelVertices === n && window.__filigree.detailLog.at(-1).reason === 'idle',
      vertices);
    const idle = await hookState(page);
    const refined = idle.detailLog.at(-1);
    assert.ok(refined.at - idle.lastNewFrameAt >= IDLE_AT_LEAST_MS,
      `full detail ${refined.at - idle.lastNewFrameAt} ms after the last new frame`);
    assert.equal(idle.watchStreams, rested.watchStreams, 'every switch on the same stream (SetDetail)');
    assert.ok(idle.levelSwaps >= 2, `swaps: ${idle.levelSwaps}`);
    assert.equal(idle.resyncs, 0);
    assert.equal(idle.error, null);
    await page.context().close();
  });
});
