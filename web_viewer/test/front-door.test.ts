// The front door's pure parts: gRPC-Web framing of CreateSession's body and
// of streamed answers, the connect-a-program lines, file formats, session links.
import { fromBinary } from '@bufbuild/protobuf';
import { describe, expect, it } from 'vitest';

import { connectLines, grpcAddress, meshFormat, sessionHref } from '../src/connect';
import { CHUNK_BYTES, requestBody } from '../src/create';
import { CreateSessionRequestSchema } from '../src/gen/filigree/v1/filigree_pb';
import { frame, FrameReader, parseTrailers, TRAILER_FLAG } from '../src/grpc-web';

describe('gRPC-Web frames', () => {
  it('frames a payload with a flag and a big-endian length', () => {
    expect(Array.from(frame(new Uint8Array([7, 8, 9])))).toEqual([0, 0, 0, 0, 3, 7, 8, 9]);
    expect(Array.from(frame(new Uint8Array(300), TRAILER_FLAG).subarray(0, 5))).toEqual([0x80, 0, 0, 1, 44]);
  });

  it('reads frames split anywhere across chunks', () => {
    const stream = new Uint8Array([...frame(new Uint8Array([1, 2])), ...frame(new Uint8Array(0)),
      ...frame(new TextEncoder().encode('grpc-status:0\r\n'), TRAILER_FLAG)]);
    for (let cut = 0; cut <= stream.length; ++cut) {
      const reader = new FrameReader();
      const frames = [...reader.push(stream.subarray(0, cut)), ...reader.push(stream.subarray(cut))];
      expect(frames.map((f) => [f.flag, Array.from(f.payload)])).toEqual([[0, [1, 2]], [0, []],
        [0x80, Array.from(new TextEncoder().encode('grpc-status:0\r\n'))]]);
      expect(reader.pending).toBe(0);
    }
    const cutShort = new FrameReader();
    expect(cutShort.push(stream.subarray(0, 4))).toEqual([]);
    expect(cutShort.pending).toBe(4);
  });

  it('parses trailers, the message percent-decoded', () => {
    expect(parseTrailers('grpc-status:8\r\ngrpc-message:two uploads at once%2C at most\r\n'))
      .toEqual({ status: 8, message: 'two uploads at once, at most' });
    expect(parseTrailers('Grpc-Status: 0\r\n')).toEqual({ status: 0, message: '' });
    expect(parseTrailers('nothing').status).toBe(2);
  });
});

describe('the CreateSession body', () => {
  it('is begin then the file in chunks, each a data frame that parses as a request', async () => {
    const file = new Blob([new Uint8Array(1000).map((_, i) => i % 251)]);
    const body = new Uint8Array(await requestBody(file, 'obj', 'web-test', 300).arrayBuffer());
    const frames = new FrameReader().push(body);
    expect(frames.length).toBe(1 + 4);
    const messages = frames.map((f) => fromBinary(CreateSessionRequestSchema, f.payload));
    expect(messages[0].kind.case).toBe('begin');
    const begin = messages[0].kind.value as { format: string; totalBytes: bigint; clientName: string };
    expect([begin.format, begin.totalBytes, begin.clientName]).toEqual(['obj', 1000n, 'web-test']);
    const bytes = messages.slice(1).map((m) => (m.kind.case === 'chunk' ? Array.from(m.kind.value) : []));
    expect(bytes.map((b) => b.length)).toEqual([300, 300, 300, 100]);
    expect(bytes.flat()).toEqual(Array.from(new Uint8Array(1000).map((_, i) => i % 251)));
  });

  it('sends chunks of 512 KiB by default, whose messages fit a server with --max-message-mib 1', async () => {
    const size = (3 << 20) + 7;
    const frames = new FrameReader().push(new Uint8Array(await requestBody(new Blob([new Uint8Array(size)]), 'ply', 'web').arrayBuffer()));
    expect(CHUNK_BYTES).toBe(512 << 10);
    expect(frames.length).toBe(1 + Math.ceil(size / CHUNK_BYTES));
    for (const f of frames) expect(f.payload.length).toBeLessThan(1 << 20);
  });

  it('frames a chunk over 2 MiB (a multi-byte length varint)', async () => {
    const size = (2 << 20) + 5;
    const body = new Uint8Array(await requestBody(new Blob([new Uint8Array(size)]), 'ply', 'web', 3 << 20).arrayBuffer());
    const frames = new FrameReader().push(body);
    const chunk = fromBinary(CreateSessionRequestSchema, frames[1].payload);
    expect(chunk.kind.case === 'chunk' && chunk.kind.value.length).toBe(size);
  });
});

describe('connecting a program', () => {
  const server = { grpc_host: '127.0.0.1', grpc_port: 50051, tls: false, api_keys: false };

  it('names the gRPC port, the page\'s host when the server gives none', () => {
    expect(grpcAddress(server, 'example.org')).toBe('127.0.0.1:50051');
    expect(grpcAddress({ ...server, grpc_host: '' }, 'example.org')).toBe('example.org:50051');
    expect(grpcAddress({ ...server, grpc_host: '0.0.0.0' }, 'example.org')).toBe('example.org:50051');
    expect(grpcAddress({ ...server, grpc_host: '::1' }, 'x')).toBe('[::1]:50051');
  });

  it('passes tokens in FILIGREE_TOKEN, never as an argument; an API key where the server needs one', () => {
    const lines = connectLines(server, 'h', { id: 'abc', editorToken: 'tok' });
    expect(lines.drive).toBe('FILIGREE_TOKEN=tok filigree drive --server 127.0.0.1:50051 --session abc --motion bend');
    expect(lines.python).toContain('client.join("abc", os.environ["FILIGREE_TOKEN"])');
    expect(lines.python).not.toContain('tok');
    expect(lines.upload).toBe('filigree upload MESH.obj --server 127.0.0.1:50051');
    expect(connectLines({ ...server, api_keys: true }, 'h').upload).toMatch(/^FILIGREE_API_KEY=\S+ filigree upload/);
  });

  it('knows the mesh formats by extension', () => {
    expect(['a.OBJ', 'b.ply', 'c.off', 'd.gltf', 'e.glb', 'f.stl', 'obj'].map(meshFormat))
      .toEqual(['obj', 'ply', 'off', 'gltf', 'glb', '', '']);
  });

  it('puts tokens in the fragment, not the query', () => {
    const href = sessionHref('http://h:8080/?x=1#y', 'sid', 'edit', 'view');
    const url = new URL(href);
    expect(url.search).toBe('?session=sid');
    expect(url.hash).toBe('#token=edit&viewer=view');
  });
});
