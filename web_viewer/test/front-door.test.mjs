// The front door in Chromium against a real filigree-server: the root page
// lists sessions, creates one from a file chosen in the page (progress while
// sending and preprocessing), lands in it live as its editor with share
// links, the viewer link opening the same session without editor controls in
// a second context; the demo button; and a server with --api-keys listing
// nothing without a key and the key's own sessions with it.
//
// Environment: FILIGREE_SERVER (required), FILIGREE_CLI, CHROMIUM (harness.mjs).
// Needs the build (dist/). No sleeps: every wait is on a condition, with a timeout.

import { after, before, describe, it } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { chromium } from 'playwright-core';

import {
  checkTools, CHROMIUM, CHROMIUM_ARGS, CLI, cli, fields, hookState, openPage, ROOT, startServer, stopServerCleanly, waitShowing,
} from './harness.mjs';

const MESH = join(ROOT, 'tests', 'data', 'head_open.off');
const HOOK_TIMEOUT_MS = 60_000;
const TEST_TIMEOUT_MS = 120_000;
const WAIT_MS = 60_000;  // uploads preprocess on a busy machine
const STOP_TIMEOUT_MS = 20_000;

let browser;
const pageErrors = [];

const newPage = (url) => openPage(browser, url, pageErrors, { width: 1100, height: 700 });

const waitFor = (page, fn, arg, timeout = WAIT_MS) => waitShowing(page, fn, arg, timeout);

// Live, a frame drawn.
const live = (page) => waitFor(page, () => window.__filigree?.state === 'live' && window.__filigree.framesApplied >= 1 && window.__filigree.framesRendered >= 1
  && window.__filigree.canEdit !== null);

before(async () => {
  assert.ok(process.env.FILIGREE_SERVER, 'set FILIGREE_SERVER to the filigree-server binary');
  checkTools();
  browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
}, { timeout: HOOK_TIMEOUT_MS });

after(async () => {
  await browser?.close();
  assert.deepEqual(pageErrors, [], 'no uncaught errors in any page');
});

// A server for one describe(): started before, stopped (SIGTERM, exit 0) after.
function withServer(extraArgs = () => []) {
  const state = {};
  before(async () => {
    state.dataDir = mkdtempSync(join(tmpdir(), 'filigree-front-door-'));
    state.server = startServer(state.dataDir, extraArgs(state.dataDir));
    const addresses = await state.server.addresses;
    state.grpc = addresses.grpc;
    state.baseUrl = `http://${addresses.http}`;
  }, { timeout: HOOK_TIMEOUT_MS });
  after(async () => {
    if (state.server) {
      await stopServerCleanly(state.server, STOP_TIMEOUT_MS);
    }
    if (state.dataDir) for (const path of [state.dataDir, `${state.dataDir}-keys`]) rmSync(path, { recursive: true, force: true });
  }, { timeout: HOOK_TIMEOUT_MS });
  return state;
}

