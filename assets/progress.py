"""Progress of long work (corpora, face tracks, enrolment speech...), the one progress bar every command and
training step uses: tqdm's bar on a terminal; whole lines in a log.

A bar redraws itself in place with ``\\r``: when stderr is a file or a pipe (CI, ``2> log``, ``| tee``) every
redraw lands in the file, one ``\\r``-joined blob per bar. There :class:`Progress` writes a plain ASCII line at
most every :data:`LOG_INTERVAL_S` (and the last count when the work ends), so a long run still shows how far it
got in its log."""

from __future__ import annotations

import sys
from typing import Any

from tqdm import tqdm

LOG_INTERVAL_S = 30.0
"""Seconds between two progress lines in a log (tqdm's ``mininterval``): a two-hour run writes ~240 lines."""


def _is_terminal(stream: Any) -> bool:
    isatty = getattr(stream, "isatty", None)
    return bool(isatty is not None and isatty())


class Progress(tqdm):
    """``tqdm`` (same arguments; ``Progress(iterable, desc=, unit=)``, ``Progress.write(line)``) that, when its
    stream (``file``, default stderr) is not a terminal, writes each refresh as its own ASCII line, at most every
    :data:`LOG_INTERVAL_S` unless the caller sets ``mininterval``, and takes back nothing (a log cannot be
    redrawn). On a terminal it is tqdm's bar, unchanged."""

    def __init__(self, iterable: Any = None, *args: Any, **kwargs: Any) -> None:
        self._in_log = not _is_terminal(kwargs.get("file") or sys.stderr)
        self._line_n: float | None = None  # the count of the last line written (in a log)
        if self._in_log:
            kwargs.setdefault("mininterval", LOG_INTERVAL_S)
            # A fixed miniters: with tqdm's dynamic one (> 1 on fast loops) its monitor thread redraws a bar left
            # alone for maxinterval (10 s), which in a log is a line every 10 s, whatever mininterval says.
            kwargs.setdefault("miniters", 1)
            kwargs.setdefault("ascii", True)  # a log viewer need not draw the block characters
        super().__init__(iterable, *args, **kwargs)

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        if not self._in_log:
            return bool(super().display(msg, pos))
        if msg == "":  # tqdm clearing the bar (before a write, at a close that leaves nothing): nothing to undo
            return False
        if msg is None and self.n == self._line_n:  # a redraw (after a write...) of the count the log shows
            return True
        self.fp.write(f"{self if msg is None else msg}\n")
        self.fp.flush()
        self._line_n = self.n
        return True

    def set_postfix(self, ordered_dict: Any = None, refresh: bool = True, **kwargs: Any) -> None:
        # In a log a postfix waits for the next line (tqdm's default refresh wrote one per call: `facecast train`
        # logged every Baum-Welch iteration, 9 lines in a second, each with the objective of the iteration after
        # the count it showed).
        super().set_postfix(ordered_dict, refresh=refresh and not self._in_log, **kwargs)

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        super().set_postfix_str(s, refresh=refresh and not self._in_log)

    def clear(self, nolock: bool = False) -> None:
        if not self._in_log:
            super().clear(nolock)

    def close(self) -> None:
        leave: bool | None = getattr(self, "leave", True)
        if leave is None:  # tqdm's rule: the outermost bar stays
            leave = abs(getattr(self, "pos", 0)) == 0
        if self._in_log and not self.disable and leave:
            if self._line_n != self.n:
                self.display()  # the final count, as the bar left on a terminal shows it
            # tqdm's close would draw the bar once more and end its line: our lines are whole already.
            self.leave = False
        super().close()
