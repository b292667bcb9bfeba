"""Places where a long computation may be stopped by its caller.

The transforms' long loops (a fit's rounds, a registration's, the blocks of a large array)
call :func:`checkpoint` once a pass. It does nothing unless the caller has installed a check
with :func:`checked`; the check raises to stop the computation (a served job past its time
limit raises its 504 problem), so the work stops at the next pass instead of running on
unseen. Nothing is left half-written: a stopped transform returns nothing.

The check is held in a context variable, so each thread (each served job) has its own and
the transforms take no extra argument.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

_check: ContextVar[Callable[[], None] | None] = ContextVar("meshflat_check", default=None)


def checkpoint() -> None:
    """Call the check :func:`checked` installed in this context, if any (it raises to stop
    the computation)."""
    check = _check.get()
    if check is not None:
        check()


@contextmanager
def checked(check: Callable[[], None]) -> Iterator[None]:
    """Within the block, every :func:`checkpoint` of this context calls ``check()``."""
    token = _check.set(check)
    try:
        yield
    finally:
        _check.reset(token)
