"""A dependency-free progress bar on stderr (redrawn in place on a terminal, a few lines otherwise)."""

from __future__ import annotations

import sys
import time


class Progress:
    """``Progress(total, desc)``; ``update(n, loss=...)``; ``close()``. Silent when ``enabled`` is False."""

    def __init__(self, total: int, desc: str = "", enabled: bool = True, stream=None, width: int = 24):
        self.total, self.desc, self.enabled, self.width = max(int(total), 1), desc, enabled, width
        self.stream = stream if stream is not None else sys.stderr
        self.count, self.start, self.postfix = 0, time.perf_counter(), ""
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._next_line = 0.0

    def update(self, n: int = 1, **postfix) -> None:
        self.count = min(self.count + n, self.total)
        if postfix:
            self.postfix = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in postfix.items())
        if not self.enabled:
            return
        frac = self.count / self.total
        if self._tty:
            self._draw("\r", "")
        elif frac >= self._next_line or self.count == self.total:
            self._draw("", "\n")
            self._next_line = frac + 0.25

    def _draw(self, prefix: str, suffix: str) -> None:
        frac = self.count / self.total
        elapsed = time.perf_counter() - self.start
        eta = elapsed / frac - elapsed if frac > 0 else float("nan")
        bar = "#" * int(round(frac * self.width))
        line = (f"{prefix}{self.desc} [{bar:<{self.width}}] {self.count}/{self.total} "
                f"{elapsed:5.0f}s<{eta:4.0f}s {self.postfix}")
        self.stream.write(line + suffix)
        self.stream.flush()

    def close(self) -> None:
        if self.enabled and self._tty:
            self.stream.write("\n")
            self.stream.flush()
