"""Waiting on a pool's futures so that Ctrl-C and SIGTERM act at once."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, wait

POLL = 0.1   # s, the longest a signal waits to be handled


def completed(futures: Iterable[Future]) -> Iterator[Future]:
    """The futures as they finish, like :func:`concurrent.futures.as_completed`,
    but waking every ``POLL`` s.

    The kernel may deliver SIGINT or SIGTERM to any thread of the process;
    Python runs its handler in the main thread, and a main thread blocked
    without a timeout on a lock is not woken by a signal another thread took:
    waking every ``POLL`` s, a Ctrl-C is handled within that time.
    """
    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=POLL, return_when=FIRST_COMPLETED)
        yield from done
