"""SIGINT/SIGTERM while a DriveStation (or an API bus) is open: SIGTERM raises SessionTerminated in the
main thread (like KeyboardInterrupt), and during the safe stop a further SIGINT/SIGTERM only sets
`hurry` (the stop escalates to a coast stop instead of being interrupted). Main thread only
(elsewhere a guard changes no handler). Touches only the signal module.

Several guards may be open at once (two API buses): they share one handler per signal, installed
when the first guard needs it; each guard keeps its protection until its own restore(), in any
order, and the handlers from before the first guard come back only when the last one is restored.
A signal that arrives while some guards stop (they are hurried) and others are still open is not
lost: it is raised (SessionTerminated / KeyboardInterrupt) when the stopping guards are restored, so
the open ones end through their own safe stop too.

On Windows SIGBREAK counts as SIGTERM does: Ctrl-Break, and closing the console window (the C
runtime delivers CTRL_CLOSE_EVENT as SIGBREAK; Windows then ends the process within about 5 s, so the
safe stop starts at once). Ctrl-C is SIGINT there too.
"""

from __future__ import annotations

import os
import signal
import threading
from types import FrameType
from typing import Any, Protocol


class SessionTerminated(BaseException):
    """SIGTERM arrived while a DriveStation was open (raised in the main thread, like KeyboardInterrupt)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


#: the open guards (installed or stopping), oldest first
_active: list["SignalGuard"] = []
#: the handler of each signal before the first guard took it: signum -> handler
_original: dict[int, Any] = {}
#: a signal that hurried some stops while other guards were still open (raised on their restore)
_pending: list[int] = []


def _terminating() -> tuple[int, ...]:
    """The signals that end an open session as SIGTERM does: SIGTERM, and SIGBREAK where the
    platform has it (Windows)."""
    brk = getattr(signal, "SIGBREAK", None)
    return (signal.SIGTERM,) if brk is None else (signal.SIGTERM, brk)


def _dispatch(signum: int, frame: FrameType | None) -> None:
    guarding = [g for g in _active if g._guarding]
    if guarding:
        for g in guarding:
            g.hurry = True
        if any(not g._guarding for g in _active) and not _pending:
            _pending.append(signum)
        return
    if signum in _terminating() and _active:
        raise SessionTerminated(signum)
    _call_original(signum, frame)


def _call_original(signum: int, frame: FrameType | None) -> Any:
    h = _original.get(signum, signal.SIG_DFL)
    if callable(h):
        return h(signum, frame)
    if h == signal.SIG_IGN:
        return None
    signal.signal(signum, signal.SIG_DFL)      # the default action: deliver it again, unhandled
    os.kill(os.getpid(), signum)
    return None


def _sync() -> None:
    """Our handler on SIGTERM while any guard is open, on SIGINT while any guard is stopping; the
    original handler back on each signal as soon as no guard needs it."""
    if not _main_thread():
        return
    want = {s: bool(_active) for s in _terminating()}
    want[signal.SIGINT] = any(g._guarding for g in _active)
    for s, on in want.items():
        try:
            if on and s not in _original:
                _original[s] = signal.signal(s, _dispatch)
            elif not on and s in _original:
                h = _original.pop(s)
                signal.signal(s, h if h is not None else signal.SIG_DFL)
        except (TypeError, ValueError):
            pass


class Guard(Protocol):
    """What a session needs of its signal guard (SignalGuard, or the API's guard that shares a bus's)."""

    hurry: bool

    def install(self) -> None: ...

    def guard(self) -> None: ...

    def restore(self) -> None: ...


class SignalGuard:
    """The session's signal handling: install() when it opens, guard() when its safe stop begins,
    restore() when it is closed. `hurry` turns True on a signal during the stop."""

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self.hurry = False
        self._guarding = False

    def install(self) -> None:
        if not self.enabled or not _main_thread():
            return
        if self not in _active:
            _active.append(self)
        _sync()

    def guard(self) -> None:
        """While stopping: a further SIGINT/SIGTERM hurries the stop (coast) instead of raising."""
        if not self.enabled or not _main_thread():
            return
        if self not in _active:
            _active.append(self)
        self._guarding = True
        _sync()

    def restore(self) -> None:
        """This guard's protection ends (the others' stays). Raises the signal that hurried this
        stop while other guards were open, once no guard is stopping any more."""
        if self not in _active:
            return
        _active.remove(self)                    # also from another thread: the handler then chains
        self._guarding = False
        _sync()
        if _pending and _main_thread() and not any(g._guarding for g in _active):
            signum = _pending.pop()
            if _active:
                if signum in _terminating():
                    raise SessionTerminated(signum)
                raise KeyboardInterrupt
