// A rest mesh that came in parts: when the arrays of a session's rest mesh
// would make SessionInfo larger than the server sends in one message
// (RestMesh.inParts; half its --max-message-mib), JoinSession answers with
// the counts only and GetRestMesh streams the arrays. Each part continues
// them where the previous one left them: positions (3·n), then faces (3·F),
// then uploaded_ids (n); a part may end one array and start the next.
// RestAssembler copies the parts into typed arrays of the announced sizes and
// refuses parts that hold more, or an end that holds less.

export interface RestPart { positions: ArrayLike<number>; faces: ArrayLike<number>; uploadedIds: ArrayLike<number> }

export class RestPartsError extends Error {
  override name = 'RestPartsError';
}

export class RestAssembler {
  readonly positions: Float32Array<ArrayBuffer>;
  readonly faces: Uint32Array<ArrayBuffer>;
  readonly uploadedIds: Uint32Array<ArrayBuffer>;
  private positionsAt = 0;
  private facesAt = 0;
  private idsAt = 0;
  parts = 0;

  constructor(readonly vertexCount: number, readonly faceCount: number) {
    this.positions = new Float32Array(3 * vertexCount);
    this.faces = new Uint32Array(3 * faceCount);
    this.uploadedIds = new Uint32Array(vertexCount);
  }

  // Values of the three arrays, in all.
  get total(): number {
    return this.positions.length + this.faces.length + this.uploadedIds.length;
  }

  // Values received so far.
  get received(): number {
    return this.positionsAt + this.facesAt + this.idsAt;
  }

  get fraction(): number {
    return this.total === 0 ? 1 : this.received / this.total;
  }

  // Appends a part; throws RestPartsError if it holds more than the mesh has left.
  push(part: RestPart): void {
    if (this.positionsAt + part.positions.length > this.positions.length
        || this.facesAt + part.faces.length > this.faces.length
        || this.idsAt + part.uploadedIds.length > this.uploadedIds.length) {
      throw new RestPartsError(`The session's mesh, sent in parts, holds more than its ${this.vertexCount} vertices ` +
        `and ${this.faceCount} faces (part ${this.parts + 1}).`);
    }
    this.positions.set(part.positions, this.positionsAt);
    this.positionsAt += part.positions.length;
    this.faces.set(part.faces, this.facesAt);
    this.facesAt += part.faces.length;
    this.uploadedIds.set(part.uploadedIds, this.idsAt);
    this.idsAt += part.uploadedIds.length;
    ++this.parts;
  }

  // After the last part: throws RestPartsError unless the positions and the
  // faces are complete (uploaded_ids may be left out: the viewer does not need them).
  finish(): void {
    if (this.positionsAt !== this.positions.length || this.facesAt !== this.faces.length
        || (this.idsAt !== 0 && this.idsAt !== this.uploadedIds.length)) {
      throw new RestPartsError(`The session's mesh, sent in parts, arrived incomplete: its ${this.parts} parts hold ` +
        `${this.positionsAt / 3} vertices, ${this.facesAt / 3} faces and ${this.idsAt} uploaded ids, not ` +
        `${this.vertexCount}, ${this.faceCount} and ${this.vertexCount}.`);
    }
    for (let i = 0; i < this.faces.length; ++i) {
      if (this.faces[i] >= this.vertexCount) {
        throw new RestPartsError(`The session's mesh, sent in parts, is not whole: face ${Math.floor(i / 3)} names ` +
          `vertex ${this.faces[i]} of ${this.vertexCount}.`);
      }
    }
  }
}
