"""Ctrl-C that a command never loses.

Python's own SIGINT handler raises ``KeyboardInterrupt`` in whatever Python code runs next. When
that code is a weakref callback or a ``__del__`` (run by the garbage collector in the middle of
other code), Python prints "Exception ignored in ..." and carries on: the command ran to its end
and exited 0 after the user pressed Ctrl-C. While a command runs, the handler here moves such an
interrupt out of that code: it sends SIGINT to the process again a moment later, until the
interrupt lands where it can be raised.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from types import FrameType
from typing import Iterator, Optional

#: how long a deferred interrupt waits before it is sent again [s]: a finalizer is short
RESEND_AFTER_S = 0.01

#: code that Python runs from C and whose exceptions it prints and drops: weakref callbacks
#: (the standard library's weak containers) and finalizers
_SWALLOWING_FILES = ("weakref.py", "_weakrefset.py")
_SWALLOWING_NAMES = ("__del__",)


def in_swallowing_code(frame: Optional[FrameType]) -> bool:
    """Whether ``frame`` or a frame below it runs a weakref callback or a ``__del__``, where a
    raised ``KeyboardInterrupt`` would be dropped."""
    while frame is not None:
        code = frame.f_code
        if code.co_name in _SWALLOWING_NAMES or os.path.basename(code.co_filename) in _SWALLOWING_FILES:
            return True
        frame = frame.f_back
    return False


def _resend() -> None:
    os.kill(os.getpid(), signal.SIGINT)


def _handler(signum: int, frame: Optional[FrameType]) -> None:
    if in_swallowing_code(frame):
        # sent from another thread: os.kill in the main thread would run this handler again at
        # once, still inside the same callback
        timer = threading.Timer(RESEND_AFTER_S, _resend)
        timer.daemon = True
        timer.start()
        return
    raise KeyboardInterrupt


@contextlib.contextmanager
def interrupts_not_swallowed() -> Iterator[None]:
    """Within the block (main thread only), Ctrl-C raises ``KeyboardInterrupt`` as Python's own
    handler does, but never inside a weakref callback or finalizer. A handler the caller set
    (or SIGINT ignored) is left as it is."""
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    signal.signal(signal.SIGINT, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
