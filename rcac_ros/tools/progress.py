"""A dependency-free progress line for long runs (stderr, redrawn in place)."""

import sys
import time


class Progress:
    """``with Progress(total, label) as p: p.update(done)``: ``label [####  ] 42% 1.3 s``."""

    def __init__(self, total, label, stream=None, enabled=True, width=30):
        self.total, self.label, self.width = max(total, 1), label, width
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._t0 = time.perf_counter()
        self._last = -1

    def update(self, done):
        pct = int(100 * done / self.total)
        # on a terminal redraw in place; in a log only the final line
        if not self.enabled or pct == self._last or (not self.tty and done < self.total):
            return
        self._last = pct
        fill = int(self.width * done / self.total)
        elapsed = time.perf_counter() - self._t0
        bar = "#" * fill + " " * (self.width - fill)
        self.stream.write(f"{chr(13) if self.tty else ''}{self.label} [{bar}] "
                          f"{pct:3d}% {elapsed:6.1f} s")
        self.stream.flush()

    def __enter__(self):
        self.update(0)
        return self

    def __exit__(self, *exc):
        if self.enabled:
            self.update(self.total)
            self.stream.write("\n")
            self.stream.flush()
        return False
