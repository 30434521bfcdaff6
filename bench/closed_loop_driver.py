"""A session driven closed-loop on a thread of its own, for the stall benches.

The driver sends a pose, waits for the frame that answers it, and records
when it came; the benches compare the intervals between frames before and
while something else loads the server.
"""
import threading
import time

import numpy as np


class ClosedLoopDriver:
    def __init__(self, session) -> None:
        self._driver = session.drive()
        self._base = session.base_positions.copy()
        self._stop = threading.Event()
        self.stamps: list[float] = []  # when each frame arrived (time.monotonic)
        self._thread = threading.Thread(target=self._run)

    def _run(self) -> None:
        k = 0
        while not self._stop.is_set():
            k += 1
            self._driver.wait_for_pose(self._driver.send(self._base + np.float32(0.001 * (k % 10))))
            self.stamps.append(time.monotonic())

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def intervals_before(self, t: float) -> np.ndarray:
        """Intervals between the frames that came before time t."""
        return np.diff([s for s in self.stamps if s < t])

    def intervals_during(self, start: float, end: float) -> list[float]:
        """Intervals that overlap [start, end]."""
        return [b - a for a, b in zip(self.stamps, self.stamps[1:]) if b > start and a < end]
