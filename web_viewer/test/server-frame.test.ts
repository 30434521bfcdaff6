// A frame encoded by filigree-server itself (Draco 1.5.5, C++), decoded by
// this viewer's path (draco3d's WebAssembly decoder): the captured fixture
// of test/fixtures/capture-frame.ts, checked vertex by vertex.
import { readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

import draco3d from 'draco3d';
import { expect, it } from 'vitest';

import { decodeDeltas, type DracoDecoderModule } from '../src/frame';

const fixtures = join(dirname(fileURLToPath(import.meta.url)), 'fixtures');
const meta = JSON.parse(readFileSync(join(fixtures, 'bunny_small_rotated.json'), 'utf8'));
const bytes = new Uint8Array(readFileSync(join(fixtures, 'bunny_small_rotated.frame.bin')));
const expectedBytes = readFileSync(join(fixtures, 'bunny_small_rotated.expected.f32'));
const expected = new Float32Array(expectedBytes.buffer.slice(expectedBytes.byteOffset, expectedBytes.byteOffset + expectedBytes.byteLength));

it('decodes a server frame of a rotated bunny into that rotation, vertex by vertex', async () => {
  const draco = (await draco3d.createDecoderModule({})) as DracoDecoderModule;
  expect(bytes.length).toBe(meta.bytes);
  expect(expected.length).toBe(3 * meta.vertexCount);

  const deltas = decodeDeltas(draco, bytes, meta.vertexCount);
  // The frame's own bound (max_error), plus the deformer's rigid-motion
  // tolerance and float32 rounding of the expected deltas.
  const tolerance = meta.maxError + 1e-5;
  let worst = 0;
  let worstVertex = -1;
  for (let i = 0; i < deltas.length; ++i) {
    const error = Math.abs(deltas[i] - expected[i]);
    if (error > worst) [worst, worstVertex] = [error, Math.floor(i / 3)];
  }
  expect(worst, `vertex ${worstVertex} is off by ${worst}`).toBeLessThanOrEqual(tolerance);
  // A rotation moves vertices by different amounts: the check above would
  // fail for a decoder that reordered points.
  expect(Math.max(...expected) - Math.min(...expected)).toBeGreaterThan(100 * tolerance);
});
