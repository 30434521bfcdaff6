// gRPC-Web framing by hand, for the one call connect-web cannot make:
// CreateSession streams its requests, which gRPC-Web (over fetch) cannot do,
// so the page POSTs one body holding every request message back to back and
// reads the streamed answer itself. A frame is 1 flag byte (0x00 data, 0x80
// trailers), a 4-byte big-endian length and that many bytes.
export const TRAILER_FLAG = 0x80;

// The 5-byte header of a data frame of `length` bytes.
export function frameHeader(length: number, flag = 0): Uint8Array {
  const header = new Uint8Array(5);
  header[0] = flag;
  new DataView(header.buffer).setUint32(1, length, false);
  return header;
}

// One whole frame (header + payload).
export function frame(payload: Uint8Array, flag = 0): Uint8Array {
  const out = new Uint8Array(5 + payload.length);
  out.set(frameHeader(payload.length, flag), 0);
  out.set(payload, 5);
  return out;
}

export interface Trailers { status: number; message: string }

// Reads `grpc-status` and `grpc-message` (percent-encoded) from a trailer
// frame's text: HTTP/1-style header lines.
export function parseTrailers(text: string): Trailers {
  let status = NaN;
  let message = '';
  for (const line of text.split(/\r?\n/)) {
    const colon = line.indexOf(':');
    if (colon < 0) continue;
    const name = line.slice(0, colon).trim().toLowerCase();
    const value = line.slice(colon + 1).trim();
    if (name === 'grpc-status') status = Number(value);
    else if (name === 'grpc-message') {
      try {
        message = decodeURIComponent(value);
      } catch {
        message = value;
      }
    }
  }
  return { status: Number.isInteger(status) ? status : 2 /* UNKNOWN */, message };
}

// Splits a response body arriving in pieces of any size into frames.
export class FrameReader {
  private buffer = new Uint8Array(0);

  // The whole frames completed by `chunk`, in order.
  push(chunk: Uint8Array): { flag: number; payload: Uint8Array }[] {
    const joined = new Uint8Array(this.buffer.length + chunk.length);
    joined.set(this.buffer, 0);
    joined.set(chunk, this.buffer.length);
    const frames: { flag: number; payload: Uint8Array }[] = [];
    let at = 0;
    while (joined.length - at >= 5) {
      const length = new DataView(joined.buffer, joined.byteOffset + at + 1, 4).getUint32(0, false);
      if (joined.length - at - 5 < length) break;
      frames.push({ flag: joined[at], payload: joined.slice(at + 5, at + 5 + length) });
      at += 5 + length;
    }
    this.buffer = joined.slice(at);
    return frames;
  }

  // Bytes of an unfinished frame (a body that ends with some is cut short).
  get pending(): number {
    return this.buffer.length;
  }
}
