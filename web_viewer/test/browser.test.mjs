// The viewer in a real browser against a real filigree-server: Debian's
// Chromium (headless, SwiftShader WebGL) driven by playwright-core, the page
// served by the server itself (--web-root dist) and talking gRPC-Web to it;
// the session is made and driven with the `filigree` CLI (harness.mjs).
//
// Environment: FILIGREE_SERVER (required here), FILIGREE_CLI, CHROMIUM; see harness.mjs.
// Needs `npm run build` first (dist/); run-tests.sh does both.
//
// No sleeps: every wait is on a condition in the page or on a process, with a timeout.
//
// The last suite loads the viewer over HTTPS (--tls-cert/--tls-key, a CA made
// by openssl at run time), the server's key pinned in Chromium.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync, spawn } from 'node:child_process';
import { createHash, X509Certificate } from 'node:crypto';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, cli, diagonal, driveArgs, hookState, ROOT, startServer, stopServer, stopServerCleanly, upload,
  waitForHealth, writeEllipsoidObj,
} from './harness.mjs';

const MESH = join(ROOT, 'tests', 'data', 'bunny_small.obj');

const HOOK_TIMEOUT_MS = 60_000;
const TEST_TIMEOUT_MS = 90_000;
const WAIT_MS = 30_000;          // for a condition in the page
const STOP_TIMEOUT_MS = 20_000;

// ------------------------------------------------------------------ helpers

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

