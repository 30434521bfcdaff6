// The viewer's screenshots in ../docs (run by hand, not a test):
//   docs/viewer-regions.png  a session bent part-way by the CLI, T = 1e6, the regions overlay on
//   docs/viewer-handles.png  a handle being dragged (two anchoring), the stretch map on
//   docs/images/front-door.png  the root page: create, the sessions (one made here), connect a program
//   docs/images/live-two-participants.png  two editor pages on one session side by side, each holding handles; each
//                                          shows the other's in its colour with its name, and lists it
//   docs/images/million-vertices.png  a 1,001,114-vertex bumpy sphere bent by the CLI
//
//   node test/screenshots.mjs [MESH] [--only regions,handles,front,two,million]
//   (after npm run build; MESH default: data/armadillo.off)
//
// Same server and upload as browser.test.mjs (harness.mjs); the environment
// variables are the same. Waits on page conditions, never on sleeps.

import { mkdirSync, mkdtempSync, rmSync, statSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { spawn } from 'node:child_process';

import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, diagonal, driveArgs, hookState, ROOT, startServer, stopServer, upload,
  writeBumpySphere,
} from './harness.mjs';

const args = process.argv.slice(2);
const onlyAt = args.indexOf('--only');
const ONLY = new Set(onlyAt >= 0 ? args[onlyAt + 1].split(',') : ['regions', 'handles', 'front', 'two', 'million']);
const MESH = resolve(args.find((a, i) => !a.startsWith('--') && i !== onlyAt + 1 || (onlyAt < 0 && !a.startsWith('--')))
  ?? join(ROOT, 'data', 'armadillo.off'));
const DOCS = join(ROOT, 'docs');
const IMAGES = join(DOCS, 'images');
const VIEWPORT = { width: 1280, height: 800 };
const WAIT_MS = 60_000;
const THRESHOLD = 1e6;  // regions of a useful size on the armadillo

