// Working together in Chromium against a real filigree-server: two editor
// pages (own browser contexts, so own client names) on a bumpy sphere of
// 2,050 vertices with 600 base vertices.
//
//   - A drag (pull) is one history entry even with a pause in it (one gesture
//     id for the drag: without it the server would start a new entry after
//     0.5 s), and so is a handle drag, which one undo takes back whole.
//   - A pulls, B pulls elsewhere, A presses Ctrl+Z: A's change is undone, B's
//     kept (vertex positions on both pages); Ctrl+Shift+Z redoes it; the Undo
//     button and Ctrl+Y too.
//   - B pulls over all of A's pull: A's undo changes nothing and says so,
//     naming B; "Undo anyway" overwrites.
//   - A checkpoint saved, compared ("N base vertices differ, max distance d"),
//     restored (B's later pull gone on both pages), compared again (0).
//   - Presence: a page that joins late sees A at once (the stream's first
//     message) in A's colour with A's role and A's pointer at the vertex
//     under A's mouse; A's pointer moves; the base vertices A's pull touched
//     show as dots in A's colour; a viewer page is listed as a viewer.
//   - GetHistory while a program drives: one call in flight, at most 4 a second.
//
// Environment: FILIGREE_SERVER (required), FILIGREE_CLI, CHROMIUM (harness.mjs).
// Needs the build (dist/). No sleeps: every wait is on a condition, with a
// timeout (the pauses inside drags are part of what is tested: the page's
// clock passing 0.6 s with the mouse held still).

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
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
const WAIT_MS = 45_000;
const STOP_TIMEOUT_MS = 20_000;
// A pause longer than the server's 0.5 s that splits gesture-less changes into entries.
const PAUSE_MS = 600;
const OUTCOME = { DONE: 0, PARTIAL: 1, CONFLICT: 2, NOTHING: 3 };
// The server's palette (server/session_presence.cpp).
const SERVER_PALETTE = ['#e6194b', '#3cb44b', '#4363d8', '#f58231', '#911eb4', '#bfef45', '#f032e6', '#9a6324'];

let browser;
let server;
let dataDir;
let baseUrl;
let grpc;
let session;
const pageErrors = [];

const newPage = (token) => openPage(browser, `${baseUrl}/?session=${session.session_id}#token=${token}`, pageErrors,
  { width: 900, height: 650 });
const waitFor = (page, fn, arg, timeout = WAIT_MS) => waitShowing(page, fn, arg, timeout);
const distance = (p, q) => Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);

// The server's colour of a name: FNV-1a of its UTF-8 bytes over the palette.
function serverColour(name) {
  let h = 0x811c9dc5;
  for (const byte of Buffer.from(name, 'utf8')) h = Math.imul(h ^ byte, 0x01000193) >>> 0;
  return SERVER_PALETTE[h % SERVER_PALETTE.length];
}

// An editor page, live, past its first history answer and presence message.
async function editor() {
  const page = await newPage(session.editor_token);
  await waitFor(page, () => window.__filigree?.error || (window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1
    && window.__filigree.canEdit === true && window.__filigree.historyAnswers >= 1 && window.__filigree.presenceMessages >= 1));
  const state = await hookState(page);
  assert.equal(state.error, null, 'the page shows no error');
  return page;
}

const setRadius = (page, percent) => page.$eval('#pull-radius', (input, value) => {
  input.value = value;
  input.dispatchEvent(new Event('input'));
}, String(percent));

// Where the page draws the mesh's left and right thirds at mid-height, and
// the vertices a press there takes.
async function twoPoints(page) {
  return page.evaluate(() => {
    const h = window.__filigree;
    const rect = document.querySelector('#view canvas').getBoundingClientRect();
    const e = h.screenExtent();
    const y = rect.top + (e.top + e.height / 2) * rect.height;
    const at = (f) => {
      const x = rect.left + (e.left + f * e.width) * rect.width;
      const vertex = h.vertexAt(x, y);
      return { x, y, vertex, position: h.vertexPosition(vertex) };
    };
    return [at(0.2), at(0.8)];
  });
}

