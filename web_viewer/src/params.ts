// The page address: /?session=ID#token=T[&server=http://host:port]. The
// token belongs in the fragment (after #): browsers never send it to a
// server, so it stays out of access logs and other sites' Referer. Every
// parameter may be in the query or the fragment; the fragment's wins.
export interface ViewerParams {
  sessionId: string;
  token: string;
  serverUrl: string;  // the gRPC-Web endpoint, no trailing slash
  detail?: string;    // detail=: the level of detail asked for (detail.ts, parseDetail)
}

export type ParamsResult =
  | { kind: 'ok'; params: ViewerParams }
  | { kind: 'usage' }                    // no session named: show how to use the page
  | { kind: 'error'; message: string };

// `origin` is the default server: the viewer is normally served by the
// filigree-server it watches (--web-root).
export function readParams(search: string, origin: string, hash = ''): ParamsResult {
  const query = new URLSearchParams(search);
  const fragment = new URLSearchParams(hash.replace(/^#/, ''));
  const get = (name: string) => fragment.get(name)?.trim() || query.get(name)?.trim() || '';
  const sessionId = get('session');
  if (sessionId === '') return { kind: 'usage' };
  const token = get('token');
  if (token === '') {
    return { kind: 'error', message: `No token for session ${sessionId}: add #token=… (its viewer or editor token) to the address.` };
  }
  const server = get('server') || origin;
  let url: URL;
  try {
    url = new URL(server);
  } catch {
    return { kind: 'error', message: `server=${server} is not a URL (expected http://host:port).` };
  }
  if (url.protocol !== 'http:' && url.protocol !== 'https:') {
    return { kind: 'error', message: `server=${server} must be an http:// or https:// address.` };
  }
  const detail = get('detail') || undefined;
  return { kind: 'ok', params: { sessionId, token, serverUrl: url.href.replace(/\/+$/, ''), ...(detail ? { detail } : {}) } };
}

// The address with the token moved from the query into the fragment (for
// history.replaceState), or null when the query holds no token.
export function tokenOutOfQuery(href: string): string | null {
  const url = new URL(href);
  const token = url.searchParams.get('token');
  if (token === null) return null;
  url.searchParams.delete('token');
  const fragment = new URLSearchParams(url.hash.replace(/^#/, ''));
  if (!fragment.has('token')) fragment.set('token', token);
  url.hash = fragment.toString();
  return url.href;
}