describe('the front door (no API keys)', { timeout: 4 * TEST_TIMEOUT_MS }, () => {
  const s = withServer();

  it('creates a session from a chosen file, lands in it as editor, shares a viewer link', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await newPage(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.state === 'usage' && window.__filigree.frontState === 'listed');
    assert.ok(await page.isVisible('#create'), 'the create box is shown');
    assert.ok(await page.isVisible('#demo'), 'the demo button is shown');
    assert.equal(await page.isVisible('#api-key'), false, 'no API key asked for on a server without keys');
    // The connect box: the gRPC port (not the page's), the token in FILIGREE_TOKEN.
    assert.equal(await page.textContent('#grpc-address'), s.grpc);
    const cliText = await page.textContent('#connect-cli');
    assert.match(cliText, new RegExp(`FILIGREE_TOKEN=\\S+ filigree drive --server ${s.grpc} --session \\S+ --motion bend`));
    assert.doesNotMatch(cliText, /--token /);
    assert.match(await page.textContent('#connect-python'), new RegExp(`filigree\\.Client\\("${s.grpc}"\\)`));

    await page.setInputFiles('#mesh-file', MESH);
    // Progress: the bytes being sent, then at least one of the server's stages; then live, in place.
    await live(page);
    const state = await hookState(page);
    assert.equal(state.createStages[0], 'sending', `stages: ${state.createStages}`);
    assert.ok(state.createStages.some((stage) => ['validating', 'simplifying', 'starting'].includes(stage)),
      `a server stage was shown: ${state.createStages}`);
    assert.equal(state.canEdit, true, 'the creator is the editor');
    assert.ok(state.vertexCount > 0);
    assert.ok(await page.isVisible('#edit-mode'), 'editor controls shown');
    const url = new URL(page.url());
    assert.equal(url.searchParams.get('session'), state.sessionId);
    assert.equal(url.searchParams.get('token'), null, 'no token in the query');
    assert.match(url.hash, /token=/, 'the token is in the fragment');

    // Share links: tokens in the fragment; the viewer link opens the same session read-only.
    const viewerLink = await page.inputValue('#share-viewer');
    const editorLink = await page.inputValue('#share-editor');
    for (const link of [viewerLink, editorLink]) {
      const u = new URL(link);
      assert.equal(u.searchParams.get('session'), state.sessionId);
      assert.equal(u.searchParams.get('token'), null);
      assert.match(u.hash, /token=\w+/);
    }
    assert.notEqual(new URLSearchParams(new URL(viewerLink).hash.slice(1)).get('token'),
      new URLSearchParams(new URL(editorLink).hash.slice(1)).get('token'), 'the viewer link has another token');
    assert.match(await page.textContent('#session-connect-cli'), new RegExp(`--session ${state.sessionId}`));

    const viewer = await newPage(viewerLink);
    await live(viewer);
    const seen = await hookState(viewer);
    assert.equal(seen.sessionId, state.sessionId);
    assert.equal(seen.canEdit, false, 'the viewer link is a viewer');
    assert.equal(seen.vertexCount, state.vertexCount);
    assert.equal(await viewer.isVisible('#edit-mode'), false, 'no editor controls for the viewer');
    assert.equal(await viewer.isVisible('#share-editor'), false, 'no editor link for the viewer');
    assert.equal(await viewer.isVisible('#share-viewer'), true);

    // The new session is listed on the front door; this browser made it, so its link opens as editor.
    const front = await page.context().newPage();
    await front.goto(`${s.baseUrl}/`);
    await waitFor(front, (id) => window.__filigree?.sessionsListed?.includes(id), state.sessionId);
    const href = await front.getAttribute(`#sessions li[data-session="${state.sessionId}"] a`, 'href');
    assert.match(href, /#token=/);
    await Promise.all([page.context().close(), viewer.context().close()]);
  });

  it('opens the demo with one click', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await newPage(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed');
    await page.click('#demo');
    await live(page);
    const state = await hookState(page);
    assert.equal(state.canEdit, true);
    assert.equal(state.vertexCount > 1000, true, `the bunny (${state.vertexCount} vertices)`);
    assert.ok(await page.isVisible('#share-viewer'));
    await page.context().close();
  });

  it('says what is wrong with a file it cannot upload', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await newPage(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed');
    const bad = join(mkdtempSync(join(tmpdir(), 'filigree-bad-')), 'broken.obj');
    writeFileSync(bad, 'this is not a mesh\n');
    await page.setInputFiles('#mesh-file', bad);
    await waitFor(page, () => window.__filigree.frontState === 'error');
    assert.match(await page.textContent('#create-status'), /Could not create the session: .+/);
    assert.equal(await page.evaluate(() => window.__filigree.state), 'usage', 'still on the front door');
    await page.context().close();
  });
});

// `filigree api-key NAME`: { key, line } (the line goes into the --api-keys file).
async function makeKey(name) {
  const out = fields(await cli(['api-key', name]));
  assert.ok(out.key && out.line, 'filigree api-key printed a key and a line');
  return out;
}

function uploadWithKey(grpc, key, name) {
  return new Promise((done, fail) => {
    execFile(CLI, ['upload', MESH, '--server', grpc, '--name', name], { timeout: 60_000, env: { ...process.env, FILIGREE_API_KEY: key } },
      (error, stdout, stderr) => (error ? fail(new Error(`${error.message}\n${stderr}`)) : done(fields(stdout))));
  });
}

