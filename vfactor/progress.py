"""The progress bar of every long command (solve, track, detect, render, train): stderr, no dependencies.

Redrawn in place on a terminal, a few lines otherwise. Loops report either by
steps (``update(n)``, training) or through a callback ``progress(done, total)``
(``solve_scene``, ``track_scene``, ``detect_scene``, ``render_simulation``,
``make_dataset``): a :class:`Progress` is such a callback.
"""

from __future__ import annotations

__all__ = ["Progress"]

import sys
import time


class Progress:
    """``Progress(total, desc)``; ``update(n, loss=...)``; ``close()``; or called as ``bar(done, total)``.

    Silent when ``enabled`` is False; with ``tty_only``, also when the stream is not a terminal.
    """

    def __init__(self, total: int = 1, desc: str = "", enabled: bool = True, stream=None, width: int = 24,
                 tty_only: bool = False):
        self.total, self.desc, self.width = max(int(total), 1), desc, width
        self.stream = stream if stream is not None else sys.stderr
        self.count, self.start, self.postfix = 0, time.perf_counter(), ""
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = enabled and (self._tty or not tty_only)
        self._next_line = 0.0

    def __call__(self, done: int, total: int) -> None:
        """Callback form: ``done`` of ``total`` items are finished (ends the line when all are)."""
        self.total = max(int(total), 1)
        self.update(int(done) - self.count)
        if done >= total:
            self.close()

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