// The fraction of pixels with a clearly coloured (not grey) value: the
// region colours; the plain mesh and the background are grey.
function colouredFraction(image, spread = 60) {
  let coloured = 0;
  for (let i = 0; i < image.data.length; i += 4) {
    const [r, g, b] = image.data.subarray(i, i + 3);
    if (Math.max(r, g, b) - Math.min(r, g, b) > spread) ++coloured;
  }
  return coloured / (image.width * image.height);
}

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

  // Tokens in the fragment, where they belong (never sent to a server).
  const viewerUrl = (token, extra = '') => `?session=${session.session_id}${extra}#token=${token}`;

  const waitFor = (page, fn, arg) => page.waitForFunction(fn, arg, { timeout: WAIT_MS });

  before(async () => {
    assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    checkTools();
    meshDiagonal = diagonal(MESH);

    dataDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-test-'));
    server = startServer(dataDir);
    const addresses = await server.addresses;
    grpcAddress = addresses.grpc;
    baseUrl = `http://${addresses.http}`;
    session = await upload(grpcAddress, MESH, 'browser-test');

    browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    await browser?.close();
    if (server && server.child.exitCode === null && server.child.signalCode === null) {
      await stopServerCleanly(server, STOP_TIMEOUT_MS);
    }
    if (dataDir) rmSync(dataDir, { recursive: true, force: true });
    assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
  }, { timeout: HOOK_TIMEOUT_MS });

  it('shows how to use the page when no session is named', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open('');
    await waitFor(page, () => window.__filigree?.state === 'usage');
    assert.ok(await page.isVisible('#usage'));
    assert.match(await page.textContent('#usage'), /\?session=SESSION_ID#token=TOKEN/);
    await page.context().close();
  });

  it('explains a wrong token in the page', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open(viewerUrl('not-a-token'));
    await waitFor(page, () => window.__filigree?.state === 'error');
    assert.ok(await page.isVisible('#error'));
    // The server answers a wrong token as it answers an unknown session (DESIGN §3.2).
    assert.match(await page.textContent('#error'), /token was refused for session|does not exist .*or the token is not one of its tokens/);
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
    // The mesh's pixels only: not the dots where the driver worked in the last 10 s (history.test.mjs tests those).
    await page.uncheck('#show-activity');
    const joined = await hookState(page);
    assert.equal(joined.state, 'live');
    assert.equal(joined.vertexCount, 1839);
    assert.equal(joined.error, null);
    assert.match(await page.textContent('#session-info'), /vertices1839triangles3674base vertices[1-9]/);

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

    await cli(driveArgs(grpcAddress, session, 'bend', 30, 30, 'browser-test-bend'));

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
    // The page asks for chunked frames, and applies them without losing a keyframe.
    assert.notEqual(done.frameKind, 'single', 'the server sends the page chunked frames');
    assert.equal(done.resyncs, 0, 'no keyframe was lost');
    const back = changedFraction(rest, png(await page.evaluate(() => window.__filigree.capture())));
    assert.ok(back < 0.002, `back at rest: ${(100 * back).toFixed(2)}% of pixels differ from the start`);

    t.diagnostic(`canvas luminance variance ${variance.toFixed(0)}; bent frame v${bent.version}: ` +
      `${(100 * moved).toFixed(1)}% of pixels changed; back at rest v${done.version}: ${(100 * back).toFixed(2)}%; ` +
      `frames received ${done.framesReceived - joined.framesReceived}, skipped ${done.framesSkipped}; last one ${done.frameKind}`);
    assert.match(await page.textContent('#changes'), /browser-test-bend: pose \d+, \d+ base vertices/);
    assert.match(await page.textContent('#stats'), /bytes\/frame\s*\d+ \(/);
    assert.match(await page.textContent('#stats'), /frames\/s\s*\d+\.\d arrived, \d+\.\d applied, \d+\.\d drawn/);
    assert.equal(done.drawnVersion, done.version, 'the last frame applied is drawn');
    await page.context().close();
  });

  it('moves a token from the query into the fragment', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await open(`?session=${session.session_id}&token=${session.viewer_token}`);
    await waitFor(page, () => window.__filigree?.state === 'live');
    const url = new URL(page.url());
    assert.equal(url.searchParams.get('token'), null);
    assert.equal(new URLSearchParams(url.hash.slice(1)).get('token'), session.viewer_token);
    await page.context().close();
  });

  it('lists a skinned session\'s clips and plays one: the mesh moves, the clip ends', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    // A skinned GLB made from the shipped bunny by `filigree rig` (bend and twist clips).
    const rigged = join(dataDir, 'bunny_rigged.glb');
    await cli(['rig', MESH, '-o', rigged, '--joints', '4']);
    const skinned = await upload(grpcAddress, rigged, 'browser-test-rig');
    const page = await open(`?session=${skinned.session_id}#token=${skinned.editor_token}`);
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1);
    assert.deepEqual((await hookState(page)).clips, ['bend', 'twist']);
    assert.equal(await page.isVisible('#clips-section'), true);
    const rest = png(await page.evaluate(() => window.__filigree.capture()));
    await page.selectOption('#clip', 'bend');
    await page.click('#clip-play');
    // The bend peaks a quarter into the clip: the page shows a displaced frame.
    await waitFor(page, (d) => window.__filigree.displacement > 0.02 * d, meshDiagonal);
    const bent = png(await page.evaluate(() => window.__filigree.capture()));
    const moved = changedFraction(rest, bent);
    assert.ok(moved > 0.005, `the bent mesh looks like the rest mesh (${moved} of the pixels changed)`);
    await waitFor(page, () => window.__filigree.clipState === 'done');
    const { clipFrames } = await hookState(page);
    assert.ok(clipFrames >= 2, `clip stream frames: ${clipFrames}`);
    assert.match(await page.textContent('#clip-status'), /^Played bend \(\d+ frames\)\.$/);
    t.diagnostic(`clip 'bend': ${clipFrames} frames, ${(100 * moved).toFixed(1)}% of the pixels moved at the peak`);
    // A viewer token may not play: no clip controls at all.
    const viewer = await open(`?session=${skinned.session_id}#token=${skinned.viewer_token}`);
    await waitFor(viewer, () => window.__filigree?.state === 'live' && window.__filigree.canEdit === false);
    assert.equal(await viewer.isVisible('#clip-play'), false);
    await viewer.context().close();
    await page.context().close();
  });

  it('shows no editor controls with the viewer token, and all of them with the editor token', { timeout: TEST_TIMEOUT_MS }, async () => {
    const controls = ['#threshold', '#options button[type=submit]', '#round-trip', '#edit-mode', '#clear-handles'];
    const viewer = await open(viewerUrl(session.viewer_token));
    const editor = await open(viewerUrl(session.editor_token));
    await waitFor(viewer, () => window.__filigree?.state === 'live' && window.__filigree.canEdit === false);
    await waitFor(editor, () => window.__filigree?.state === 'live' && window.__filigree.canEdit === true);
    for (const control of controls) {
      assert.equal(await viewer.isVisible(control), false, `${control} is hidden from a viewer`);
      assert.equal(await editor.isVisible(control), true, `${control} is shown to an editor`);
    }
    assert.equal(await viewer.isVisible('#read-only-note'), true);
    assert.equal(await editor.isVisible('#read-only-note'), false);
    // The overlays stay: watching is what a viewer does.
    assert.equal(await viewer.isVisible('#overlay-regions'), true);
    await viewer.context().close();
    await editor.context().close();
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
    const { clientName } = await hookState(page);
    assert.match(clientName, /^web-[0-9a-f]{6}$/);
    await waitFor(page, (name) => new RegExp(`${name}: pose 1, \\d+ base vertices`).test(document.querySelector('#changes').textContent),
      clientName);
    await page.context().close();
  });

  it('drags a handle with the editor token; a second page sees the change, and cannot edit', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const live = () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1;
    const editor = await open(viewerUrl(session.editor_token));
    const watcher = await open(viewerUrl(session.viewer_token));
    await waitFor(editor, live);
    await waitFor(watcher, () => window.__filigree?.state === 'live' && window.__filigree.canEdit === false);
    await editor.selectOption('#edit-mode', 'handles');
    const start = await hookState(editor);

    // A real press, drag and release on the vertex nearest to the camera.
    const at = await editor.evaluate(() => window.__filigree.screenPointOfVertex(window.__filigree.nearestVertexToCamera()));
    assert.notEqual(await editor.evaluate(({ x, y }) => window.__filigree.vertexAt(x, y), at), null, 'the point is on the mesh');
    await editor.mouse.move(at.x, at.y);
    await editor.mouse.down();
    await waitFor(editor, () => window.__filigree.handleCount === 1);
    await editor.mouse.move(at.x + 70, at.y - 40, { steps: 8 });
    await editor.mouse.up();

    // Every SetHandles call answered, the frame that includes the last one
    // shown, and the mesh moved by a good part of the drag.
    const moved = 0.02 * meshDiagonal;
    await waitFor(editor, ([v0, eps]) => window.__filigree.handlesAnswered >= 1 && !window.__filigree.handlesSending
      && window.__filigree.version > Math.max(v0, window.__filigree.handlesAcceptedAt)
      && window.__filigree.displacement > eps, [start.version, moved]);
    const dragged = await hookState(editor);
    assert.equal(dragged.handleCount, 1);
    assert.equal(dragged.handlesInSession, 1);

    // The watcher (viewer token, own browser context) gets the same frames.
    await waitFor(watcher, (v) => window.__filigree.version >= v, dragged.version);
    const seen = await hookState(watcher);
    assert.ok(seen.displacement > moved, `the watcher's mesh moved: ${seen.displacement}`);
    if (seen.version === dragged.version) assert.equal(seen.displacement, dragged.displacement);
    await waitFor(watcher, (name) => document.querySelector('#changes').textContent.includes(`${name}: moved handles`),
      dragged.clientName);

    // Pressing on the mesh with a viewer token edits nothing: it orbits.
    const watcherAt = await watcher.evaluate(() => window.__filigree.screenPointOfVertex(window.__filigree.nearestVertexToCamera()));
    const lookBefore = (await watcher.evaluate(() => window.__filigree.viewDirection())).look;
    await watcher.mouse.move(watcherAt.x, watcherAt.y);
    await watcher.mouse.down();
    await watcher.mouse.move(watcherAt.x + 60, watcherAt.y, { steps: 4 });
    await watcher.mouse.up();
    await waitFor(watcher, (before) => {
      const look = window.__filigree.viewDirection().look;
      return look[0] * before[0] + look[1] * before[1] + look[2] * before[2] < 0.999;
    }, lookBefore);
    const watched = await hookState(watcher);
    assert.equal(watched.handleCount, 0);
    assert.equal(watched.handlesAnswered, 0);

    // Clearing sends an empty set: no handles left in the session.
    await editor.click('#clear-handles');
    await waitFor(editor, () => window.__filigree.handleCount === 0 && window.__filigree.handlesInSession === 0);
    t.diagnostic(`drag: v${start.version} → v${dragged.version}, displacement ${dragged.displacement.toFixed(4)} ` +
      `(diagonal ${meshDiagonal.toFixed(3)}), ${dragged.handlesAnswered} SetHandles answered, ` +
      `${dragged.framesSparse} sparse frames applied; watcher at v${seen.version}`);
    await editor.context().close();
    await watcher.context().close();
  });

  it('shows another participant\'s handle in its colour with its name, on editor and viewer pages, until it is dropped', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    // Two editors (own contexts, so own names) and a viewer, all live and
    // past their first GetHandles before A places anything: what they show
    // later comes from the frames' changes, not from the join.
    const a = await open(viewerUrl(session.editor_token));
    const b = await open(viewerUrl(session.editor_token));
    const viewer = await open(viewerUrl(session.viewer_token));
    const settled = () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1
      && window.__filigree.participantsAnswers >= 1 && !window.__filigree.participantsFetching;
    for (const page of [a, b, viewer]) await waitFor(page, settled);
    const nameA = (await hookState(a)).clientName;
    const nameB = (await hookState(b)).clientName;
    assert.notEqual(nameA, nameB);
    const colourA = await b.evaluate((n) => window.__filigree.participantColour(n), nameA);
    assert.match(colourA, /^#[0-9a-f]{6}$/);
    assert.equal(await a.evaluate((n) => window.__filigree.participantColour(n), nameA), colourA, 'the same colour on every page');
    assert.notEqual(colourA, '#39d0ff', 'not the colour of a page\'s own handles');
    for (const page of [b, viewer]) {
      assert.ok(!(await hookState(page)).participants.some((p) => p.name === nameA), 'A holds no handle yet');
    }

    // A places a handle: a click (press and release) on the vertex nearest to the camera.
    await a.selectOption('#edit-mode', 'handles');
    const vertex = await a.evaluate(() => window.__filigree.nearestVertexToCamera());
    const at = await a.evaluate((i) => window.__filigree.screenPointOfVertex(i), vertex);
    await a.mouse.click(at.x, at.y);
    await waitFor(a, () => window.__filigree.handleCount === 1 && window.__filigree.handlesAnswered >= 1
      && !window.__filigree.handlesSending);
    const placedAt = (await hookState(a)).handlesAcceptedAt;

    // What B and the viewer show: A's sphere in A's colour, a name tag beside
    // it, and a legend line; never their own handles as someone else's.
    const rgbToHex = (css) => `#${css.match(/\d+/g).slice(0, 3).map((c) => Number(c).toString(16).padStart(2, '0')).join('')}`;
    for (const page of [b, viewer]) {
      await waitFor(page, (n) => window.__filigree.participants.some((p) => p.name === n && p.handles === 1), nameA);
      const spheres = (await page.evaluate(() => window.__filigree.otherHandles())).filter((s) => s.name === nameA);
      assert.equal(spheres.length, 1, `one sphere of A's: ${JSON.stringify(spheres)}`);
      assert.equal(spheres[0].vertex, vertex);
      assert.equal(spheres[0].colour, colourA, 'drawn in A\'s colour');
      assert.ok(spheres[0].visible && spheres[0].x !== null, 'in view');
      // The label: A's name, A's colour, next to the sphere (placed at the next animation frame).
      const labelSelector = `.participant-label[data-participant="${nameA}"]`;
      await waitFor(page, (s) => {
        const label = document.querySelector(s);
        return label !== null && !label.hidden && label.style.transform !== '';
      }, labelSelector);
      const label = await page.evaluate((s) => {
        const element = document.querySelector(s);
        const r = element.getBoundingClientRect();
        return {
          text: element.textContent, background: getComputedStyle(element).backgroundColor,
          left: r.left, right: r.right, top: r.top, bottom: r.bottom,
        };
      }, labelSelector);
      assert.equal(label.text, nameA);
      assert.equal(rgbToHex(label.background), colourA);
      const { x, y } = spheres[0];
      const gap = Math.hypot(Math.max(label.left - x, 0, x - label.right), Math.max(label.top - y, 0, y - label.bottom));
      assert.ok(gap > 0 && gap < 25, `the label is beside the sphere, not over it (${gap.toFixed(1)} px from it)`);
      assert.ok(await page.isVisible(labelSelector), 'the label is seen');
      // The legend: swatch in A's colour, A's name, one handle.
      const legend = await page.evaluate((n) => {
        const item = document.querySelector(`#participants li[data-participant="${n}"]`);
        return item && { text: item.textContent, swatch: getComputedStyle(item.querySelector('.swatch')).backgroundColor };
      }, nameA);
      assert.ok(legend, 'a legend line for A');
      assert.match(legend.text, new RegExp(`${nameA}\\s*1 handle$`));
      assert.equal(rgbToHex(legend.swatch), colourA);
    }
    // A's own handle keeps its own look (handles.ts): A does not draw it as someone else's.
    assert.deepEqual((await a.evaluate(() => window.__filigree.otherHandles())).filter((s) => s.name === nameA), []);
    assert.equal(await a.locator(`.participant-label[data-participant="${nameA}"]`).count(), 0);

    // A drops it (right-click on the handle): it goes from B and the viewer too.
    await a.mouse.click(at.x, at.y, { button: 'right' });
    await waitFor(a, () => window.__filigree.handleCount === 0 && window.__filigree.handlesInSession === 0
      && !window.__filigree.handlesSending);
    for (const page of [b, viewer]) {
      await waitFor(page, (n) => !window.__filigree.participants.some((p) => p.name === n)
        && !window.__filigree.otherHandles().some((s) => s.name === n)
        && document.querySelector(`.participant-label[data-participant="${n}"]`) === null
        && document.querySelector(`#participants li[data-participant="${n}"]`) === null, nameA);
    }
    assert.match(await b.textContent('#participants'), /No other participant holds handles\./);
    const seen = await hookState(b);
    t.diagnostic(`A ${nameA} (${colourA}) placed vertex ${vertex} at v${placedAt}; B ${nameB} asked GetHandles ` +
      `${seen.participantsAnswers} times, last at v${seen.participantsVersion}`);
    for (const page of [a, b, viewer]) await page.context().close();
  });

  it('pulls the neighbourhood of a dragged point with the editor token, and leaves the far side in place', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const page = await open(viewerUrl(session.editor_token));
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1
      && window.__filigree.canEdit === true);
    const start = await hookState(page);
    assert.equal(start.editMode, 'pull', 'pulling is the default');
    // The vertex nearest to the camera, and the one farthest from it.
    const { v, far, before } = await page.evaluate(() => {
      const h = window.__filigree;
      const v = h.nearestVertexToCamera();
      const p = h.vertexPosition(v);
      let far = v;
      let best = 0;
      for (let i = 0; i < h.vertexCount; ++i) {
        const q = h.vertexPosition(i);
        const d = Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]);
        if (d > best) [far, best] = [i, d];
      }
      return { v, far, before: [p, h.vertexPosition(far)] };
    });
    const at = await page.evaluate((i) => window.__filigree.screenPointOfVertex(i), v);
    await page.mouse.move(at.x, at.y);
    await page.mouse.down();
    await page.mouse.move(at.x + 70, at.y - 40, { steps: 8 });
    await page.mouse.up();
    // Every pose answered and the frame that includes the last one drawn.
    await waitFor(page, () => window.__filigree.handlesAnswered >= 1 && !window.__filigree.handlesSending
      && window.__filigree.drawnVersion > window.__filigree.handlesAcceptedAt);
    const after = await page.evaluate(([a, b]) => [window.__filigree.vertexPosition(a), window.__filigree.vertexPosition(b)], [v, far]);
    const distance = (p, q) => Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
    const pulled = distance(before[0], after[0]);
    const farMoved = distance(before[1], after[1]);
    const done = await hookState(page);
    assert.ok(pulled > 0.02 * meshDiagonal, `the pulled point moved ${pulled} (diagonal ${meshDiagonal})`);
    assert.ok(farMoved < 0.05 * pulled, `the far side stayed: it moved ${farMoved}, the pulled point ${pulled}`);
    assert.ok(done.pulledVertices > 0 && done.pulledVertices < done.baseVertexCount,
      `a neighbourhood moved: ${done.pulledVertices} of ${done.baseVertexCount} base vertices`);
    assert.equal(done.handleCount, 0, 'pulling leaves no handle');
    assert.ok(done.editToDrawnMs > 0, 'the panel times the edit to the frame drawn');
    t.diagnostic(`pulled ${done.pulledVertices} of ${done.baseVertexCount} base vertices: the point moved ` +
      `${pulled.toFixed(4)}, the far side ${farMoved.toExponential(2)}; edit → drawn ${done.editToDrawnMs.toFixed(1)} ms`);
    await page.context().close();
  });

  // Generated bodies (harness.mjs, writeEllipsoidObj): one standing along z
  // whose detail faces +x, one standing along y whose detail faces −z.
  for (const body of [
    { name: 'Z-up', axes: [1, 0.6, 3], up: 'z', front: [1, 0, 0] },
    { name: 'Y-up', axes: [1, 3, 0.6], up: 'y', front: [0, 0, -1] },
  ]) {
    it(`frames a ${body.name} body from its front, filling the view, and fits it again on F and the Fit button`, { timeout: TEST_TIMEOUT_MS }, async (t) => {
      const file = join(dataDir, `body-${body.up}.obj`);
      writeEllipsoidObj(file, body.axes, body.up, body.front);
      const made = await upload(grpcAddress, file, `browser-fit-${body.up}`);
      const page = await open(`?session=${made.session_id}#token=${made.viewer_token}`);
      await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesRendered >= 1);
      const upVector = body.up === 'z' ? [0, 0, 1] : [0, 1, 0];
      const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
      const look = async () => {
        const [extent, view] = await page.evaluate(() => [window.__filigree.screenExtent(), window.__filigree.viewDirection()]);
        return { extent, view, fill: Math.max(extent.width, extent.height) };
      };
      const first = await look();
      assert.equal((await hookState(page)).upAxis, body.up);
      // Seen from the front: looking along −front, up on screen is the body's up.
      assert.ok(dot(first.view.look, body.front) < -0.99, `looks at the front: ${first.view.look}`);
      assert.ok(dot(first.view.up, upVector) > 0.99, `up is ${body.up}: ${first.view.up}`);
      assert.ok(first.fill >= 0.5, `fills ${(100 * first.fill).toFixed(0)}% of the view's height or width`);
      assert.ok(first.extent.left >= 0 && first.extent.top >= 0 && first.extent.left + first.extent.width <= 1
        && first.extent.top + first.extent.height <= 1, `all in view: ${JSON.stringify(first.extent)}`);

      // Zoomed out and turned: F brings it back; so does the Fit button.
      const canvas = await page.locator('#view canvas').boundingBox();
      const middle = { x: canvas.x + canvas.width / 2, y: canvas.y + canvas.height / 2 };
      for (const refit of [() => page.keyboard.press('f'), () => page.click('#fit')]) {
        await page.mouse.move(middle.x, middle.y);
        for (let i = 0; i < 6; ++i) await page.mouse.wheel(0, 400);
        await page.mouse.move(middle.x + 5, middle.y + 5);
        await page.mouse.down();
        await page.mouse.move(middle.x + 150, middle.y + 60, { steps: 5 });
        await page.mouse.up();
        await waitFor(page, () => {
          const e = window.__filigree.screenExtent();
          return Math.max(e.width, e.height) < 0.4;
        });
        const fits = (await hookState(page)).fits;
        await refit();
        await waitFor(page, (n) => window.__filigree.fits > n, fits);
        const again = await look();
        assert.ok(Math.abs(again.fill - first.fill) < 1e-3, `fit again: ${again.fill} vs ${first.fill}`);
        assert.ok(dot(again.view.look, body.front) < -0.99);
      }
      t.diagnostic(`${body.name}: fills ${(100 * first.extent.width).toFixed(0)}% × ${(100 * first.extent.height).toFixed(0)}% ` +
        `of the view, looking along ${first.view.look.map((x) => x.toFixed(2))}`);
      await page.context().close();
    });
  }

  it('at phone width (390 px): the canvas first and whole, the panel a drawer, by keyboard too', { timeout: TEST_TIMEOUT_MS }, async () => {
    const context = await browser.newContext({ viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true });
    const page = await context.newPage();
    page.on('pageerror', (error) => pageErrors.push(`phone: ${error.message}`));
    await page.goto(`${baseUrl}/${viewerUrl(session.editor_token)}`);
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesRendered >= 1);
    const canvas = await page.locator('#view canvas').boundingBox();
    assert.ok(canvas.x === 0 && canvas.y === 0 && canvas.width >= 389 && canvas.height >= 600,
      `the canvas takes the screen: ${JSON.stringify(canvas)}`);
    assert.equal(await page.isVisible('#panel'), false, 'the drawer starts closed');
    const extent = await page.evaluate(() => window.__filigree.screenExtent());
    assert.ok(Math.max(extent.width, extent.height) >= 0.5, `the mesh fills the view: ${JSON.stringify(extent)}`);

    // Keyboard only: Tab to the panel button, Enter opens the drawer, Escape closes it.
    await page.keyboard.press('Tab');
    await page.keyboard.press('Tab');
    assert.equal(await page.evaluate(() => document.activeElement?.id), 'panel-toggle');
    await page.keyboard.press('Enter');
    await waitFor(page, () => document.querySelector('#panel').getBoundingClientRect().height > 0);
    const panel = await page.locator('#panel').boundingBox();
    assert.ok(panel.x >= 0 && panel.x + panel.width <= 390 && panel.y + panel.height <= 844 + 1,
      `the drawer is on screen: ${JSON.stringify(panel)}`);
    assert.equal(await page.getAttribute('#panel-toggle', 'aria-expanded'), 'true');
    assert.ok(await page.isVisible('#stats'));
    await page.keyboard.press('Escape');
    await waitFor(page, () => document.querySelector('#panel').getBoundingClientRect().height === 0);
    assert.equal(await page.getAttribute('#panel-toggle', 'aria-expanded'), 'false');
    await context.close();
  });

  it('colours the stretch of a bent mesh, computed in the worker', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const page = await open(viewerUrl(session.viewer_token));
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1);
    await page.uncheck('#show-activity');  // colours of the stretch map only, not the driver's dots
    const plain = colouredFraction(png(await page.evaluate(() => window.__filigree.capture())));
    await page.check('#overlay-stretch');
    // Armed before the drive: the first frame whose stretch is clearly above rigid.
    const stretched = waitFor(page, () => window.__filigree.stretchMax > 0.05);
    await cli(driveArgs(grpcAddress, session, 'bend', 20, 20, 'browser-test-stretch'));
    await stretched;
    const { stretchMax } = await hookState(page);
    const coloured = colouredFraction(png(await page.evaluate(() => window.__filigree.capture())));
    assert.ok(coloured > 0.02 && coloured > 4 * plain, `the stretch map colours the mesh: ${(100 * coloured).toFixed(1)}% ` +
      `of the pixels (${(100 * plain).toFixed(1)}% without it)`);
    await page.uncheck('#overlay-stretch');
    await waitFor(page, () => window.__filigree.stretchMax === 0);
    t.diagnostic(`stretch: ${(100 * coloured).toFixed(1)}% coloured pixels at max |L2 − 1| = ${stretchMax.toFixed(3)}`);
    await page.context().close();
  });

  it('shows the regions, which the threshold turns on and off', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const page = await open(viewerUrl(session.editor_token));
    await waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1);
    const setThreshold = async (value) => {
      await page.fill('#threshold', String(value));
      await page.click('#options button[type=submit]');
      await waitFor(page, (v) => document.querySelector('#options-status').textContent === `T is now ${v}.`, value);
    };
    await page.check('#overlay-regions');
    await page.uncheck('#show-activity');  // colours of the regions only, not the driver's dots
    await setThreshold(1e5);

    // Armed before the drive: a bend with T = 1e5 refines regions.
    const sawRegions = waitFor(page, () => window.__filigree.regionCount > 0);
    await cli(driveArgs(grpcAddress, session, 'bend', 20, 20, 'browser-test-regions'));
    await sawRegions;
    const withRegions = await hookState(page);
    const coloured = colouredFraction(png(await page.evaluate(() => window.__filigree.capture())));
    assert.ok(coloured > 0.02, `the regions are coloured: ${(100 * coloured).toFixed(1)}% of pixels`);
    assert.match(await page.textContent('#overlays-status'), /[1-9]\d* regions?, a cut mesh of \d+ triangles/);

    // T = 0 and one more pose: direct recovery only, no regions.
    await setThreshold(0);
    await page.click('#round-trip');
    await waitFor(page, () => window.__filigree.regionCount === 0);
    const without = colouredFraction(png(await page.evaluate(() => window.__filigree.capture())));
    assert.ok(without < 0.005, `no region colours at T = 0: ${(100 * without).toFixed(2)}% of pixels`);
    t.diagnostic(`T = 1e5: ${withRegions.regionCount} regions at v${withRegions.overlaysVersion}, ` +
      `${(100 * coloured).toFixed(1)}% coloured pixels; T = 0: ${(100 * without).toFixed(2)}%`);
    await page.context().close();
  });
});

