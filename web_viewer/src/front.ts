// The front door: the page with no session in its address. Lists the
// sessions the visitor may see, creates one from a dropped or chosen mesh
// (or the bundled demo), and says how a program connects.
import { describeError } from './client';
import { connectLines, meshFormat, sessionHref, type ServerJson } from './connect';
import { createSession, listSessions, type Created, type Progress } from './create';
import { hook } from './hook';
import { byId } from './panel';

const KEY_STORAGE = 'filigree.apiKey';        // sessionStorage: gone with the tab
const TOKENS_STORAGE = 'filigree.sessions';   // localStorage: the sessions made in this browser, with their tokens
const DEMO_URL = 'demo/bunny.obj';

interface Remembered { editorToken: string; viewerToken: string; name: string; created: number }

function remembered(): Record<string, Remembered> {
  try {
    return JSON.parse(window.localStorage.getItem(TOKENS_STORAGE) ?? '{}') as Record<string, Remembered>;
  } catch {
    return {};
  }
}

function remember(created: Created, name: string): void {
  const all = remembered();
  all[created.sessionId] = { editorToken: created.editorToken, viewerToken: created.viewerToken, name, created: Date.now() };
  try {
    window.localStorage.setItem(TOKENS_STORAGE, JSON.stringify(all));
  } catch {
    // storage full or refused: the session still opens, it is only not remembered
  }
}

// The tokens this browser keeps for a session (it made it), if any.
export function rememberedTokens(sessionId: string): Remembered | undefined {
  return remembered()[sessionId];
}

export async function serverJson(serverUrl: string): Promise<ServerJson | null> {
  try {
    const response = await fetch(`${serverUrl}/server.json`);
    if (!response.ok) return null;
    return await response.json() as ServerJson;
  } catch {
    return null;
  }
}

const megabytes = (bytes: number) => `${(bytes / 1e6).toFixed(bytes < 1e6 ? 2 : 1)} MB`;

const STAGES: Record<string, string> = {
  validating: 'Reading and checking the mesh',
  simplifying: 'Building the base mesh and the hierarchy',
  starting: 'Starting the session',
};

export class FrontDoor {
  private server: ServerJson | null = null;
  private apiKey = window.sessionStorage.getItem(KEY_STORAGE) ?? '';
  private busy = false;

  // `open`: lands in a session made here (as its editor), without reloading.
  constructor(private readonly serverUrl: string, private readonly open: (href: string) => void) {}

  async start(): Promise<void> {
    document.body.classList.add('front');
    byId('front').hidden = false;
    byId('usage').hidden = false;
    this.setupCreate();
    this.setupKey();
    this.server = await serverJson(this.serverUrl);
    hook.apiKeysNeeded = this.server?.api_keys ?? false;
    this.showConnect();
    byId('api-key-form').hidden = !this.server?.api_keys;
    await this.refresh();
  }

  private showConnect(): void {
    if (this.server === null) {
      byId('grpc-address').textContent = 'unknown (this server does not say: no /server.json)';
      return;
    }
    const lines = connectLines(this.server, window.location.hostname);
    byId('grpc-address').textContent = lines.address + (this.server.tls ? ' (TLS)' : '');
    byId('connect-cli').textContent = `# a new session (prints its id and tokens)\n${lines.upload}\n` +
      `# move it\n${lines.drive}`;
    byId('connect-python').textContent = `# Python (client/python)\n${lines.python}`;
  }

  private setupKey(): void {
    const input = byId<HTMLInputElement>('api-key');
    input.value = this.apiKey;
    byId('api-key-forget').hidden = this.apiKey === '';
    byId<HTMLFormElement>('api-key-form').addEventListener('submit', (event) => {
      event.preventDefault();
      this.apiKey = input.value.trim();
      window.sessionStorage.setItem(KEY_STORAGE, this.apiKey);
      byId('api-key-forget').hidden = false;
      void this.refresh();
    });
    byId('api-key-forget').addEventListener('click', () => {
      this.apiKey = '';
      input.value = '';
      window.sessionStorage.removeItem(KEY_STORAGE);
      byId('api-key-forget').hidden = true;
      void this.refresh();
    });
  }