describe('the front door on a server with --api-keys', { timeout: 3 * TEST_TIMEOUT_MS }, () => {
  let keys;
  before(async () => {
    keys = { alice: await makeKey('alice'), bob: await makeKey('bob') };
  }, { timeout: HOOK_TIMEOUT_MS });
  // The keys file beside the data directory (the file keeps only the keys' hashes).
  const s = withServer((dataDir) => {
    const file = `${dataDir}-keys`;
    writeFileSync(file, `# name sha256 quotas\n${keys.alice.line}\n${keys.bob.line}\n`);
    return ['--api-keys', file];
  });

  it('lists nothing without a key, and the key\'s own sessions with it', { timeout: TEST_TIMEOUT_MS }, async () => {
    const mine = await uploadWithKey(s.grpc, keys.alice.key, 'alice-mesh');
    const theirs = await uploadWithKey(s.grpc, keys.bob.key, 'bob-mesh');
    assert.ok(mine.session_id && theirs.session_id);

    const page = await newPage(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'needs-key');
    assert.equal(await page.evaluate(() => window.__filigree.apiKeysNeeded), true);
    assert.deepEqual(await page.evaluate(() => window.__filigree.sessionsListed), []);
    assert.equal(await page.locator('#sessions li').count(), 0, 'nothing listed without a key');
    assert.ok(await page.isVisible('#api-key'), 'the page asks for a key');
    assert.match(await page.textContent('#connect-cli'), /FILIGREE_API_KEY=\S+ filigree upload/);

    await page.fill('#api-key', keys.alice.key);
    await page.click('#api-key-form button[type=submit]');
    await waitFor(page, () => window.__filigree.frontState === 'listed');
    assert.deepEqual(await page.evaluate(() => window.__filigree.sessionsListed), [mine.session_id], 'only the key\'s own sessions');
    assert.equal(await page.locator(`#sessions li[data-session="${theirs.session_id}"]`).count(), 0);
    // The key stays for this tab (sessionStorage): a reload lists again without asking.
    await page.reload();
    await waitFor(page, (id) => window.__filigree?.frontState === 'listed' && window.__filigree.sessionsListed.includes(id),
      mine.session_id);

    // The listed session opens by its link; made elsewhere, it asks for a token (none in the link).
    await page.click(`#sessions li[data-session="${mine.session_id}"] a`);
    await waitFor(page, () => window.__filigree?.state === 'error' && !document.querySelector('#token-form').hidden);
    assert.equal(new URL(page.url()).searchParams.get('session'), mine.session_id);
    await page.fill('#token-input', mine.viewer_token);
    await page.click('#token-form button[type=submit]');
    await live(page);
    assert.equal(await page.evaluate(() => window.__filigree.sessionId), mine.session_id);
    assert.equal(await page.evaluate(() => window.__filigree.canEdit), false, 'opened with the viewer token');
    assert.equal(await page.isVisible('#token-form'), false);
    await page.goto(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'listed');

    // A wrong key: refused, nothing listed.
    await page.fill('#api-key', 'fgk_not_a_key');
    await page.click('#api-key-form button[type=submit]');
    await waitFor(page, () => window.__filigree.frontState === 'error');
    assert.deepEqual(await page.evaluate(() => window.__filigree.sessionsListed), []);
    await page.context().close();
  });

  it('creates a session with the key', { timeout: TEST_TIMEOUT_MS }, async () => {
    const page = await newPage(`${s.baseUrl}/`);
    await waitFor(page, () => window.__filigree?.frontState === 'needs-key');
    await page.click('#demo');
    await waitFor(page, () => /needs an API key/.test(document.querySelector('#create-status').textContent));
    await page.fill('#api-key', keys.bob.key);
    await page.click('#api-key-form button[type=submit]');
    await waitFor(page, () => window.__filigree.frontState === 'listed');
    await page.click('#demo');
    await live(page);
    const id = await page.evaluate(() => window.__filigree.sessionId);
    // Back on the front door (same tab: the key is kept), the new session is listed for bob's key.
    await page.goto(`${s.baseUrl}/`);
    await waitFor(page, (sid) => window.__filigree?.frontState === 'listed' && window.__filigree.sessionsListed.includes(sid), id);
    await page.context().close();
  });
});