// ------------------------------------------------------------------ HTTPS

// A CA valid for a day and a server certificate for 127.0.0.1 and localhost
// signed by it, in `dir` (ca.pem, server.pem, server.key); EC keys (fast).
function makeCertificates(dir) {
  const openssl = (...args) => execFileSync('openssl', args, { cwd: dir, stdio: ['ignore', 'ignore', 'pipe'] });
  const newKey = (name) => ['-newkey', 'ec', '-pkeyopt', 'ec_paramgen_curve:prime256v1', '-nodes', '-subj', `/CN=${name}`,
    '-keyout', `${name}.key`];
  openssl('req', '-x509', ...newKey('ca'), '-days', '1', '-out', 'ca.pem');
  openssl('req', ...newKey('server'), '-out', 'server.csr');
  writeFileSync(join(dir, 'server.ext'), 'subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n');
  openssl('x509', '-req', '-in', 'server.csr', '-CA', 'ca.pem', '-CAkey', 'ca.key', '-set_serial', '1', '-days', '1',
    '-out', 'server.pem', '-extfile', 'server.ext');
}

// base64(SHA-256(SubjectPublicKeyInfo)): what --ignore-certificate-errors-spki-list takes.
function spkiHash(pemFile) {
  const der = new X509Certificate(readFileSync(pemFile)).publicKey.export({ type: 'spki', format: 'der' });
  return createHash('sha256').update(der).digest('base64');
}

