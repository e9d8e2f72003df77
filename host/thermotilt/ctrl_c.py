"""Ctrl-C where raising KeyboardInterrupt at any line would leave work half
done: a loop that stops at a point of its choosing, a block that finishes
first. Where Ctrl-C is ignored (a background job's SIGINT) or outside the
main thread, both leave it as it is."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def _ours_to_handle() -> bool:
    return (
        threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
    )


@contextmanager
def ctrl_c_as_flag() -> Iterator[Callable[[], bool]]:
    """Within the block Ctrl-C raises nothing; the function yielded says
    whether it was pressed, for the loop to stop at its next look."""
    if not _ours_to_handle():
        yield lambda: False
        return
    pressed: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: pressed.append(signum))
    try:
        yield lambda: bool(pressed)
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def ctrl_c_after_block() -> Iterator[None]:
    """Ctrl-C during the block reaches the handler there was before it
    (KeyboardInterrupt, or a ctrl_c_as_flag's flag) when the block ends."""
    if not _ours_to_handle():
        yield
        return
    pressed: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: pressed.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if pressed:
        handler = previous if callable(previous) else signal.default_int_handler
        handler(signal.SIGINT, None)
