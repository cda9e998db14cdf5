"""A one-line progress bar for long jobs (batch sweeps, streamed filters) on a terminal."""

from __future__ import annotations

import sys
import time


class Progress:
    """A one-line progress bar on a terminal (stderr); silent when not a terminal."""

    def __init__(self, total: int, label: str, stream=None, enabled: bool | None = None) -> None:
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.total, self.label, self.done = max(total, 1), label, 0
        self.t0 = time.perf_counter()
        self._last = -1.0

    def update(self, step: int, note: str = "") -> None:
        self.done += step
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        frac = min(self.done / self.total, 1.0)
        bar = "#" * int(30 * frac)
        elapsed = now - self.t0
        eta = f" eta {elapsed / frac * (1 - frac):6.1f}s" if 0 < frac < 1 else ""
        self.stream.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}% {elapsed:6.1f}s{eta} {note}")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
