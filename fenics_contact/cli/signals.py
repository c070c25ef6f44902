"""How the command ends: the exit codes, SIGINT/SIGTERM raised as ``Interrupted`` (so that cleanup runs), the
progress log on stdout and the one line on stderr that ends every failure."""

import contextlib
import errno
import fcntl
import logging
import os
import signal
import socket
import stat
import struct
import sys
import termios
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from mpi4py import MPI

from fenics_contact.io import process_alive

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_CODES",
    "EXIT_NOT_CONVERGED",
    "EXIT_NUMERICAL",
    "EXIT_WRITE",
    "Interrupted",
    "end_every_rank",
    "share_rank_zero",
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
    """SIGINT and SIGTERM raise ``Interrupted`` (so that cleanup runs), once: a later SIGINT or SIGTERM is ignored
    (under ``mpiexec`` a rank gets SIGTERM from the launcher and again from another rank); the previous handlers
    come back after.

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
        for s in signals:  # the run is ending: a second signal must not cut its cleanup or its last line short
            signal.signal(s, signal.SIG_IGN)
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


#: a rank other than 0 that was interrupted gives rank 0 this long to end the run (s) before it does so itself
ABORT_GRACE_S = 2.0
#: the longest wait for the launcher to read the last line from stderr before ``MPI_Abort`` (s)
STDERR_DRAIN_S = 2.0
#: (host name, process id) of rank 0 (``share_rank_zero``)
_rank_zero: list[tuple[str, int]] = []
#: the socket whose name claims the one line of an interrupted run (``_claim_the_line``), held until the end
_claim: list[socket.socket] = []


def share_rank_zero(comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """Tell every rank the host and process of rank 0 (collective), for ``end_every_rank``."""
    _rank_zero[:] = [comm.bcast((socket.gethostname(), os.getpid()), root=0)]


def _claim_the_line() -> bool:
    """True for the first rank on this host to ask (the one that prints the line), False for the later ones.

    The claim is an abstract Unix socket named after rank 0's process: the kernel binds a name once and frees it
    when its holder ends, so nothing is left behind.  True where no such socket can be made (not Linux).
    """
    if not _rank_zero:
        return True
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        sock.bind(f"\0fenics-contact-interrupted-{_rank_zero[0][1]}")
    except OSError as error:
        sock.close()
        return error.errno != errno.EADDRINUSE
    _claim.append(sock)
    return True


def _unread_bytes(fd: int) -> int:
    """The bytes written to the pipe ``fd`` that its reader has not read yet (0 when ``fd`` is not a pipe)."""
    try:
        if not stat.S_ISFIFO(os.fstat(fd).st_mode):
            return 0
        return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, bytes(4)))[0]
    except OSError:
        return 0


def _write_last_line(message: str) -> None:
    """``message`` as one line on stderr (fd 2 directly, after what Python holds for it), then a wait of at most
    ``STDERR_DRAIN_S`` until the launcher has read it.

    Once an abort reaches MPICH's ``mpiexec`` (hydra), it kills its proxies at its next whole second and exits,
    dropping output that has not reached it yet; a proxy serves a rank's PMI socket before its stderr pipe when
    both wait.  A line still in the pipe when the rank aborts is therefore lost now and then (a few aborts in a
    hundred).  The proxy sends what it reads from the pipe on to ``mpiexec`` at once, on the stream that later
    carries the abort: once the pipe is empty, the line reaches ``mpiexec`` ahead of the abort.
    """
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    line = (" ".join(str(message).split()) + "\n").encode()
    with contextlib.suppress(OSError):
        os.write(2, line)  # (one write of less than PIPE_BUF bytes: not interleaved with another rank's)
    deadline = time.monotonic() + STDERR_DRAIN_S
    while _unread_bytes(2) > 0 and time.monotonic() < deadline:
        time.sleep(0.001)


def end_every_rank(message: str, signum: int, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """End every rank of the run with exit code 128 + ``signum`` (MPI_Abort; MPICH adds a line of its own), with
    ``message`` as the one line on stderr, printed once.

    Under MPI a signal reaches one rank only (``kill PID``), or every rank (``mpiexec`` passes the SIGTERM it gets
    on to all of them), at different points of the run: a rank that returned alone would leave the others waiting
    in a collective operation for ever, at 100 % CPU.  Rank 0 prints and aborts at once.  Another rank passes the
    signal on to rank 0 (on the same host), which ends the run with its one line; if rank 0 has not done so within
    ``ABORT_GRACE_S`` (it waits in a collective operation for this rank, or runs on another host) this rank prints
    and aborts.  Of the ranks of one host only the first to claim the line (``_claim_the_line``) prints it; the
    line is read by the launcher before the abort (``_write_last_line``).
    """
    for s in (signal.SIGINT, signal.SIGTERM):  # (the run is ending: a second signal must not cut this short)
        signal.signal(s, signal.SIG_IGN)
    if comm.rank != 0:
        local = bool(_rank_zero) and _rank_zero[0][0] == socket.gethostname()
        if local:
            with contextlib.suppress(OSError):
                os.kill(_rank_zero[0][1], signum)
        time.sleep(ABORT_GRACE_S)
        if local and not process_alive(_rank_zero[0][1]):  # rank 0 has ended the run, with its line
            os._exit(128 + signum)
    if _claim_the_line():
        _write_last_line(message)
    else:  # a rank of this host prints the line and ends the run: an abort now could cut its line off
        time.sleep(ABORT_GRACE_S + STDERR_DRAIN_S)
    comm.Abort(128 + signum)
    os._exit(128 + signum)  # (MPI_Abort may return before the launcher has ended the processes)


def _fail(message: str, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """One line on stderr (rank 0)."""
    if comm.rank == 0:
        print(" ".join(str(message).split()), file=sys.stderr, flush=True)
