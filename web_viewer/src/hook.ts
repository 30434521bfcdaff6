// window.__filigree: what the page is doing, for the browser tests
// (test/browser.test.mjs) and for a person at the console. After each applied
// frame the page dispatches FRAME_EVENT on window, so a test can look at a
// given frame (capture()) before the next one replaces it.
export const FRAME_EVENT = 'filigree:frame';

export interface TestHook {
  state: 'starting' | 'usage' | 'joining' | 'live' | 'reconnecting' | 'closed' | 'error';
  error: string | null;     // the last error shown in the page
  sessionId: string | null;
  vertexCount: number;
  baseVertexCount: number;
  version: number;          // of the last applied frame
  framesReceived: number;
  framesApplied: number;
  framesSkipped: number;    // superseded by a newer frame before they were decoded
  framesRendered: number;
  roundTripMs: number | null;
  displacement: number;     // largest |delta| coordinate of the last applied frame (its quantization range)
  capture(): string | null; // the canvas as a PNG data URL, null before the mesh exists
}

declare global {
  interface Window { __filigree: TestHook }
}

export const hook: TestHook = window.__filigree = {
  state: 'starting', error: null, sessionId: null, vertexCount: 0, baseVertexCount: 0, version: 0,
  framesReceived: 0, framesApplied: 0, framesSkipped: 0, framesRendered: 0, roundTripMs: null,
  displacement: 0, capture: () => null,
};
