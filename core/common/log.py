"""Messages and progress of a long run, without printing: the core reports into these and the
front end shows them -- the command line prints them, the add-on's operators replay the
messages with ``self.report`` (as glTF-Blender-IO's ``Log`` does) and show progress in the
status bar.

* :class:`MessageLog` -- the run's messages in order, ``(level, text)``, level ``"INFO"``
  or ``"WARNING"`` (errors are raised, :mod:`.errors`);
* :class:`FrameProgress` -- "label: done/total frames (rate)" handed to a sink at most once a
  second, and once at the end.
"""

from __future__ import annotations

import time

LEVELS = ("INFO", "WARNING")


class MessageLog:
    """The messages of one run. ``echo(level, text)``, if given, sees each message as it is
    logged (the command line prints warnings at once)."""

    def __init__(self, echo=None):
        self.messages: list[tuple[str, str]] = []
        self.echo = echo

    def log(self, level: str, text: str) -> None:
        if level not in LEVELS:
            raise ValueError(f"unknown message level {level!r}")
        self.messages.append((level, text))
        if self.echo is not None:
            self.echo(level, text)

    def info(self, text: str) -> None:
        self.log("INFO", text)

    def warning(self, text: str) -> None:
        self.log("WARNING", text)

    @property
    def warnings(self) -> list[str]:
        return [text for level, text in self.messages if level == "WARNING"]

    def replay(self, report) -> None:
        """Hand every message to ``report({level}, text)`` -- a Blender operator's ``self.report``."""
        for level, text in self.messages:
            report({level}, text)


class FrameProgress:
    """``sink(text, final)`` at most once a second while ``total`` frames are worked through,
    and once with ``final=True`` at the end. ``sink`` None: silent."""

    def __init__(self, total: int, label: str, sink=None, interval_s: float = 1.0):
        self.total, self.label, self.sink, self.interval_s = total, label, sink, interval_s
        self.t0 = self.last = time.perf_counter()

    def __call__(self, done: int, final: bool = False) -> None:
        now = time.perf_counter()
        if self.sink is not None and (final or now - self.last > self.interval_s):
            self.last = now
            rate = done / max(now - self.t0, 1e-9)
            self.sink(f"{self.label}: {done}/{self.total} frames ({rate:.0f} frames/s)", final)