checkTools();
mkdirSync(IMAGES, { recursive: true });
const meshDiagonal = diagonal(MESH);
const dataDir = mkdtempSync(join(tmpdir(), 'filigree-screenshots-'));
const server = startServer(dataDir);
let browser;
try {
  const { grpc, http } = await server.addresses;
  browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });

  const open = async (session) => {
    const page = await (await browser.newContext({ viewport: VIEWPORT })).newPage();
    page.on('pageerror', (error) => { throw error; });
    await page.goto(`http://${http}/?session=${session.session_id}#token=${session.editor_token}`);
    await page.waitForFunction(() => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1,
      null, { timeout: WAIT_MS });
    return page;
  };
  const waitFor = (page, fn, arg) => page.waitForFunction(fn, arg, { timeout: WAIT_MS }).catch(async (error) => {
    throw new Error(`${error.message}\nthe page: ${JSON.stringify(await hookState(page))}`);
  });
  // Where the mesh is on a page: the top of the centre column (x, top), a row
  // near the bottom (y) and where that row meets the mesh (left, right).
  const meshExtent = (page) => page.evaluate(() => {
    const rect = document.querySelector('#view canvas').getBoundingClientRect();
    const hit = (x, y) => window.__filigree.vertexAt(x, y) !== null;
    const hitInRow = (y) => { for (let x = rect.left; x < rect.right; x += 8) if (hit(x, y)) return true; return false; };
    const x = rect.left + rect.width / 2;
    let top = rect.top;
    while (top < rect.bottom && !hit(x, top)) top += 2;
    let bottom = rect.bottom;
    while (bottom > top && !hitInRow(bottom)) bottom -= 4;
    const y = bottom - 0.05 * (bottom - top);
    let left = rect.left;
    while (left < rect.right && !hit(left, y)) left += 2;
    let right = rect.right;
    while (right > left && !hit(right, y)) right -= 2;
    return { x, top, bottom, y, left, right };
  });
  // The panel shows the section about the overlays.
  const showPanelAt = (page, selector) => page.evaluate((s) => {
    const panel = document.querySelector('#panel');
    panel.scrollTop = document.querySelector(s).closest('section').offsetTop - 8;
  }, selector);

  // ---- regions: bend with T = 1e6, stop the drive part-way, wait for that frame's overlays.
  if (ONLY.has('regions')) {
    const session = await upload(grpc, MESH, 'screenshots');
    const page = await open(session);
    await page.check('#overlay-regions');
    await page.fill('#threshold', String(THRESHOLD));
    await page.click('#options button[type=submit]');
    await waitFor(page, (t) => document.querySelector('#options-status').textContent === `T is now ${t}.`, THRESHOLD);
    const drive = spawn(CLI, driveArgs(grpc, session, 'bend', 120, 10, 'cli-bend'), { stdio: 'ignore' });
    await waitFor(page, (d) => window.__filigree.displacement > d && window.__filigree.regionCount > 0, 0.25 * meshDiagonal);
    drive.kill('SIGTERM');
    await new Promise((done) => drive.on('exit', done));
    // The session keeps the last pose: wait until the page shows its frame and overlays.
    // (received = applied + skipped: no frame is still being decoded.)
    await waitFor(page, () => window.__filigree.overlaysVersion === window.__filigree.version && window.__filigree.regionCount > 0
      && window.__filigree.framesReceived === window.__filigree.framesApplied + window.__filigree.framesSkipped);
    await showPanelAt(page, '#overlays');
    await page.screenshot({ path: join(DOCS, 'viewer-regions.png') });
    console.log('docs/viewer-regions.png:', JSON.stringify(await hookState(page)));
    await page.context().close();
  }

  // ---- handles: both feet anchored by a click, the head dragged sideways and held.
  if (ONLY.has('handles')) {
    const session = await upload(grpc, MESH, 'screenshots-handles');
    const page = await open(session);
    await page.selectOption('#edit-mode', 'handles');
    await page.check('#overlay-stretch');
    // Where the mesh is: the top of the centre column, the ends of a row near the bottom.
    const extent = await meshExtent(page);
    const height = extent.bottom - extent.top;
    const handles = (n) => waitFor(page, (k) => window.__filigree.handleCount === k && !window.__filigree.handlesSending, n);
    // Anchors: a click (press and release, no move) keeps a vertex where it is.
    for (const x of [extent.left + 10, extent.right - 10]) {
      await page.mouse.click(x, extent.y);
    }
    await handles(2);
    // The dragged handle (the head), held while the screenshot is taken.
    const from = { x: extent.x, y: extent.top + 0.06 * height };
    await page.mouse.move(from.x, from.y);
    await page.mouse.down();
    await page.mouse.move(from.x + 0.4 * height, from.y + 0.12 * height, { steps: 20 });
    await handles(3);
    // The frame with the last target is shown.
    await waitFor(page, () => window.__filigree.version > window.__filigree.handlesAcceptedAt
      && window.__filigree.framesReceived === window.__filigree.framesApplied + window.__filigree.framesSkipped);
    await showPanelAt(page, '#handle-count');
    await page.screenshot({ path: join(DOCS, 'viewer-handles.png') });
    console.log('docs/viewer-handles.png:', JSON.stringify(await hookState(page)));
    await page.mouse.up();
    await page.context().close();
  }

  const saved = (path) => console.log(`${path.slice(ROOT.length + 1)}: ${Math.round(statSync(path).size / 1024)} KB`);

  // ---- the front door: a session made with the demo button in this browser, another by the CLI.
  if (ONLY.has('front')) {
    await upload(grpc, MESH, 'cli-upload');
    const context = await browser.newContext({ viewport: { width: 1280, height: 760 } });
    const page = await context.newPage();
    page.on('pageerror', (error) => { throw error; });
    await page.goto(`http://${http}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed');
    await page.click('#demo');
    await waitFor(page, () => window.__filigree.state === 'live' && window.__filigree.framesApplied >= 1);
    await page.goto(`http://${http}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed' && window.__filigree.sessionsListed.length >= 2);
    const path = join(IMAGES, 'front-door.png');
    await page.screenshot({ path });
    saved(path);
    await context.close();
  }

  // ---- two participants: two editor pages side by side, each holding handles; each page shows the other's
  // handles in its colour with its name, and lists it in the panel.
  if (ONLY.has('two')) {
    const session = await upload(grpc, MESH, 'two-participants');
    const size = { width: 720, height: 520 };  // over 700 px: the panel beside the canvas, not a drawer
    const pages = [];
    for (let k = 0; k < 2; ++k) {
      const page = await (await browser.newContext({ viewport: size })).newPage();
      page.on('pageerror', (error) => { throw error; });
      await page.goto(`http://${http}/?session=${session.session_id}#token=${session.editor_token}&viewer=${session.viewer_token}`);
      await page.waitForFunction(() => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1, null, { timeout: WAIT_MS });
      await page.selectOption('#edit-mode', 'handles');
      pages.push(page);
    }
    const [a, b] = pages;
    // Page names are random and colours come from names: B is reloaded (a new name) until the two colours differ.
    const colourOf = (page) => page.evaluate(() => window.__filigree.participantColour(window.__filigree.clientName));
    while (await colourOf(a) === await colourOf(b)) {
      await b.reload();
      await b.waitForFunction(() => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1, null, { timeout: WAIT_MS });
      await b.selectOption('#edit-mode', 'handles');
    }
    const settled = (page, n) => waitFor(page, (k) => window.__filigree.handleCount === k && window.__filigree.handlesAnswered > 0
      && !window.__filigree.handlesSending, n);
    // B pins a foot (a click keeps a vertex where it is).
    const eb = await meshExtent(b);
    await b.mouse.click(eb.right - 8, eb.y);
    await settled(b, 1);
    // A pins the other foot, then drags the head sideways and holds it.
    const ea = await meshExtent(a);
    await a.mouse.click(ea.left + 8, ea.y);
    await settled(a, 1);
    const height = ea.bottom - ea.top;
    const from = { x: ea.x, y: ea.top + 0.06 * height };
    await a.mouse.move(from.x, from.y);
    await a.mouse.down();
    await a.mouse.move(from.x + 0.12 * height, from.y + 0.04 * height, { steps: 20 });
    await settled(a, 2);
    // Each page shows the other's handles (asked after the frame that names them), its
    // label placed, and the newest frame drawn; the change lists name both pages.
    const names = await Promise.all(pages.map((p) => p.evaluate(() => window.__filigree.clientName)));
    const accepted = await Promise.all(pages.map((p) => p.evaluate(() => window.__filigree.handlesAcceptedAt)));
    for (const [k, page] of pages.entries()) {
      const other = 1 - k;
      await waitFor(page, ([name, count, at]) => window.__filigree.participants.some((p) => p.name === name && p.handles === count)
        && window.__filigree.participantsVersion >= at && !window.__filigree.participantsFetching
        && document.querySelector(`.participant-label[data-participant="${name}"]`)?.style.transform
        && window.__filigree.drawnVersion === window.__filigree.newestVersion
        && window.__filigree.framesReceived === window.__filigree.framesApplied + window.__filigree.framesSkipped,
        [names[other], other === 0 ? 2 : 1, accepted[other]]);
      await waitFor(page, (n) => n.every((name) => document.querySelector('#changes').textContent.includes(name)), names);
      await showPanelAt(page, '#participants');
    }
    const shots = await Promise.all(pages.map((p) => p.screenshot().then((data) => PNG.sync.read(data))));
    const gap = 8;
    const out = new PNG({ width: 2 * size.width + gap, height: size.height });
    out.data.fill(0x10);
    shots.forEach((shot, k) => PNG.bitblt(shot, out, 0, 0, size.width, size.height, k * (size.width + gap), 0));
    const path = join(IMAGES, 'live-two-participants.png');
    // Kept small for the repository: RGB without alpha, each channel to 6 bits (deflate then finds runs).
    for (let i = 0; i < out.data.length; ++i) if (i % 4 !== 3) out.data[i] = Math.min(255, out.data[i] + 2) & 0xfc;
    writeFileSync(path, PNG.sync.write(out, { colorType: 2, inputHasAlpha: true }));
    saved(path);
    await a.mouse.up();
    for (const page of pages) await page.context().close();
  }

  // ---- a million vertices: a bumpy sphere (binary PLY in a temp dir), bent by the CLI part-way.
  if (ONLY.has('million')) {
    const file = join(dataDir, 'sphere-1m.ply');
    const n = writeBumpySphere(file, 708, 1416);
    const session = await upload(grpc, file, 'million', []);
    const page = await (await browser.newContext({ viewport: { width: 1200, height: 720 } })).newPage();
    page.on('pageerror', (error) => { throw error; });
    await page.goto(`http://${http}/?session=${session.session_id}#token=${session.editor_token}&viewer=${session.viewer_token}`);
    await page.waitForFunction(() => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1, null, { timeout: 3 * WAIT_MS });
    const drive = spawn(CLI, driveArgs(grpc, session, 'bend', 60, 10, 'cli-bend'), { stdio: 'ignore' });
    await waitFor(page, () => window.__filigree.displacement > 0.3);
    drive.kill('SIGTERM');
    await new Promise((done) => drive.on('exit', done));
    // The last frame applied and drawn in full detail: every vertex (Auto
    // watches a level while driven and switches to full detail at rest), not
    // the stand-in drawn while busy.
    await waitFor(page, () => window.__filigree.framesReceived === window.__filigree.framesApplied + window.__filigree.framesSkipped
      && window.__filigree.drawnVersion === window.__filigree.version
      && window.__filigree.levelVertices === window.__filigree.fullVertexCount);
    await waitFor(page, () => window.__filigree.lastDrawFull);
    const path = join(IMAGES, 'million-vertices.png');
    await page.screenshot({ path });
    saved(path);
    console.log(`  ${n} vertices:`, JSON.stringify(await hookState(page)));
    await page.context().close();
  }
} finally {
  await browser?.close();
  await stopServer(server, 20_000);
  rmSync(dataDir, { recursive: true, force: true });
}
