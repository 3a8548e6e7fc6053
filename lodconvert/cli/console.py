"""What the command line prints while it works: progress, warnings, results.

On a terminal, progress is a bar per stage (reading, converting, checking) with count, rate and
time left (tqdm); elsewhere (a log, CI) it is a plain line per stage at most every
:data:`LINE_SECONDS` and when the stage ends (unless its last line already said its count), each
with the time from the stage's start to its count. ``-v`` adds every step's detail, ``-q`` keeps
the final summary line only, ``-qq`` (``--silent``) prints errors only.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

LINE_SECONDS = 5.0
"""Least time between two progress lines when stderr is not a terminal."""
BAR_SECONDS = 0.2
"""Least time between two redraws of a progress bar."""


class Console:
    """Progress and messages on stderr. ``quiet`` 0 prints everything but details, 1 the
    summary line only, 2 nothing but errors; ``verbose`` adds details."""

    def __init__(self, quiet: int = 0, verbose: bool = False, stream: TextIO | None = None) -> None:
        self.quiet, self.verbose = int(quiet), verbose
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() and not self.quiet
        self.start = time.perf_counter()
        self._bar = None
        self._stage: str | None = None
        self._stage_start = self._last_line = self._done_at = 0.0
        self._done = 0
        self._total: int | None = None
        self._printed: int | None = None  # the count the stage's last plain line said

    def progress(self, message: str) -> None:
        """A step's detail (shown with ``-v``)."""
        if self.verbose and not self.quiet:
            self._write(f"{time.perf_counter() - self.start:6.1f}s {message}")

    def step(self, stage: str, done: int, total: int | None = None) -> None:
        """``done`` of ``total`` (``None``: unknown) items of ``stage`` are finished."""
        if self.quiet:
            return
        now = time.perf_counter()
        if stage != self._stage:
            self.end_stage()
            self._stage, self._stage_start, self._last_line = stage, now, now
            self._printed = None
            if self.live:
                from tqdm import tqdm

                self._bar = tqdm(
                    total=total,
                    desc=stage,
                    unit="obj",
                    file=self.stream,
                    leave=False,
                    mininterval=BAR_SECONDS,
                )
        self._done, self._total, self._done_at = done, total, now
        if self._bar is not None:
            self._bar.total = total
            self._bar.update(done - self._bar.n)
        elif now - self._last_line >= LINE_SECONDS:
            self._last_line = now
            self._print_line()

    def end_stage(self, report: bool = True) -> None:
        """Close the current stage's bar, or print its last plain line (when ``report``, and
        the stage's last line did not say its count already)."""
        if self._stage is None:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif report and not self.quiet and self._done and self._done != self._printed:
            self._print_line()
        self._stage = None

    def _print_line(self) -> None:
        """The stage's plain line: its count, and the time from its start to that count."""
        seconds = self._done_at - self._stage_start
        total = f"/{self._total:,}" if self._total else ""
        rate = f", {self._done / seconds:,.0f}/s" if seconds > 0 and self._done > 1 else ""
        self._write(f"{self._stage}: {self._done:,}{total} ({seconds:.1f} s{rate})")
        self._printed = self._done

    def warn(self, message: str) -> None:
        """A problem that did not stop the run (shown unless ``-qq``)."""
        if self.quiet < 2:
            self._write(f"lodconvert: warning: {message}")

    def info(self, message: str) -> None:
        """A result line (shown unless ``-q``)."""
        if not self.quiet:
            self._write(message)

    def summary(self, message: str) -> None:
        """The final line of a run (shown unless ``-qq``)."""
        self.end_stage()
        if self.quiet < 2:
            self._write(message)

    def clear(self) -> None:
        """End any progress display, silently, before an error line."""
        self.end_stage(report=False)

    def _write(self, line: str) -> None:
        if self._bar is not None:
            self._bar.write(line, file=self.stream)
        else:
            print(line, file=self.stream, flush=True)
