"""Fits run side by side in threads: the model choice's candidates, the diagnosis' refits.

The compiled kernels (simulation, sensitivities) release the interpreter and so does LAPACK's
QR; ``scipy.optimize.least_squares``'s own Python does not. Two independent fits in two threads
then take about as long as the longer one on two cores. Each fit is the same computation on one
thread or several: the results do not depend on the thread count.
"""

from __future__ import annotations

import contextvars
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np

from .errors import Cancelled

__all__ = ["MAX_WORKERS", "Cancelled", "cancellable", "check_cancelled", "side_by_side",
           "run_side_by_side", "worker_count"]

#: Most threads taken by default. A round of refits or a model choice holds a handful of fits;
#: more threads than that gain little.
MAX_WORKERS = 4

T = TypeVar("T")


def worker_count(workers: int | None, error: type[Exception] = ValueError) -> int:
    """Threads to run fits in: ``workers``, else the cores up to :data:`MAX_WORKERS`.

    Parameters
    ----------
    workers : int or None
        A whole number >= 1, or None for the default.
    error : type of Exception
        Raised for anything else.

    Returns
    -------
    int

    Raises
    ------
    error
        Naming ``workers`` and what was expected.
    """
    if workers is None:
        return max(1, min(MAX_WORKERS, os.cpu_count() or 1))
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise error(f"workers: expected a whole number >= 1, got {workers!r}")
    return int(workers)


@contextmanager
def side_by_side(n_workers: int, name: str = "hystid") -> Iterator[ThreadPoolExecutor]:
    """A pool of ``n_workers`` threads; on the way out (an error, Ctrl-C) the work not yet
    started is dropped instead of run to the end.

    Parameters
    ----------
    n_workers : int
        Threads.
    name : str
        Prefix of the threads' names.

    Yields
    ------
    concurrent.futures.ThreadPoolExecutor
    """
    jobs = ThreadPoolExecutor(n_workers, thread_name_prefix=name)
    try:
        yield jobs
    finally:
        jobs.shutdown(wait=True, cancel_futures=True)


def run_side_by_side(calls: Sequence[Callable[[], T]], workers: int | None = None,
                     name: str = "hystid") -> list[Any]:
    """The results of ``calls``, in their order, run in up to ``workers`` threads (inline, one
    after the other, with one).

    Parameters
    ----------
    calls : sequence of callable
        Functions of no argument.
    workers : int, optional
        Threads (:func:`worker_count`).
    name : str
        Prefix of the threads' names.

    Returns
    -------
    list
        ``[call() for call in calls]``, each call run in a copy of the caller's context
        (:mod:`contextvars`); the first error raised is raised again.
    """
    n = min(worker_count(workers), len(calls))
    if n <= 1:
        return [call() for call in calls]
    with side_by_side(n, name) as jobs:
        # each call sees the caller's context variables (a fit inside another's knows it is)
        futures = [jobs.submit(contextvars.copy_context().run, call) for call in calls]
        return [f.result() for f in futures]


#: The event that cancels the fits of the current context (set by :func:`cancellable`).
_CANCEL: contextvars.ContextVar[threading.Event | None] = contextvars.ContextVar(
    "_CANCEL", default=None)


def check_cancelled() -> None:
    """Raise :class:`Cancelled` when the current context's fit was cancelled; a fit's
    evaluation calls it, so a cancelled fit ends within one evaluation.

    Raises
    ------
    Cancelled
        When the event given to :func:`cancellable` is set.
    """
    event = _CANCEL.get()
    if event is not None and event.is_set():
        raise Cancelled


def cancellable(call: Callable[[], T], event: threading.Event) -> Callable[[], T | None]:
    """``call`` made to stop once ``event`` is set: it returns None then.

    A fit started ahead of the decision that needs it (the model choice's whole-record fit of a
    member that may not be chosen) runs this way, and is cancelled when it is not needed.

    Parameters
    ----------
    call : callable
        A function of no argument whose work calls :func:`check_cancelled`.
    event : threading.Event
        Set to cancel.

    Returns
    -------
    callable
        Of no argument: ``call()``, or None when cancelled.
    """
    def run() -> T | None:
        token = _CANCEL.set(event)
        try:
            return call()
        except Cancelled:
            return None
        finally:
            _CANCEL.reset(token)
    return run
