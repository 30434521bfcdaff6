// What the pages show about reaching this server from a program: the gRPC
// address (from /server.json) and copy-paste lines for the CLI and Python.
// Tokens travel in FILIGREE_TOKEN (or --token-file), never as an argument.
export interface ServerJson { grpc_host: string; grpc_port: number; tls: boolean; api_keys: boolean }

// HOST:PORT of the gRPC port; an empty grpc_host means the page's own host.
export function grpcAddress(server: ServerJson, pageHost: string): string {
  const host = server.grpc_host && server.grpc_host !== '0.0.0.0' && server.grpc_host !== '::' ? server.grpc_host : pageHost;
  return `${host.includes(':') && !host.startsWith('[') ? `[${host}]` : host}:${server.grpc_port}`;
}

export interface ConnectLines { address: string; upload: string; drive: string; python: string }

// `session`: a session's id and, when the page holds it, its editor token.
export function connectLines(server: ServerJson, pageHost: string, session?: { id: string; editorToken?: string }): ConnectLines {
  const address = grpcAddress(server, pageHost);
  const id = session?.id ?? 'SESSION_ID';
  const token = session?.editorToken ?? 'EDITOR_TOKEN';
  const key = server.api_keys ? 'FILIGREE_API_KEY=YOUR_KEY ' : '';
  return {
    address,
    upload: `${key}filigree upload MESH.obj --server ${address}`,
    drive: `FILIGREE_TOKEN=${token} filigree drive --server ${address} --session ${id} --motion bend`,
    python: [
      'import os, filigree',
      '',
      `with filigree.Client("${address}") as client:`,
      `    session = client.join("${id}", os.environ["FILIGREE_TOKEN"])`,
      '    with session.drive("python") as driver:',
      '        pose = session.base_positions.copy()  # (m, 3) float32',
      '        pose[:, 1] += 0.05 * (pose[:, 1] - pose[:, 1].min())',
      '        driver.wait_for_pose(driver.send(pose))',
    ].join('\n'),
  };
}

// The upload format of a file name ('' when not one the server reads).
export function meshFormat(name: string): string {
  const m = /\.(obj|ply|off|gltf|glb)$/i.exec(name);
  return m ? m[1].toLowerCase() : '';
}

// The address of a session on this page: the token in the fragment (never
// sent to a server), the viewer token too for an editor's page (its share links).
export function sessionHref(base: string, id: string, token: string, viewerToken?: string): string {
  const url = new URL(base);
  url.search = new URLSearchParams({ session: id }).toString();
  const fragment = new URLSearchParams({ token });
  if (viewerToken) fragment.set('viewer', viewerToken);
  url.hash = fragment.toString();
  return url.href;
}