  // The session list: ListSessions (a key's own sessions on a server with keys; none without one).
  async refresh(): Promise<void> {
    const list = byId('sessions');
    const status = byId('sessions-status');
    if (this.server?.api_keys && this.apiKey === '') {
      list.replaceChildren();
      hook.sessionsListed = [];
      status.textContent = 'This server needs an API key to list or create sessions: enter yours above. ' +
        'A session\'s own link (with its token) opens without one.';
      hook.frontState = 'needs-key';
      return;
    }
    status.textContent = 'Loading…';
    try {
      const sessions = await listSessions(this.serverUrl, this.apiKey);
      const mine = remembered();
      list.replaceChildren(...sessions.map((s) => {
        const item = document.createElement('li');
        item.dataset.session = s.sessionId;
        const tokens = mine[s.sessionId];
        const link = document.createElement('a');
        link.href = tokens ? sessionHref(window.location.href, s.sessionId, tokens.editorToken, tokens.viewerToken)
          : sessionHref(window.location.href, s.sessionId, '').replace(/#.*$/, '');
        link.textContent = tokens?.name ? `${tokens.name} · ${s.sessionId}` : s.sessionId;
        const who = `${s.watchers} watching${s.drivers ? `, ${s.drivers} driving` : ''}`;
        const detail = document.createElement('span');
        detail.className = 'note';
        detail.textContent = `${s.vertexCount.toLocaleString('en')} vertices · version ${s.version} · ${who}` +
          (tokens ? ' · made in this browser: opens as editor' : ' · opens with its token');
        item.append(link, detail);
        return item;
      }));
      hook.sessionsListed = sessions.map((s) => s.sessionId);
      hook.frontState = 'listed';
      status.textContent = sessions.length === 0 ? 'No sessions yet: create one.'
        : `${sessions.length} session${sessions.length === 1 ? '' : 's'}${this.apiKey ? ' of this key' : ''}.`;
    } catch (error) {
      list.replaceChildren();
      hook.sessionsListed = [];
      hook.frontState = 'error';
      status.textContent = describeError(error, '', this.serverUrl).replace(/^UNAUTHENTICATED: /, '');
      status.classList.add('bad');
    }
  }

  private setupCreate(): void {
    const input = byId<HTMLInputElement>('mesh-file');
    input.addEventListener('change', () => {
      const file = input.files?.[0];
      if (file) void this.create(file, file.name);
      input.value = '';
    });
    const drop = byId('drop');
    drop.addEventListener('dragover', (event) => {
      event.preventDefault();
      drop.classList.add('over');
    });
    drop.addEventListener('dragleave', () => drop.classList.remove('over'));
    drop.addEventListener('drop', (event) => {
      event.preventDefault();
      drop.classList.remove('over');
      const file = event.dataTransfer?.files[0];
      if (file) void this.create(file, file.name);
    });
    byId('demo').addEventListener('click', async () => {
      if (this.busy) return;
      try {
        const response = await fetch(DEMO_URL);
        if (!response.ok) throw new Error(`the demo mesh is missing (${DEMO_URL}: HTTP ${response.status})`);
        await this.create(await response.blob(), 'bunny.obj', 'demo');
      } catch (error) {
        this.failed(error);
      }
    });
  }

  private async create(file: Blob, name: string, label = name): Promise<void> {
    if (this.busy) return;
    const format = meshFormat(name);
    const status = byId('create-status');
    status.classList.remove('bad');
    if (format === '') {
      status.textContent = `${name}: not a mesh format the server reads (OBJ, PLY, OFF, glTF, GLB).`;
      status.classList.add('bad');
      return;
    }
    if (this.server?.api_keys && this.apiKey === '') {
      status.textContent = 'This server needs an API key to create a session: enter it under Sessions.';
      status.classList.add('bad');
      return;
    }
    this.busy = true;
    hook.createStages = [];
    hook.frontState = 'creating';
    status.textContent = '';
    byId('create-progress').hidden = false;
    for (const id of ['demo', 'mesh-file']) byId<HTMLButtonElement | HTMLInputElement>(id).disabled = true;
    try {
      const created = await createSession(this.serverUrl, file, format, {
        apiKey: this.apiKey, clientName: 'web', onProgress: (p) => this.progress(p, name),
      });
      remember(created, label);
      hook.frontState = 'created';
      this.open(sessionHref(window.location.href, created.sessionId, created.editorToken, created.viewerToken));
    } catch (error) {
      this.failed(error);
    } finally {
      this.busy = false;
      for (const id of ['demo', 'mesh-file']) byId<HTMLButtonElement | HTMLInputElement>(id).disabled = false;
    }
  }

  private progress(progress: Progress, name: string): void {
    const text = byId('create-text');
    const bar = byId<HTMLProgressElement>('create-bar');
    if (!hook.createStages.includes(progress.stage)) hook.createStages.push(progress.stage);
    if ('bytes' in progress) {
      text.textContent = `Sending ${name} (${megabytes(progress.bytes)})…`;
      bar.removeAttribute('value');
    } else {
      const left = progress.secondsLeft > 0 ? `, about ${Math.max(1, Math.round(progress.secondsLeft))} s left` : '';
      text.textContent = `${STAGES[progress.stage] ?? progress.stage}… ${Math.round(100 * progress.fraction)} %${left}`;
      bar.max = 1;
      bar.value = progress.fraction;
    }
  }

  private failed(error: unknown): void {
    hook.frontState = 'error';
    byId('create-progress').hidden = true;
    const status = byId('create-status');
    status.textContent = `Could not create the session: ${describeError(error, '', this.serverUrl)}`;
    status.classList.add('bad');
  }
}
