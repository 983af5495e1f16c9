"""Progress lines of the long-running functions (``progress=`` of fit and diagnose)."""

from __future__ import annotations

import sys
import time
from typing import Callable, Union

__all__ = ["Progress", "Reporter", "reporter"]

#: A ``progress=`` argument: ``True`` prints to stderr, a callable receives each line.
Progress = Union[bool, Callable[[str], None]]
#: Takes one progress line.
Reporter = Callable[[str], None]


def _silent(message: str) -> None:
    pass


def reporter(progress: Progress, label: str, started: float, width: int = 6) -> Reporter:
    """The function that handles the progress lines of one call.

    Args:
        progress: ``True`` to print ``"<label>: [<seconds> s] <message>"`` to stderr,
            a callable to receive each message as is, ``False`` for silence.
        label: name of the function printed in front of each line.
        started: ``time.perf_counter()`` at the start of the call [s].
        width: field width of the elapsed seconds.
    """
    if progress is True:

        def say(message: str) -> None:
            elapsed = time.perf_counter() - started
            print(f"{label}: [{elapsed:{width}.2f} s] {message}", file=sys.stderr, flush=True)

        return say
    if callable(progress):
        return progress
    return _silent
