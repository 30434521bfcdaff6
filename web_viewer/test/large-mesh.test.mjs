// A mesh too large for one message, in Chromium against a real
// filigree-server started with --max-message-mib 1: a bumpy sphere of 40,962
// vertices has a rest mesh of ~1.2 MB on the wire, over half the limit, so
// JoinSession answers with its counts only (RestMesh.inParts) and the page
// reads the arrays from GetRestMesh in parts. The page joining it (made with
// the CLI) must draw every vertex and triangle and go live, following a
// drive; the front door's upload of the same file (1.6 MB: more than one
// message, so in chunks) must land in it live too.
//
// Environment: FILIGREE_SERVER (required), FILIGREE_CLI, CHROMIUM (harness.mjs).
// Needs the build (dist/). No sleeps: every wait is on a condition, with a timeout.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import { mkdtempSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { chromium } from 'playwright-core';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, driveArgs, hookState, openPage, startServer, stopServerCleanly, upload, waitShowing,
  writeBumpySphere,
} from './harness.mjs';

const HOOK_TIMEOUT_MS = 60_000;
const TEST_TIMEOUT_MS = 180_000;
const WAIT_MS = 120_000;  // a 41k-vertex upload preprocesses on a busy machine
const STOP_TIMEOUT_MS = 20_000;
// 129 rings of 320 segments: 128·320 + 2 = 40,962 vertices and 81,920 faces (as many as an icosphere subdivided 6 times).
const RINGS = 129;
const SEGMENTS = 320;

let browser;
let server;
let dataDir;
let baseUrl;
let grpc;
let mesh;
let vertices;
const faces = 2 * SEGMENTS * (RINGS - 1);
const pageErrors = [];

const newPage = (url) => openPage(browser, url, pageErrors, { width: 900, height: 650 });

const waitFor = (page, fn, arg, timeout = WAIT_MS) => waitShowing(page, fn, arg, timeout);

// Live, a frame applied and drawn; or the page's first error (a stop, a
// refused upload, a frame it could not show), at once.
async function live(page) {
  await waitFor(page, () => window.__filigree?.error || window.__filigree?.state === 'error'
    || window.__filigree?.frontState === 'error' || (window.__filigree?.state === 'live'
    && window.__filigree.framesApplied >= 1 && window.__filigree.framesRendered >= 1 && window.__filigree.canEdit !== null));
  const state = await hookState(page);
  assert.ok(state.state === 'live' && state.error === null,
    `the page failed: ${state.error} ${await page.textContent('#create-status').catch(() => '')}`);
  return state;
}

// What every page of this mesh must show: all of it, received in parts.
function assertWholeInParts(state) {
  assert.equal(state.vertexCount, vertices, 'every vertex drawn');
  assert.equal(state.triangleCount, faces, 'every triangle drawn');
  assert.ok(state.restParts >= 3, `the mesh came from GetRestMesh in parts (${state.restParts})`);
  const receive = state.loadStages.indexOf('receive');
  assert.ok(receive >= 0 && receive < state.loadStages.indexOf('build'), `stages: ${state.loadStages}`);
  assert.equal(state.receiveFraction, 1, 'the progress reached the whole mesh');
  assert.equal(state.error, null);
}

before(async () => {
  assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
  checkTools();
  dataDir = mkdtempSync(join(tmpdir(), 'filigree-large-mesh-'));
  mesh = join(dataDir, 'bumpy-sphere.ply');
  vertices = writeBumpySphere(mesh, RINGS, SEGMENTS);
  assert.equal(vertices, 40962);
  assert.ok(statSync(mesh).size > 1 << 20, 'the file is larger than one message');
  server = startServer(join(dataDir, 'data'), ['--max-message-mib', '1']);
  const addresses = await server.addresses;
  grpc = addresses.grpc;
  baseUrl = `http://${addresses.http}`;
  browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
}, { timeout: HOOK_TIMEOUT_MS });

after(async () => {
  await browser?.close();
  if (server) {
    await stopServerCleanly(server, STOP_TIMEOUT_MS);
  }
  if (dataDir) rmSync(dataDir, { recursive: true, force: true });
  assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
}, { timeout: HOOK_TIMEOUT_MS });

describe('a mesh too large for one message (--max-message-mib 1)', { timeout: 3 * TEST_TIMEOUT_MS }, () => {
  it('a page joining it receives the mesh in parts, draws all of it and follows a drive', { timeout: TEST_TIMEOUT_MS }, async () => {
    const session = await upload(grpc, mesh, 'large-mesh', []);
    const page = await newPage(`${baseUrl}/?session=${session.session_id}#token=${session.viewer_token}`);
    const state = await live(page);
    assertWholeInParts(state);
    assert.equal(state.canEdit, false, 'opened with the viewer token');
    const extent = await page.evaluate(() => window.__filigree.screenExtent());
    assert.ok(extent && Math.max(extent.width, extent.height) > 0.5, `the mesh fills the view: ${JSON.stringify(extent)}`);

    // Frames of the whole mesh apply on it: a drive is followed.
    const from = state.version;
    await new Promise((done, fail) => {
      execFile(CLI, driveArgs(grpc, session, 'bend', 10, 20, 'large-mesh-test'), { timeout: WAIT_MS },
        (error, _stdout, stderr) => (error ? fail(new Error(`filigree drive failed: ${error.message}\n${stderr}`)) : done()));
    });
    await waitFor(page, (v) => window.__filigree.version > v && window.__filigree.framesDrawn >= 1, from);
    const after = await hookState(page);
    assert.equal(after.state, 'live');
    assert.equal(after.resyncs, 0, 'no frame failed to apply');
    await page.context().close();
  });

  it('the front door uploads it in chunks and lands in it live as its editor', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await newPage(`${baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed');
    await page.setInputFiles('#mesh-file', mesh);
    const state = await live(page);
    assert.equal(state.createStages[0], 'sending', `stages: ${state.createStages}`);
    assert.equal(state.canEdit, true, 'the creator is the editor');
    assertWholeInParts(state);
    await page.context().close();
  });
});
