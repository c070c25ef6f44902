"""Ctrl-C (SIGINT) or SIGTERM during a run: exit 130 / 143, one line on stderr, --out left as it was."""

import contextlib
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI
from outcome import outcome_lines, run_files

from fenics_contact.cli import main
from fenics_contact.io import _STAGING

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own process")

#: a run that takes minutes: the plain update to a tolerance near round-off
LONG_RUN = ["--h", "64", "--H", "16", "--accel", "none", "--tol", "1e-14", "--max-iterations", "100000", "--no-plots"]


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupted_run_leaves_the_previous_results(tmp_path, signum, code):
    out = tmp_path / "run"
    assert main(["run", "--h", "16", "--H", "4", "--no-plots", "--out", str(out)]) == 0
    before = run_files(out)
    log = tmp_path / "stdout.txt"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    with open(log, "w") as stdout:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fenics_contact.cli", "run", *LONG_RUN, "--out", str(out)],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        try:
            deadline = time.monotonic() + 300
            while " it " not in log.read_text():  # the iteration is under way (the staging directory exists)
                assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
                time.sleep(0.2)
            assert list(out.glob(".fenics-contact-*.partial")), "the staging directory is inside the existing --out"
            proc.send_signal(signum)
            _, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == code, err
    lines = outcome_lines(err)
    assert lines == [f"interrupted by {signal.Signals(signum).name}: {out} left as it was (no partial output)"], err
    assert run_files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "stdout.txt"], "no staging directory is left"


@pytest.mark.slow
def test_interrupt_while_starting_up(tmp_path):
    """Ctrl-C while the console script still imports DOLFINx: exit 130, one line, no traceback, nothing written."""
    out = tmp_path / "run"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    # the console script's own code path (pyproject: fenics-contact = fenics_contact.launch:main); the SIGINT
    # arrives once the package itself is imported (the marker file), while the command line's imports run
    marker = tmp_path / "imported"
    code = (
        "import sys, pathlib, fenics_contact; pathlib.Path(sys.argv[1]).touch(); "
        "from fenics_contact.launch import main; sys.exit(main(sys.argv[2:]))"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code, str(marker), "run", "--h", "16", "--H", "4", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        deadline = time.monotonic() + 120
        while not marker.exists():
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.01)
        time.sleep(0.2)  # inside main(): the import of the command line (1-5 s here) is under way
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["interrupted by SIGINT while starting up: nothing was written"], err
    assert not out.exists()


@pytest.mark.slow
def test_interrupt_during_the_imports_is_held_until_they_finish(tmp_path):
    """A SIGINT that arrives while the command line is being imported does not break into the import (where it
    could land in a callback of DOLFINx's C++ module initialisation and abort the process): the import runs to
    its end, then the run stops with exit 130 and the one line.  The signal is sent from inside the import."""
    out = tmp_path / "run"
    code = (
        "import builtins, os, signal, sys, fenics_contact.launch as launch\n"
        "real = builtins.__import__\n"
        "def hooked(name, *args, **kwargs):\n"
        "    if name == 'fenics_contact.cli':\n"
        "        builtins.__import__ = real\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "    return real(name, *args, **kwargs)\n"
        "builtins.__import__ = hooked\n"
        "code = launch.main(sys.argv[1:])\n"
        "print('imported', 'fenics_contact.cli' in sys.modules, 'dolfinx.fem' in sys.modules)\n"
        "sys.exit(code)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, "run", "--h", "16", "--H", "4", "--out", str(out)],
        capture_output=True,
        text=True,
        env=dict(os.environ, OMP_NUM_THREADS="1"),
        timeout=300,
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines() == ["interrupted by SIGINT while starting up: nothing was written"]
    assert proc.stdout.split() == ["imported", "True", "True"]  # the import was not cut short
    assert not out.exists()


def test_a_signal_inside_a_finalizer_is_not_lost():
    """Python ignores exceptions raised in ``__del__``: a SIGTERM that arrived while DOLFINx freed a vector was
    swallowed and the run went on to exit 0 (seen once in the suite).  It is sent again just after; one that
    lands in the very last finalizer of the block is handed to the caller; the caller's handlers and alarms
    are left as they were."""
    from fenics_contact.cli import Interrupted, interruptible

    class Freed:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)  # the handler runs inside this finalizer
            time.sleep(0.01)

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGALRM)}
    rang = []
    signal.signal(signal.SIGALRM, lambda *_: rang.append(1))
    signal.setitimer(signal.ITIMER_REAL, 0.3)  # a caller's alarm, running through the block
    try:
        with pytest.raises(Interrupted) as stop, interruptible():
            Freed()  # (dropped at once)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.01)
        assert stop.value.signum == signal.SIGTERM
        with interruptible() as pending:  # the signal lands in the block's last finalizer
            Freed()
        assert pending == [signal.SIGTERM]
        time.sleep(0.4)
        assert rang == [1], "the caller's alarm still rings"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, before[signal.SIGALRM])
    assert {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)} == {
        s: before[s] for s in (signal.SIGINT, signal.SIGTERM)
    }