describe('the web viewer over HTTPS (--tls-cert on the --http port)', { timeout: 3 * TEST_TIMEOUT_MS }, () => {
  let server;
  let dataDir;
  let certDir;
  let baseUrl;   // https://H:P
  let grpcAddress;
  let browser;   // trusts the test server's key, nothing else
  let session;
  const tlsArgs = () => ['--tls-ca', join(certDir, 'ca.pem')];
  const pageErrors = [];

  before(async () => {
    assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    checkTools();
    certDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-tls-'));
    makeCertificates(certDir);
    dataDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-tls-data-'));
    server = startServer(dataDir, ['--tls-cert', join(certDir, 'server.pem'), '--tls-key', join(certDir, 'server.key')]);
    const addresses = await server.addresses;
    grpcAddress = addresses.grpc;
    baseUrl = `https://${addresses.http}`;
    session = await upload(grpcAddress, MESH, 'browser-tls-test', tlsArgs());
    // Pinning the server's key is narrower than ignoreHTTPSErrors (any certificate).
    browser = await chromium.launch({
      executablePath: CHROMIUM, headless: true,
      args: [...CHROMIUM_ARGS, `--ignore-certificate-errors-spki-list=${spkiHash(join(certDir, 'server.pem'))}`],
    });
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    await browser?.close();
    if (server && server.child.exitCode === null && server.child.signalCode === null) {
      await stopServerCleanly(server, STOP_TIMEOUT_MS);
    }
    for (const dir of [dataDir, certDir]) if (dir) rmSync(dir, { recursive: true, force: true });
    assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
  }, { timeout: HOOK_TIMEOUT_MS });

  it('loads over https://, shows the session\'s mesh and follows a drive', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const context = await browser.newContext({ viewport: { width: 800, height: 600 } });
    const page = await context.newPage();
    page.on('pageerror', (error) => pageErrors.push(`https: ${error.message}`));
    const response = await page.goto(`${baseUrl}/?session=${session.session_id}&token=${session.viewer_token}`);
    assert.equal(response.status(), 200);
    assert.ok((await response.securityDetails())?.protocol?.startsWith('TLS'), 'the page came over TLS');
    assert.deepEqual(await page.evaluate(() => [location.protocol, window.isSecureContext]), ['https:', true]);

    await page.waitForFunction(() => window.__filigree?.framesApplied >= 1 && window.__filigree.framesRendered >= 1,
      null, { timeout: WAIT_MS });
    const joined = await hookState(page);
    assert.equal(joined.state, 'live');
    assert.equal(joined.vertexCount, 1839);
    assert.equal(joined.error, null);
    const variance = luminanceVariance(png(await page.locator('#view canvas').screenshot()));
    assert.ok(variance > 100, `the canvas shows a mesh (luminance variance ${variance.toFixed(1)})`);

    // Frames streamed over the same TLS port (gRPC-Web Watch) reach the page.
    await cli([...driveArgs(grpcAddress, session, 'bend', 20, 30, 'browser-tls-bend'), ...tlsArgs()]);
    await page.waitForFunction((before) => window.__filigree.framesReceived >= before + 5, joined.framesReceived,
      { timeout: WAIT_MS });
    const done = await hookState(page);
    assert.ok(done.version > joined.version, `version grows over HTTPS: ${done.version} > ${joined.version}`);
    t.diagnostic(`over ${(await response.securityDetails()).protocol}: frames received ` +
      `${done.framesReceived - joined.framesReceived}, v${joined.version} → v${done.version}`);
    await context.close();
  });

  it('is refused by a browser that does not trust the certificate', { timeout: TEST_TIMEOUT_MS }, async () => {
    const plain = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
    try {
      const page = await (await plain.newContext()).newPage();
      await assert.rejects(page.goto(`${baseUrl}/`), /ERR_CERT_AUTHORITY_INVALID/);
    } finally {
      await plain.close();
    }
  });
});