// Every call of the page's edits answered and the frame that includes the last one drawn.
const settled = (page) => waitFor(page, () => window.__filigree.handlesAnswered >= 1 && !window.__filigree.handlesSending
  && window.__filigree.drawnVersion > window.__filigree.handlesAcceptedAt);

// A press at `from`, a drag by (dx, dy) in `steps` moves, a release; with
// `pause`, the mouse is held still for PAUSE_MS (every call answered first) halfway.
async function drag(page, from, dx, dy, { steps = 6, pause = false } = {}) {
  await page.mouse.move(from.x, from.y);
  await page.mouse.down();
  await page.mouse.move(from.x + dx / 2, from.y + dy / 2, { steps });
  if (pause) {
    await waitFor(page, () => window.__filigree.handlesAnswered >= 1 && !window.__filigree.handlesSending);
    const until = await page.evaluate((ms) => performance.now() + ms, PAUSE_MS);
    await waitFor(page, (t) => performance.now() >= t, until);
  }
  await page.mouse.move(from.x + dx, from.y + dy, { steps });
  await page.mouse.up();
  await settled(page);
}

// Waits until the page's vertices are where `expected` says (id → position), within `tolerance`.
function positionsNear(page, expected, tolerance) {
  return waitFor(page, ([wanted, eps]) => wanted.every(([id, p]) => {
    const q = window.__filigree.vertexPosition(id);
    return q !== null && Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) <= eps;
  }), [expected, tolerance]);
}

const positionsOf = (page, ids) => page.evaluate((list) => list.map((id) => window.__filigree.vertexPosition(id)), ids);

// Waits for the page's next undo answer (the `n`th) and returns it.
async function nextUndo(page, n) {
  await waitFor(page, (count) => window.__filigree.undos.length >= count && window.__filigree.undosPending === 0, n);
  return (await hookState(page)).undos[n - 1];
}

const ownEntries = async (page) => {
  const { history, clientName } = await hookState(page);
  return history.filter((e) => e.author === clientName);
};

before(async () => {
  assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
  checkTools();
  dataDir = mkdtempSync(join(tmpdir(), 'filigree-viewer-history-'));
  const mesh = join(dataDir, 'sphere.ply');
  writeBumpySphere(mesh, 33, 64);  // 2,050 vertices
  server = startServer(dataDir);
  const addresses = await server.addresses;
  grpc = addresses.grpc;
  baseUrl = `http://${addresses.http}`;
  session = await upload(grpc, mesh, 'history-test', ['--base-vertices', '600']);
  browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
}, { timeout: HOOK_TIMEOUT_MS });

after(async () => {
  await browser?.close();
  if (server && server.child.exitCode === null && server.child.signalCode === null) await stopServerCleanly(server, STOP_TIMEOUT_MS);
  if (dataDir) rmSync(dataDir, { recursive: true, force: true });
  assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
}, { timeout: HOOK_TIMEOUT_MS });

