// Gesture ids: every call of one drag (a pull's SubmitPose calls, a handle
// drag's SetHandles calls) carries the same id, so that the server records
// the drag as one history entry and one undo takes all of it back. A fresh
// id per drag (random, never 0: 0 means "no gesture"), so that two drags in
// quick succession stay two entries.
export function newGestureId(random: (bytes: Uint8Array) => Uint8Array = (b) => crypto.getRandomValues(b)): bigint {
  for (;;) {
    const bytes = random(new Uint8Array(8));
    let id = 0n;
    for (const b of bytes) id = (id << 8n) | BigInt(b);
    if (id !== 0n) return id;
  }
}
