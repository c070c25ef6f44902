"""How the command ends: the exit codes, SIGINT/SIGTERM raised as ``Interrupted`` (so that cleanup runs), the
progress log on stdout and the one line on stderr that ends every failure."""

import logging
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from mpi4py import MPI

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_CODES",
    "EXIT_NOT_CONVERGED",
    "EXIT_NUMERICAL",
    "EXIT_WRITE",
    "Interrupted",
    "interruptible",
    "raise_interrupted",
]

#: exit code -> meaning (``--help``, README)
EXIT_CODES = {
    0: "converged",
    2: "bad input (an option, a file or the mesh tags; nothing written)",
    3: "not converged: the transmission residual stayed above --tol (--max-iterations hit, or the interface Newton's "
    'corrections ran out; results written, "converged": false)',
    4: "numerical failure: Newton did not converge, non-finite values, a failed factorization (nothing written)",
    5: "the results could not be written (a full disk, an unwritable or removed directory); --out left as it was",
    130: "interrupted by SIGINT (Ctrl-C); --out left as it was",
    143: "interrupted by SIGTERM; --out left as it was",
}
EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, EXIT_NUMERICAL, EXIT_WRITE = 2, 3, 4, 5


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived (raised by the handlers of ``interruptible``)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def raise_interrupted(signum: int, frame) -> None:
    """A signal handler: raise ``Interrupted``."""
    raise Interrupted(signum)


#: a signal that arrives inside a ``__del__`` is raised again this much later (s)
DEFERRED_SIGNAL_S = 0.05


def _in_finalizer(frame) -> bool:
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


@contextmanager
def interruptible() -> Iterator[list[int]]:
    """SIGINT and SIGTERM raise ``Interrupted`` (so that cleanup runs); the previous handlers come back after.

    Python ignores an exception raised in a ``__del__`` (it prints "Exception ignored in ...") and goes on: a
    SIGTERM that arrived while DOLFINx freed a vector was lost and the run went on to exit 0.  A signal that
    arrives in a finalizer is therefore sent again ``DEFERRED_SIGNAL_S`` later (a timer thread; no SIGALRM, so
    a caller's alarms are left alone), and it is kept in the yielded list until it has been raised: a signal
    still listed when the block ends (it landed in the last finalizers) is the caller's to report.
    """
    pending: list[int] = []
    timers: list[threading.Timer] = []

    def handler(signum, frame):
        if _in_finalizer(frame):
            pending.append(signum)
            timer = threading.Timer(DEFERRED_SIGNAL_S, os.kill, (os.getpid(), signum))
            timer.daemon = True
            timers.append(timer)
            timer.start()
            return
        pending.clear()
        raise Interrupted(signum)

    main_thread = threading.current_thread() is threading.main_thread()
    signals = (signal.SIGINT, signal.SIGTERM) if main_thread else ()
    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield pending
    finally:
        for timer in timers:
            timer.cancel()
        for s, h in previous.items():
            signal.signal(s, h)


class _RankZero(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return MPI.COMM_WORLD.rank == 0


class _BelowWarning(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno < logging.WARNING


def stdout_lost(error: OSError) -> None:
    """stdout cannot be written (a closed pipe, ``| head``; a full device): what is left for it goes to the null
    device, so that the run goes on (and Python's last flush at exit does not fail), with one warning on stderr."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a file (a test's capture)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)
    if MPI.COMM_WORLD.rank == 0:
        print(
            f"warning: stdout cannot be written ({error.strerror or error}): the progress log stops here; the run "
            "goes on",
            file=sys.stderr,
            flush=True,
        )


class _ProgressHandler(logging.StreamHandler):
    """The progress log on stdout; a write that fails (``stdout_lost``) stops it, not the run."""

    def handleError(self, record: logging.LogRecord) -> None:
        error = sys.exc_info()[1]
        if isinstance(error, OSError):
            stdout_lost(error)
        else:
            super().handleError(record)


def _setup_logging(verbose: bool) -> None:
    """The progress log on stdout, warnings on stderr prefixed ``warning:``, rank 0 only; a failure ends with one
    line on stderr (``_fail``), the last."""
    out = _ProgressHandler(sys.stdout)
    out.addFilter(_RankZero())
    out.addFilter(_BelowWarning())
    out.setFormatter(logging.Formatter("%(message)s"))
    warn = logging.StreamHandler(sys.stderr)
    warn.setLevel(logging.WARNING)
    warn.addFilter(_RankZero())
    warn.setFormatter(logging.Formatter("warning: %(message)s"))
    root = logging.getLogger("fenics_contact")
    root.handlers[:] = [out, warn]
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    root.propagate = False


def _fail(message: str, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """One line on stderr (rank 0)."""
    if comm.rank == 0:
        print(" ".join(str(message).split()), file=sys.stderr, flush=True)