describe('working together: history, undo, checkpoints, presence', { timeout: 8 * TEST_TIMEOUT_MS }, () => {
  it('undoes a page\'s own drag with Ctrl+Z and keeps another page\'s; redoes it; a drag with a pause is one entry',
    { timeout: TEST_TIMEOUT_MS }, async (t) => {
      const a = await editor();
      const b = await editor();
      const nameA = (await hookState(a)).clientName;
      const nameB = (await hookState(b)).clientName;
      for (const page of [a, b]) await setRadius(page, 15);
      const [pa, pb] = await twoPoints(a);
      const radius = 0.15 * (await hookState(a)).meshRadius;
      assert.ok(distance(pa.position, pb.position) > 2.2 * radius,
        `the two pulls do not overlap: ${distance(pa.position, pb.position)} apart, radius ${radius}`);
      const bAt = await b.evaluate(({ x, y }) => window.__filigree.vertexAt(x, y), pb);
      assert.equal(bAt, pb.vertex, 'B\'s page takes the same vertex at the same point');

      // A's pull, held still halfway: one gesture, one entry.
      await drag(a, pa, 60, -50, { pause: true });
      const pulledA = await hookState(a);
      assert.ok(pulledA.pulledVertices > 0);
      await waitFor(a, () => window.__filigree.history.some((e) => e.author === window.__filigree.clientName));
      const entriesA = await ownEntries(a);
      assert.equal(entriesA.length, 1, `A's drag with a pause is one history entry: ${JSON.stringify(entriesA)}`);
      assert.equal(entriesA[0].kind, 'pose');
      assert.notEqual(entriesA[0].gestureId, '0', 'the entry carries the drag\'s gesture id');

      // B pulls elsewhere; A's page shows it.
      const [beforeB] = await positionsOf(a, [pb.vertex]);
      await drag(b, pb, -50, -50);
      await waitFor(a, ([id, p, eps]) => {
        const q = window.__filigree.vertexPosition(id);
        return Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) > eps;
      }, [pb.vertex, beforeB, 0.2 * radius]);
      const [pulledPosA, pulledPosB] = await positionsOf(a, [pa.vertex, pb.vertex]);
      const movedA = distance(pulledPosA, pa.position);
      const movedB = distance(pulledPosB, beforeB);
      assert.ok(movedA > 0.2 * radius && movedB > 0.2 * radius, `both pulls moved their vertex: ${movedA}, ${movedB}`);
      const tolerance = 0.08 * Math.min(movedA, movedB);

      // Ctrl+Z on A: A's pull undone, B's kept, on both pages.
      await a.keyboard.press('Control+z');
      const undone = await nextUndo(a, 1);
      assert.equal(undone.redo, false, 'Ctrl+Z undoes');
      assert.equal(undone.outcome, OUTCOME.DONE, `the undo restored all of A's pull: ${undone.text} (${undone.message})`);
      assert.match(undone.text, /^Undid your change to \d+ base vertices?\.$/);
      assert.match(await a.textContent('#undo-status'), /^Undid your change/);
      for (const page of [a, b]) {
        await positionsNear(page, [[pa.vertex, pa.position], [pb.vertex, pulledPosB]], tolerance);
      }
      await waitFor(a, (seq) => window.__filigree.history.some((e) => e.seq === seq && e.undone)
        && window.__filigree.history.some((e) => e.kind === 'undo' && e.author === window.__filigree.clientName), entriesA[0].seq);
      assert.ok(await a.isVisible(`#history li[data-seq="${entriesA[0].seq}"][data-undone="true"] .badge`), 'the list marks it undone');
      // B's page lists it undone too (the undo's frame names A).
      await waitFor(b, (seq) => window.__filigree.history.some((e) => e.seq === seq && e.undone), entriesA[0].seq);

      // Ctrl+Shift+Z: redone.
      await a.keyboard.press('Control+Shift+z');
      const redone = await nextUndo(a, 2);
      assert.equal(redone.redo, true, 'Ctrl+Shift+Z redoes');
      assert.equal(redone.outcome, OUTCOME.DONE, redone.text);
      assert.match(redone.text, /^Redid your/);
      for (const page of [a, b]) await positionsNear(page, [[pa.vertex, pulledPosA], [pb.vertex, pulledPosB]], tolerance);

      // The Undo button, then Ctrl+Y.
      await a.click('#undo');
      assert.equal((await nextUndo(a, 3)).outcome, OUTCOME.DONE);
      await positionsNear(a, [[pa.vertex, pa.position], [pb.vertex, pulledPosB]], tolerance);
      await a.keyboard.press('Control+y');
      const again = await nextUndo(a, 4);
      assert.equal(again.redo, true, 'Ctrl+Y redoes');
      await positionsNear(a, [[pa.vertex, pulledPosA], [pb.vertex, pulledPosB]], tolerance);

      // The list: newest first, authors in their colours.
      const rows = await a.$$eval('#history li', (items) => items.map((li) => ({
        seq: Number(li.dataset.seq), author: li.dataset.author, kind: li.dataset.kind,
        colour: li.querySelector('.author').style.backgroundColor, html: li.outerHTML,
      })));
      assert.ok(rows.every((r, i) => i === 0 || r.seq < rows[i - 1].seq), 'newest first');
      const rgb = (hex) => `rgb(${[1, 3, 5].map((k) => parseInt(hex.slice(k, k + 2), 16)).join(', ')})`;
      for (const [name, colour] of [[nameA, serverColour(nameA)], [nameB, serverColour(nameB)]]) {
        const row = rows.find((r) => r.author === name);
        assert.ok(row, `a row of ${name}`);
        assert.equal(row.colour, rgb(colour), `${name} in the server's colour for the name: ${row.html}`);
      }
      t.diagnostic(`A ${nameA} pulled ${pulledA.pulledVertices} base vertices (entry #${entriesA[0].seq}), B ${nameB} elsewhere; ` +
        `undo: "${undone.text}", redo: "${redone.text}"; history rows ${rows.length}`);
      for (const page of [a, b]) await page.context().close();
    });

  it('keeps a handle drag with a pause as one entry, and one undo takes the handle back', { timeout: TEST_TIMEOUT_MS }, async () => {
    const a = await editor();
    await a.selectOption('#edit-mode', 'handles');
    const [, point] = await twoPoints(a);
    await drag(a, point, 40, -30, { pause: true });
    await waitFor(a, () => window.__filigree.handleCount === 1 && window.__filigree.handlesInSession >= 1
      && window.__filigree.history.some((e) => e.author === window.__filigree.clientName));
    const entries = await ownEntries(a);
    assert.deepEqual(entries.map((e) => e.kind), ['handles'], `one entry for the handle drag: ${JSON.stringify(entries)}`);
    await a.keyboard.press('Control+z');
    const undone = await nextUndo(a, 1);
    assert.equal(undone.outcome, OUTCOME.DONE, undone.text);
    assert.match(undone.text, /^Undid your handle change\.$/);
    // The handle is gone from the session and from the page.
    await waitFor(a, () => window.__filigree.handleCount === 0);
    await a.context().close();
  });

  it('says whose later change a refused undo kept, and overwrites it when asked', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const a = await editor();
    const b = await editor();
    const nameB = (await hookState(b)).clientName;
    await setRadius(a, 15);
    await setRadius(b, 70);
    const [point] = await twoPoints(a);
    await drag(a, point, 40, -30);
    // B pulls at the same vertex (where B's page draws it now) with a larger radius: all of A's vertices.
    await waitFor(b, ([id, p]) => {
      const q = window.__filigree.vertexPosition(id);
      return Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) > 0;
    }, [point.vertex, point.position]);
    const atB = await b.evaluate((id) => window.__filigree.screenPointOfVertex(id), point.vertex);
    await drag(b, atB, -30, 30);
    await waitFor(a, (name) => window.__filigree.history.some((e) => e.author === name), nameB);
    const [before] = await positionsOf(a, [point.vertex]);

    await a.click('#undo');
    const refused = await nextUndo(a, 1);
    assert.equal(refused.outcome, OUTCOME.CONFLICT, `nothing undone: ${refused.text} (${refused.message})`);
    assert.ok(refused.conflicts.includes(nameB), 'the conflict names B');
    assert.match(refused.text, new RegExp(`^Nothing undone: others changed all of it since\\. Kept ${nameB}'s later change on \\d+ vert`));
    const shown = await a.textContent('#undo-status');
    assert.ok(shown.includes(`Kept ${nameB}'s later change on`), `the page says it: ${shown}`);
    // Nothing moved: B's pull stays.
    assert.ok(distance((await positionsOf(a, [point.vertex]))[0], before) < 1e-6);

    // "Undo anyway" overwrites B's work on A's vertices.
    await a.click('#undo-force');
    const forced = await nextUndo(a, 2);
    assert.equal(forced.forced, true);
    assert.equal(forced.outcome, OUTCOME.DONE, forced.text);
    await waitFor(a, ([id, p]) => {
      const q = window.__filigree.vertexPosition(id);
      return Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) > 1e-3;
    }, [point.vertex, before]);
    t.diagnostic(`refused: "${refused.text}"; forced: "${forced.text}"`);
    for (const page of [a, b]) await page.context().close();
  });

  it('saves a checkpoint, compares the mesh with it, and restores it', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const a = await editor();
    const b = await editor();
    await setRadius(b, 25);
    const name = `before B ${Date.now()}`;
    await a.fill('#checkpoint-name', name);
    await a.click('#checkpoint-save');
    await waitFor(a, (n) => document.querySelector('#checkpoint-status').textContent === `Saved checkpoint “${n}”.`
      && window.__filigree.checkpoints.some((c) => c.name === n), name);
    const checkpoint = (await hookState(a)).checkpoints.find((c) => c.name === name);
    const item = `#checkpoints li[data-checkpoint="${checkpoint.id}"]`;

    const [, point] = await twoPoints(b);
    const [start] = await positionsOf(a, [point.vertex]);
    await drag(b, point, 50, 40);
    await waitFor(a, ([id, p]) => {
      const q = window.__filigree.vertexPosition(id);
      return Math.hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2]) > 1e-3;
    }, [point.vertex, start]);
    await settled(b);
    await waitFor(a, (v) => window.__filigree.drawnVersion >= v, (await hookState(b)).drawnVersion);
    const moved = distance((await positionsOf(a, [point.vertex]))[0], start);
    const pulled = (await hookState(b)).pulledVertices;

    // Compare: B's pull differs.
    await a.click(`${item} button.compare`);
    await waitFor(a, (s) => /differ/.test(document.querySelector(`${s} .compare-result`).textContent), item);
    const compared = await a.textContent(`${item} .compare-result`);
    const m = /(\d+) base vertices? differs?, max distance ([\d.e+-]+)/.exec(compared);
    assert.ok(m, `the comparison says how much differs: ${compared}`);
    assert.ok(Number(m[1]) > 0 && Number(m[1]) <= pulled, `${m[1]} base vertices differ (B pulled ${pulled})`);
    assert.ok(Number(m[2]) > 0);

    // Restore: B's pull is gone, on both pages; the restore is A's entry.
    await a.click(`${item} button.restore`);
    await waitFor(a, () => /^Restored checkpoint/.test(document.querySelector('#checkpoint-status').textContent));
    for (const page of [a, b]) await positionsNear(page, [[point.vertex, start]], 0.05 * moved);
    await waitFor(a, () => window.__filigree.history.some((e) => e.kind === 'restore' && e.author === window.__filigree.clientName));
    await a.click(`${item} button.compare`);
    await waitFor(a, (s) => /^Now against .*: 0 base vertices differ\.$/.test(document.querySelector(`${s} .compare-result`).textContent), item);
    // B's page lists the checkpoint too.
    await waitFor(b, (n) => [...document.querySelectorAll('#checkpoints li')].some((li) => li.dataset.name === n), name);
    t.diagnostic(`checkpoint "${name}": ${compared}`);
    for (const page of [a, b]) await page.context().close();
  });

  it('shows who is here to a late joiner at once, in their colours with their roles, pointers and touched vertices',
    { timeout: TEST_TIMEOUT_MS }, async (t) => {
      const a = await editor();
      const nameA = (await hookState(a)).clientName;
      const colourA = serverColour(nameA);
      const [pa, pb] = await twoPoints(a);
      await a.mouse.move(pa.x, pa.y);
      await waitFor(a, (v) => window.__filigree.pointerVertex === v, pa.vertex);

      // B joins late: its stream's first message has A, A's colour, role and pointer.
      const b = await editor();
      const first = await hookState(b);
      assert.ok(first.presenceFirst.includes(nameA), `the first message lists A: ${first.presenceFirst}`);
      const seen = first.presence.find((p) => p.name === nameA);
      assert.ok(seen, 'B lists A');
      assert.equal(seen.colour, colourA, 'in A\'s colour');
      assert.equal(seen.role, 'editor');
      assert.equal(await b.evaluate((n) => window.__filigree.participantColour(n), nameA), colourA, 'the page\'s colour is the server\'s');
      const row = await b.evaluate((n) => {
        const li = document.querySelector(`#presence-list li[data-participant="${n}"]`);
        return li && { text: li.textContent, swatch: getComputedStyle(li.querySelector('.swatch')).backgroundColor };
      }, nameA);
      assert.ok(row && row.text.includes(nameA) && row.text.includes('editor'), `B's list shows A: ${row?.text}`);
      const rgb = (hex) => `rgb(${[1, 3, 5].map((k) => parseInt(hex.slice(k, k + 2), 16)).join(', ')})`;
      assert.equal(row.swatch, rgb(colourA));
      assert.ok((await hookState(b)).presence.some((p) => p.you && p.name === (first.clientName)), 'B lists itself');

      // A's pointer on B's page: at the vertex under A's mouse, in A's colour, tagged with A's name.
      await waitFor(b, ([n, v]) => window.__filigree.otherPointers().some((p) => p.name === n && p.vertex === v && p.visible),
        [nameA, pa.vertex]);
      const pointer = (await b.evaluate(() => window.__filigree.otherPointers())).find((p) => p.name === nameA);
      assert.equal(pointer.colour, colourA);
      const where = await b.evaluate((v) => window.__filigree.screenPointOfVertex(v), pa.vertex);
      assert.ok(Math.hypot(pointer.x - where.x, pointer.y - where.y) < 2, 'drawn at that vertex');
      assert.equal(await b.textContent(`.pointer-label[data-pointer="${nameA}"]`), nameA);
      // It moves with A's mouse.
      const calls = (await hookState(a)).pointerCalls;
      const started = Date.now();
      await a.mouse.move(pb.x, pb.y, { steps: 30 });
      await waitFor(b, ([n, v]) => window.__filigree.otherPointers().some((p) => p.name === n && p.vertex === v), [nameA, pb.vertex]);
      const sent = (await hookState(a)).pointerCalls - calls;
      const elapsed = Date.now() - started;
      assert.ok(sent >= 1 && sent <= elapsed / 100 + 2, `SetPresence at most 10 a second: ${sent} calls in ${elapsed} ms for 30 moves`);

      // A pulls: B shows the base vertices A touched as dots in A's colour.
      await setRadius(a, 15);
      await drag(a, pa, 30, -30);
      await waitFor(a, () => window.__filigree.history.some((e) => e.author === window.__filigree.clientName));
      const touched = (await ownEntries(a))[0].vertices;
      await waitFor(b, ([n, count]) => window.__filigree.touchMarkers()[n] === count, [nameA, touched]);
      // Hidden on request (the list stays).
      await b.uncheck('#show-activity');
      assert.ok((await b.evaluate(() => window.__filigree.otherPointers())).every((p) => !p.visible), 'no pointer shown');
      assert.ok(await b.isVisible(`#presence-list li[data-participant="${nameA}"]`));

      // A viewer page is listed as a viewer.
      const viewer = await newPage(session.viewer_token);
      await waitFor(viewer, () => window.__filigree?.state === 'live' && window.__filigree.presenceMessages >= 1);
      const nameV = (await hookState(viewer)).clientName;
      await waitFor(a, (n) => window.__filigree.presence.some((p) => p.name === n && p.role === 'viewer'), nameV);
      assert.equal(await viewer.isVisible('#undo'), false, 'no undo on a viewer page');
      t.diagnostic(`B saw ${nameA} (${colourA}) in its first presence message; pointer at ${pa.vertex} then ${pb.vertex} ` +
        `(${sent} SetPresence calls in ${elapsed} ms); ${touched} touched base vertices dotted`);
      for (const page of [a, b, viewer]) await page.context().close();
    });

  it('asks GetHistory one call at a time, at most 4 a second, while a program drives', { timeout: TEST_TIMEOUT_MS }, async (t) => {
    const a = await editor();
    const before = await hookState(a);
    const started = Date.now();
    await new Promise((done, fail) => {
      execFile(CLI, driveArgs(grpc, session, 'bend', 60, 30, 'history-test-drive'), { timeout: 2 * WAIT_MS },
        (error, _out, stderr) => (error ? fail(new Error(`${error.message}\n${stderr}`)) : done()));
    });
    await waitFor(a, () => window.__filigree.history.some((e) => e.author === 'history-test-drive') && !window.__filigree.historyFetching);
    const elapsed = (Date.now() - started) / 1000;
    const after = await hookState(a);
    const calls = after.historyCalls - before.historyCalls;
    assert.equal(after.historyMostInFlight, 1, 'never two GetHistory calls at once');
    assert.ok(calls >= 1 && calls <= 4 * elapsed + 2, `${calls} GetHistory calls in ${elapsed.toFixed(1)} s`);
    assert.ok(after.framesReceived - before.framesReceived > calls, 'fewer calls than frames');
    t.diagnostic(`${calls} GetHistory calls in ${elapsed.toFixed(1)} s for ${after.framesReceived - before.framesReceived} frames`);
    await a.context().close();
  });
});
