// The page address: /?session=ID&token=T[&server=http://host:port].
export interface ViewerParams {
  sessionId: string;
  token: string;
  serverUrl: string;  // the gRPC-Web endpoint, no trailing slash
}

export type ParamsResult =
  | { kind: 'ok'; params: ViewerParams }
  | { kind: 'usage' }                    // no session named: show how to use the page
  | { kind: 'error'; message: string };

// `origin` is the default server: the viewer is normally served by the
// filigree-server it watches (--web-root).
export function readParams(search: string, origin: string): ParamsResult {
  const query = new URLSearchParams(search);
  const sessionId = query.get('session')?.trim() ?? '';
  if (sessionId === '') return { kind: 'usage' };
  const token = query.get('token')?.trim() ?? '';
  if (token === '') {
    return { kind: 'error', message: `No token for session ${sessionId}: add &token=… (its viewer or editor token) to the address.` };
  }
  const server = query.get('server')?.trim() || origin;
  let url: URL;
  try {
    url = new URL(server);
  } catch {
    return { kind: 'error', message: `server=${server} is not a URL (expected http://host:port).` };
  }
  if (url.protocol !== 'http:' && url.protocol !== 'https:') {
    return { kind: 'error', message: `server=${server} must be an http:// or https:// address.` };
  }
  return { kind: 'ok', params: { sessionId, token, serverUrl: url.href.replace(/\/+$/, '') } };
}
