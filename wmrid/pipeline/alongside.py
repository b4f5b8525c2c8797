"""Two of the pipeline's passes over a log at once: one on a second thread while the caller's thread runs the other.

Which passes: :func:`wmrid.pipeline.identify.identify_log` checks the efforts' timing (the delay profile, numpy and
compiled filters) while the observer replays the log for the friction models (compiled, on the caller's thread, which
keeps the progress callbacks there).  The friction models' passes do not depend on the timing, which only decides
whether they are used (a significant delay has the log identified again with its efforts in time): so on two cores
the check costs no time of its own.  Both are deterministic, and neither writes what the other reads (the log's
pieces are read-only; a stream longer than its cache opens the file once per pass), so the numbers do not depend on
the threads.  Where a second thread would only compete for a busy core (``wmrid fleet``'s workers, one per core:
:func:`wmrid.estimators.observer.replay.one_thread`) the passes run one after the other, in the order the route
names them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Generic, TypeVar

from wmrid.estimators.observer.replay import second_thread

T = TypeVar("T")


class Once(Generic[T]):
    """``fn()``'s outcome, computed once: at the first call, or ahead of it (:meth:`run`, e.g. alongside another pass).
    An error (an Exception) is kept and raised again at each call, as ``fn`` would have raised it then."""

    def __init__(self, fn: Callable[[], T]) -> None:
        self._fn = fn
        self._done = False
        self._value: T | None = None
        self._error: Exception | None = None

    def run(self) -> None:
        """Compute the outcome now, if not yet (an error is kept for the calls)."""
        if self._done:
            return
        try:
            self._value = self._fn()
        except Exception as err:
            self._error = err
        self._done = True

    def __call__(self) -> T:
        self.run()
        if self._error is not None:
            raise self._error
        return self._value  # type: ignore[return-value]


def alongside(main: Callable[[], T], meanwhile: Callable[[], object] | None) -> T:
    """``main()``, with ``meanwhile()`` run on this thread while ``main`` runs on a second one; ``main``'s result, or
    its error raised here once ``meanwhile`` has returned.  ``meanwhile`` keeps its own outcome (a :meth:`Once.run`);
    None, or no second thread allowed (:func:`wmrid.estimators.observer.replay.second_thread`): ``main()`` alone,
    on this thread.  A stop (KeyboardInterrupt) in ``meanwhile`` is raised at once; ``main`` then ends on its own."""
    if meanwhile is None or not second_thread():
        return main()
    outcome: dict[str, object] = {}

    def work() -> None:
        try:
            outcome["value"] = main()
        except BaseException as err:  # raised again on the caller's thread
            outcome["error"] = err

    worker = threading.Thread(target=work, name="wmrid-alongside")
    worker.start()
    meanwhile()
    worker.join()
    if "error" in outcome:
        raise outcome["error"]  # type: ignore[misc]
    return outcome["value"]  # type: ignore[return-value]