def test_only_the_first_signal_of_a_run_is_raised():
    """A second SIGTERM or SIGINT while the first is handled (mpiexec passes a SIGTERM to every rank, and a rank
    passes its own on to rank 0) is ignored: it cannot cut the cleanup or the last line short."""
    from fenics_contact.cli import Interrupted, interruptible

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    handled = []
    with interruptible():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5.0)
        except Interrupted as stop:
            for again in (signal.SIGTERM, signal.SIGINT):
                os.kill(os.getpid(), again)
            time.sleep(0.1)
            handled.append(stop.signum)
    assert handled == [signal.SIGTERM]
    assert {s: signal.getsignal(s) for s in before} == before


def test_the_last_line_waits_for_its_reader():
    """What a pipe holds that its reader (mpiexec's proxy) has not read yet: the rank that ends the run aborts once
    its line is read; 0 for what is not a pipe."""
    from fenics_contact.cli.signals import _unread_bytes

    read, write = os.pipe()
    try:
        os.write(write, b"interrupted by SIGTERM\n")
        assert _unread_bytes(write) == 23
        os.read(read, 100)
        assert _unread_bytes(write) == 0
    finally:
        os.close(read)
        os.close(write)
    with open(os.devnull, "w") as null:
        assert _unread_bytes(null.fileno()) == 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="abstract Unix sockets are Linux's")
def test_one_rank_of_a_host_claims_the_line(monkeypatch):
    """The ranks of one host ending a run: the first to claim the line prints it, the others do not; the claim
    ends with the process that holds it."""
    from fenics_contact.cli import signals

    monkeypatch.setattr(signals, "_rank_zero", [(socket.gethostname(), os.getpid())])
    monkeypatch.setattr(signals, "_claim", [])
    try:
        assert signals._claim_the_line() is True
        assert signals._claim_the_line() is False
    finally:
        for sock in signals._claim:
            sock.close()
    signals._claim.clear()
    assert signals._claim_the_line() is True  # (the holder is gone)
    signals._claim.pop().close()


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (from /proc), nearest first."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, ValueError, IndexError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = [], [pid]
    while todo:
        kids = children.get(todo.pop(0), [])
        found += kids
        todo += kids
    return found


def _rank_processes(pid: int) -> list[int]:
    """The ranks started by the mpiexec ``pid``: its Python descendants."""
    ranks = []
    for p in _descendants(pid):
        with contextlib.suppress(OSError):
            if "python" in Path(f"/proc/{p}/exe").resolve().name:
                ranks.append(p)
    return ranks


def _ends(pid: int, timeout: float = 30.0) -> bool:
    """True once the process ``pid`` is gone (or a zombie) within ``timeout`` s: no rank is left running."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return True
        except (OSError, IndexError):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.slow
@pytest.mark.parametrize("target", ["every rank", "one rank"])
def test_sigterm_under_mpi_never_hangs(tmp_path, target):
    """SIGTERM to `mpiexec -n 2 fenics-contact run` (its process group, as a batch system sends it: mpiexec passes it
    on to every rank, each in a session of its own; or one rank, as `kill PID` does) at random times from start-up
    into the solve: every run ends with exit 143 and the one line, exactly once (besides MPICH's lines on
    MPI_Abort), nothing written.  What each part holds off: a rank that stopped alone would leave the other
    waiting in a collective operation for ever; a line still in the pipe to mpiexec when its rank aborts would be
    lost (mpiexec exits on the abort: a few aborts in a hundred without the wait); two ranks signalled together could
    both print it.  Eight runs of each, about 10 s each."""
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
    script = shutil.which("fenics-contact", path=str(Path(sys.executable).parent))
    if mpiexec is None or script is None:
        pytest.skip("needs mpiexec and the fenics-contact console script beside the Python")
    draw = random.Random(f"sigterm {target}")
    for trial in range(8):
        out = tmp_path / f"run{trial}"
        proc = subprocess.Popen(
            [mpiexec, "-n", "2", script, "run", "--h", "32", "--H", "4", *LONG_RUN[4:], "--out", str(out)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=dict(os.environ, OMP_NUM_THREADS="1"),
            start_new_session=True,
        )
        try:
            time.sleep(draw.uniform(1.0, 8.0))  # start-up (the imports), the mesh, the iteration
            ranks = _rank_processes(proc.pid)
            if target == "every rank" or not ranks:  # (no rank started yet: mpiexec and its group)
                os.killpg(proc.pid, signal.SIGTERM)
            else:
                os.kill(draw.choice(ranks), signal.SIGTERM)
            _, err = proc.communicate(timeout=60)  # (a hang: TimeoutExpired)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        assert proc.returncode == 143, err
        # MPICH's own lines on the abort: the rank's "application called MPI_Abort" and mpiexec's "[mpiexec@host] ..."
        lines = [
            line
            for line in outcome_lines(err)
            if "application called MPI_Abort" not in line and not line.startswith("[mpiexec@")
        ]
        assert len(lines) == 1 and lines[0].startswith("interrupted by SIGTERM"), err
        assert not out.exists(), "nothing written"
        # a rank that ended the run while rank 0 waited in a collective operation leaves the staging directory (as
        # kill -9 does): of a process that is gone, so the next run beside it removes it
        for left in tmp_path.iterdir():
            match = _STAGING.match(left.name)
            assert match and _ends(int(match["pid"])), left
