// The frames waiting to be shown by a page slower than its stream. The newest
// frame replaces the one waiting (a mailbox of one, like the server's), so a
// slow page skips frames instead of falling behind; but a keyframe waits
// until it is taken, however many frames follow it: the frames after it are
// relative to it, and the stream does not send it again.
export class FrameMailbox<F> {
  private keyframe: F | null = null;
  private frame: F | null = null;
  private readonly isKeyframe: (frame: F) => boolean;

  constructor(isKeyframe: (frame: F) => boolean) {
    this.isKeyframe = isKeyframe;
  }

  // Returns how many waiting frames the new one superseded: a keyframe
  // supersedes everything older, any other frame the other frame waiting.
  put(frame: F): number {
    let superseded = this.frame === null ? 0 : 1;
    if (this.isKeyframe(frame)) {
      if (this.keyframe !== null) ++superseded;
      this.keyframe = frame;
      this.frame = null;
    } else {
      this.frame = frame;
    }
    return superseded;
  }

  // The next frame to show, the waiting keyframe first; null when none waits.
  take(): F | null {
    const next = this.keyframe ?? this.frame;
    if (this.keyframe !== null) this.keyframe = null;
    else this.frame = null;
    return next;
  }

  get hasKeyframe(): boolean {
    return this.keyframe !== null;
  }

  clear(): void {
    this.keyframe = null;
    this.frame = null;
  }
}
