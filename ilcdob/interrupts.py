"""Ctrl-C and SIGTERM through native solvers that swallow them.

CasADi checks for signals while IPOPT iterates; when one arrives, it runs Python's handler,
catches the ``KeyboardInterrupt`` that handler raises, and returns as from a failed solve
(status ``NonIpopt_Exception_Thrown``), so that the program would go on with a partial result.
:func:`honour_interrupts` records what the handlers raised inside such a call and raises it
again once the call returns.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["honour_interrupts"]


@contextmanager
def honour_interrupts() -> Iterator[None]:
    """Re-raise, after the block, an exception a SIGINT or SIGTERM handler raised inside it.

    Outside the main thread (where Python runs no signal handlers) the block runs as is.

    Raises
    ------
    KeyboardInterrupt
        (or what the installed handler raised) when a signal arrived inside the block and the
        code in it swallowed the handler's exception.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raised: list[BaseException] = []
    previous = {}

    def recording(before):
        def handler(signum, frame):
            try:
                before(signum, frame)
            except BaseException as exc:
                raised.append(exc)
                raise
        return handler

    for sig in (signal.SIGINT, signal.SIGTERM):
        before = signal.getsignal(sig)
        if not callable(before):  # ignored, or the system's default (which ends the process anyway)
            continue
        previous[sig] = before
        signal.signal(sig, recording(before))
    try:
        yield
    finally:
        for sig, before in previous.items():
            signal.signal(sig, before)
    if raised:
        raise raised[0]
