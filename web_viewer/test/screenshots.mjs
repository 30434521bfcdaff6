// The viewer's screenshots in ../docs (run by hand, not a test):
//   docs/viewer-regions.png  a session bent part-way by the CLI, T = 1e6, the regions overlay on
//   docs/viewer-handles.png  a handle being dragged (two anchoring), the stretch map on
//
//   node test/screenshots.mjs [MESH]     (after npm run build; MESH default: data/armadillo.off)
//
// Same server and upload as browser.test.mjs (harness.mjs); the environment
// variables are the same. Waits on page conditions, never on sleeps.

import { mkdirSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { spawn } from 'node:child_process';

import { chromium } from 'playwright-core';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, diagonal, driveArgs, hookState, ROOT, startServer, stopServer, upload,
} from './harness.mjs';

const MESH = resolve(process.argv[2] ?? join(ROOT, 'data', 'armadillo.off'));
const DOCS = join(ROOT, 'docs');
const VIEWPORT = { width: 1280, height: 800 };
const WAIT_MS = 60_000;
const THRESHOLD = 1e6;  // regions of a useful size on the armadillo

checkTools();
mkdirSync(DOCS, { recursive: true });
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
  // The panel shows the section about the overlays.
  const showPanelAt = (page, selector) => page.evaluate((s) => {
    const panel = document.querySelector('#panel');
    panel.scrollTop = document.querySelector(s).closest('section').offsetTop - 8;
  }, selector);

  // ---- regions: bend with T = 1e6, stop the drive part-way, wait for that frame's overlays.
  {
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
  {
    const session = await upload(grpc, MESH, 'screenshots-handles');
    const page = await open(session);
    await page.selectOption('#edit-mode', 'handles');
    await page.check('#overlay-stretch');
    // Where the mesh is: the top of the centre column, the ends of a row near the bottom.
    const extent = await page.evaluate(() => {
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
} finally {
  await browser?.close();
  await stopServer(server, 20_000);
  rmSync(dataDir, { recursive: true, force: true });
}
