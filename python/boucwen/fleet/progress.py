"""Progress of a fleet run on the terminal: records done / total, rate, time left.

On a terminal the line is redrawn in place (carriage return); into a file or a pipe a
new line is printed at most every :data:`LOG_INTERVAL_S` seconds and at the end, so a
CI log stays short. The rate counts the records computed in this run only (records
skipped because their result was already there are counted as done, not in the rate).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["LOG_INTERVAL_S", "Progress", "format_duration"]

#: Seconds between progress lines when the stream is not a terminal.
LOG_INTERVAL_S = 10.0


def format_duration(seconds: float) -> str:
    """``42s``, ``3m05s``, ``2h07m``; ``?`` when unknown."""
    if not seconds >= 0 or seconds == float("inf"):
        return "?"
    s = round(seconds)
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{(s % 3600) // 60:02d}m"


class Progress:
    """Counts finished records and prints the progress line.

    Args:
        label: start of the line, e.g. ``"batch fit"``.
        total: records in the source.
        skipped: records already done before the run (counted as done).
        stream: where to print (default stderr); ``None`` prints nothing.
    """

    def __init__(self, label: str, total: int, skipped: int = 0, stream: TextIO | None = sys.stderr):
        self.label = label
        self.total = total
        self.skipped = skipped
        self.computed = 0
        self.errors = 0
        self.stream = stream
        self.started = time.perf_counter()
        self._last_print = -float("inf")
        self._last_update = self.started
        self._tty = bool(stream is not None and getattr(stream, "isatty", lambda: False)())

    @property
    def done(self) -> int:
        """Records with a result: skipped plus computed in this run."""
        return self.skipped + self.computed

    def start(self) -> None:
        """Starts the clock (when the first task is submitted)."""
        self.started = self._last_update = time.perf_counter()

    @property
    def elapsed(self) -> float:
        """Seconds from :meth:`start` to the latest record computed."""
        return self._last_update - self.started

    @property
    def rate(self) -> float:
        """Records computed per second, from the start to the latest record (0 before the first)."""
        return self.computed / self.elapsed if self.computed and self.elapsed > 0 else 0.0

    def line(self) -> str:
        """The progress line (without line ending)."""
        rate = self.rate
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        errors = f", {self.errors} error{'s' if self.errors != 1 else ''}" if self.errors else ""
        skipped = f" ({self.skipped} already done)" if self.skipped else ""
        if not self.computed:
            return f"{self.label}: {self.done}/{self.total} records{skipped}{errors}"
        return (
            f"{self.label}: {self.done}/{self.total} records{skipped}{errors}, "
            f"{rate:.2f} records/s, {format_duration(left if self.done < self.total else 0.0)} left"
        )

    def update(self, error: bool = False) -> None:
        """One more record computed (``error``: it ended as an error row)."""
        self.computed += 1
        self.errors += int(error)
        now = time.perf_counter()
        self._last_update = now
        if self._tty or now - self._last_print >= LOG_INTERVAL_S:
            self._print()
            self._last_print = now

    def _print(self, end: str = "") -> None:
        if self.stream is None:
            return
        if self._tty:
            self.stream.write("\r\x1b[K" + self.line() + end)
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Prints the final line."""
        self._print(end="\n")

    def say(self, message: str) -> None:
        """Prints a message line (not overwritten by the progress line)."""
        if self.stream is None:
            return
        prefix = "\r\x1b[K" if self._tty else ""
        self.stream.write(f"{prefix}{message}\n")
        self.stream.flush()
