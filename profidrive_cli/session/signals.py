"""SIGINT/SIGTERM while a DriveSession is open: SIGTERM raises SessionTerminated in the main thread
(like KeyboardInterrupt), and during the safe stop a further SIGINT/SIGTERM only sets `hurry` (the
stop escalates to a coast stop instead of being interrupted). The previous handlers come back on
restore(). Main thread only (elsewhere every call does nothing). Touches only the signal module.
"""

from __future__ import annotations

import signal
import threading
from typing import Any


class SessionTerminated(BaseException):
    """SIGTERM arrived while a DriveSession was open (raised in the main thread, like KeyboardInterrupt)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class SignalGuard:
    """The session's signal handling: install() when it opens, guard() when its safe stop begins,
    restore() when it is closed. `hurry` turns True on a signal during the stop."""

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self.hurry = False
        self._old_handlers: dict[int, Any] = {}

    def install(self) -> None:
        if not self.enabled or not _main_thread():
            return

        def on_term(signum, frame):
            raise SessionTerminated(signum)
        self._old_handlers[signal.SIGTERM] = signal.signal(signal.SIGTERM, on_term)
        self._old_handlers[signal.SIGINT] = signal.getsignal(signal.SIGINT)

    def guard(self) -> None:
        """While stopping: a further SIGINT/SIGTERM hurries the stop (coast) instead of raising."""
        if not self.enabled or not _main_thread():
            return

        def hurry(signum, frame):
            self.hurry = True
        for s in (signal.SIGTERM, signal.SIGINT):
            if s not in self._old_handlers:
                self._old_handlers[s] = signal.getsignal(s)
            signal.signal(s, hurry)

    def restore(self) -> None:
        if not _main_thread():
            return
        for s, h in self._old_handlers.items():
            try:
                signal.signal(s, h if h is not None else signal.SIG_DFL)
            except (TypeError, ValueError):
                pass
        self._old_handlers.clear()