// ------------------------------------------------------------------ restarts

describe('the web viewer across server restarts (--data-dir, same ports)', { timeout: 4 * TEST_TIMEOUT_MS }, () => {
  const FOLLOW_MS = 2000;   // the page follows again within this long of the health check passing
  let server;
  let dataDir;
  let addresses;
  let browser;
  let session;
  let page;                 // one page across both restarts
  const pageErrors = [];

  before(async () => {
    assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
    checkTools();
    dataDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-restart-'));
    server = startServer(dataDir);
    addresses = await server.addresses;
    session = await upload(addresses.grpc, MESH, 'browser-restart-test');
    browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
    const context = await browser.newContext({ viewport: { width: 800, height: 600 } });
    page = await context.newPage();
    page.on('pageerror', (error) => pageErrors.push(`restart: ${error.message}`));
    await page.goto(`http://${addresses.http}/?session=${session.session_id}#token=${session.viewer_token}`);
    await page.waitForFunction(() => window.__filigree?.state === 'live', null, { timeout: WAIT_MS });
  }, { timeout: HOOK_TIMEOUT_MS });

  after(async () => {
    await browser?.close();
    if (server && server.child.exitCode === null && server.child.signalCode === null) await stopServer(server, STOP_TIMEOUT_MS);
    if (dataDir) rmSync(dataDir, { recursive: true, force: true });
    assert.deepEqual(pageErrors, [], 'no uncaught errors in the page');
  }, { timeout: HOOK_TIMEOUT_MS });

  // Drives the session until the server goes away; kills the server with
  // `signal` while the page follows; starts it again on the same ports and
  // data directory; once its health check passes, drives again and waits
  // for the page to draw a version newer than any it saw before the kill.
  async function restart(t, signal) {
    const before = await hookState(page);
    // A driver of its own (not cli()): it is stopped with the server, not awaited (it may retry for long).
    const driver = spawn(CLI, driveArgs(addresses.grpc, session, 'bend', 100_000, 30, `restart-${signal}`), { stdio: 'ignore' });
    const driverExited = new Promise((done) => driver.on('exit', done));
    await page.waitForFunction((v) => window.__filigree.drawnVersion >= v + 5, before.drawnVersion, { timeout: WAIT_MS });

    server.child.kill(signal);
    const stopped = await server.exited;
    assert.equal(stopped.signal ?? 'exit', signal === 'SIGKILL' ? 'SIGKILL' : 'exit', `the server stopped by ${signal}`);
    await page.waitForFunction(() => window.__filigree.state === 'reconnecting', null, { timeout: WAIT_MS });
    const lastSeen = (await hookState(page)).newestVersion;
    driver.kill('SIGKILL');
    await driverExited;

    server = startServer(dataDir, [], addresses);
    await server.addresses;
    await waitForHealth(addresses.grpc, WAIT_MS);
    const healthy = Date.now();
    const again = cli(driveArgs(addresses.grpc, session, 'bend', 90, 30, `restart-${signal}-again`));
    const following = (v) => window.__filigree.state === 'live' && window.__filigree.drawnVersion > v;
    // Waits longer than the bound, so that a failure says how late the page was, and in what state.
    const late = await page.waitForFunction(following, lastSeen, { timeout: WAIT_MS }).then(() => null, (e) => e.message);
    const followed = Date.now() - healthy;
    const atFollow = await hookState(page);
    await again;
    // And it keeps following: the new drive's frames arrive and are drawn.
    await page.waitForFunction((n) => window.__filigree.framesDrawn >= n + 10, atFollow.framesDrawn, { timeout: WAIT_MS });
    const status = await page.textContent('#status');
    assert.ok(late === null && followed <= FOLLOW_MS, `the page followed ${followed} ms after the health check ` +
      `(at most ${FOLLOW_MS}): ${late ?? 'in time'}; status "${status}", page ${JSON.stringify(await hookState(page))}`);
    const after = await hookState(page);
    assert.ok(after.reconnects > before.reconnects, 'the page opened its stream again');
    assert.equal(after.error, null, 'no error shown');
    assert.match(await page.textContent('#status'), /^Live\.$/);
    t.diagnostic(`${signal}: last version seen v${lastSeen}; drawn v${after.drawnVersion} ${followed} ms after the ` +
      `health check passed; loss: ${after.lastLoss}; reconnects ${after.reconnects}`);
  }

  it('follows the session again after SIGTERM and a restart', { timeout: 2 * TEST_TIMEOUT_MS }, (t) => restart(t, 'SIGTERM'));
  it('follows the session again after SIGKILL and a restart', { timeout: 2 * TEST_TIMEOUT_MS }, (t) => restart(t, 'SIGKILL'));

  it('is live again after a restart with nothing new to show (an idle session)', { timeout: TEST_TIMEOUT_MS }, async () => {
    // Nothing drives the session: the stream opens again with no frame to
    // send, and the page says it is live once the server answers.
    const before = await hookState(page);
    server.child.kill('SIGKILL');
    await server.exited;
    await page.waitForFunction(() => window.__filigree.state === 'reconnecting', null, { timeout: WAIT_MS });
    server = startServer(dataDir, [], addresses);
    await server.addresses;
    await waitForHealth(addresses.grpc, WAIT_MS);
    await page.waitForFunction(() => window.__filigree.state === 'live', null, { timeout: FOLLOW_MS });
    const after = await hookState(page);
    assert.equal(after.reconnects, before.reconnects + 1);
    assert.match(await page.textContent('#status'), /^Live\.$/);
  });

  it('stops, saying so, when the session is gone', { timeout: TEST_TIMEOUT_MS }, async () => {
    // CloseSession through gRPC-Web from another page (the CLI has no close):
    // CloseSessionRequest { session_id = 1 } in one uncompressed frame.
    const closer = await (await browser.newContext()).newPage();
    await closer.goto(`http://${addresses.http}/`);
    const status = await closer.evaluate(async ({ id, token }) => {
      const message = new TextEncoder().encode(id);
      const body = new Uint8Array([0, 0, 0, 0, 2 + message.length, 0x0a, message.length, ...message]);
      const response = await fetch('/filigree.v1.Filigree/CloseSession', {
        method: 'POST', body,
        headers: { 'content-type': 'application/grpc-web+proto', 'x-grpc-web': '1', 'x-filigree-token': token },
      });
      await response.arrayBuffer();
      return response.headers.get('grpc-status') ?? 'in the trailer';
    }, { id: session.session_id, token: session.editor_token });
    await closer.context().close();
    assert.ok(status === '0' || status === 'in the trailer', `CloseSession answered grpc-status ${status}`);
    await page.waitForFunction(() => window.__filigree.state === 'closed', null, { timeout: WAIT_MS });
    assert.match(await page.textContent('#status'), /closed/);
  });
});
