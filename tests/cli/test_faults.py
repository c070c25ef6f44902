"""Faults around a run: stdout closed or full, SIGTERM while starting up, --out on a mount point or a full file
system, an unusable cache of compiled forms, a reference solution that vanishes.  Each ends with its exit code
and one line on stderr (or a warning and a complete run), never a traceback or lost results."""

import contextlib
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI
from outcome import outcome_lines, run_files

import fenics_contact.cli.solve as solve_module
from fenics_contact.cli import EXIT_WRITE, main
from fenics_contact.io import OutputDirectory, write_summary

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

TINY = ["--h", "8", "--H", "2", "--no-plots"]
#: the console script's own code path (pyproject: fenics-contact = fenics_contact.launch:main)
LAUNCH = "import sys; from fenics_contact.launch import main; sys.exit(main(sys.argv[1:]))"
#: a bar unloaded by its load steps: the wall pressed in by 0.01, then back to flush (u = 0 at the last step)
UNLOADED = """[mesh]
builtin = "unit-square"
h = 8
H = 2
clamped = ["left"]
[material]
E = 1.0
nu = 0.3
[obstacle]
shape = "plane"
point = [1.0, 0.0]
normal = [-1.0, 0.0]
indentation = [0.01, 0.0]
"""


def _env(**extra: str) -> dict[str, str]:
    return dict(os.environ, OMP_NUM_THREADS="1", **extra)


@contextlib.contextmanager
def _tmpfs(path: Path, size: str):
    """A tmpfs of ``size`` mounted at ``path`` (root only; skipped elsewhere), unmounted after."""
    path.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=True)


@pytest.mark.parametrize("stdout", ["closed pipe", "/dev/full"])
def test_stdout_that_cannot_be_written_stops_the_log_not_the_run(tmp_path, stdout):
    """`fenics-contact run ... | head -1`, or stdout on a full device: the run goes on and writes its results (exit
    0), with one warning on stderr; no traceback, no "PETSC ERROR" (PETSc's SIGPIPE handler is off)."""
    if stdout == "/dev/full" and not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    out = tmp_path / "run"
    command = [sys.executable, "-c", LAUNCH, "run", *TINY, "--out", str(out)]
    if stdout == "closed pipe":
        read, write = os.pipe()
        os.close(read)  # (head -1 has read its line and gone)
        proc = subprocess.run(command, stdout=write, stderr=subprocess.PIPE, text=True, env=_env(), timeout=300)
        os.close(write)
    else:
        with open("/dev/full", "w") as full:
            proc = subprocess.run(command, stdout=full, stderr=subprocess.PIPE, text=True, env=_env(), timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: stdout cannot be written"), proc.stderr
    assert json.loads((out / "summary.json").read_text())["converged"] is True


def test_sigterm_while_starting_up_is_143_and_one_line(tmp_path):
    """SIGTERM while the command line is imported (PETSc initialised on the way): exit 143 and the one line, not
    PETSc's signal handler (seven "PETSC ERROR" lines, MPI_Abort, exit 15)."""
    out, marker = tmp_path / "run", tmp_path / "imported"
    code = (
        "import sys, pathlib, fenics_contact; pathlib.Path(sys.argv[1]).touch(); "
        "from fenics_contact.launch import main; sys.exit(main(sys.argv[2:]))"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code, str(marker), "run", *TINY, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    try:
        deadline = time.monotonic() + 120
        while not marker.exists():
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.01)
        time.sleep(0.5)  # inside main(): the import of the command line (PETSc among it) is under way
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == ["interrupted by SIGTERM while starting up: nothing was written"], err
    assert not out.exists()


def test_unusable_cache_of_compiled_forms_is_bad_input(tmp_path):
    """XDG_CACHE_HOME where no directory can be made: exit 2 and one line naming it, before any form is compiled
    (FFCx failed with a traceback)."""
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-c", LAUNCH, "run", *TINY, "--out", str(out)],
        capture_output=True,
        text=True,
        env=_env(XDG_CACHE_HOME="/proc/fenics-contact-cache", MPLCONFIGDIR=str(tmp_path)),
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    assert outcome_lines(proc.stderr) == [
        "error: the cache of compiled forms /proc/fenics-contact-cache/fenics cannot be used: No such file or "
        "directory; point XDG_CACHE_HOME (or cache_dir in a dolfinx_jit_options.json) to a writable directory"
    ], proc.stderr
    assert not out.exists()


def test_an_existing_out_is_filled_in_place(tmp_path):
    """An existing --out (empty, or an earlier run's) is the same directory after the run, not a new one renamed
    into its place: a mount point or a directory owned by someone else can be --out."""
    out = tmp_path / "run"
    out.mkdir()
    inode = out.stat().st_ino
    assert main(["run", *TINY, "--out", str(out)]) == 0
    assert main(["run", *TINY, "--method", "mixed", "--out", str(out)]) == 0
    assert out.stat().st_ino == inode
    assert {"sigma.bp", "u.bp", "summary.json"} <= {p.name for p in out.iterdir()}
    assert not [p for p in out.iterdir() if p.name.startswith(".fenics-contact-") and p.is_dir()]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_out_on_a_mount_point(tmp_path):
    """--out a mount point (a Docker volume): rename(2) of a mount point fails (EBUSY), so it is filled in place."""
    with _tmpfs(tmp_path / "volume", "20m") as volume:
        assert main(["run", *TINY, "--out", str(volume)]) == 0
        assert main(["run", *TINY, "--out", str(volume)]) == 0  # the earlier run replaced
        assert json.loads((volume / "summary.json").read_text())["converged"] is True


def test_too_little_space_is_refused_before_the_solve(tmp_path, capsys):
    """A file system without room for the results: exit 5 and one line before the solve, nothing written (ADIOS2
    aborted the process on ENOSPC, HDF5 on an assertion)."""
    with _tmpfs(tmp_path / "small", "200k") as small:
        code = main(["run", "--h", "32", "--H", "4", "--method", "mixed", "--no-plots", "--out", str(small / "run")])
        err = capsys.readouterr().err
        assert code == EXIT_WRITE, err
        lines = outcome_lines(err)
        assert len(lines) == 1 and "the results need about" in lines[0] and "free" in lines[0], err
        assert list(small.iterdir()) == []


def test_a_failed_write_is_exit_5_and_leaves_out_as_it_was(tmp_path, capsys, monkeypatch):
    """A write that fails after the solve (ENOSPC while the plots or the summary are written): exit 5, one line
    naming the file, the earlier results in --out untouched, no staging directory left."""
    out = tmp_path / "run"
    assert main(["run", *TINY, "--out", str(out)]) == 0
    before = run_files(out)
    capsys.readouterr()

    def full_disk(directory, summary, comm):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(Path(directory) / "summary.json"))

    monkeypatch.setattr(solve_module, "write_summary", full_disk)
    assert main(["run", *TINY, "--model", "2", "--out", str(out)]) == EXIT_WRITE
    assert outcome_lines(capsys.readouterr().err) == [
        f"error: --out {out}: could not write the results (summary.json): No space left on device; {out} left as it was"
    ]
    assert run_files(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_check_space_compares_with_the_free_space(tmp_path):
    with OutputDirectory(tmp_path / "run") as output:
        output.check_space(1.0)
        with pytest.raises(OSError, match="need about"):
            output.check_space(1e30)


def test_non_finite_summary_values_are_null(tmp_path):
    """JSON has no inf or NaN: they are written as null (a relative error against a vanishing reference)."""
    write_summary(tmp_path, {"e_u": float("inf"), "steps": [{"e": float("nan"), "f": 1.5}]}, MPI.COMM_SELF)
    summary = json.loads((tmp_path / "summary.json").read_text(), parse_constant=pytest.fail)
    assert summary == {"e_u": None, "steps": [{"e": None, "f": 1.5}]}


@pytest.mark.parametrize("method", ["mixed", "mixed-ms"])
def test_reference_of_a_vanishing_solution(tmp_path, method):
    """--reference where the run's solution vanishes (the last load step unloads the body): the relative errors
    are 0/0 = 0 (hybrid and reference both exactly zero), not a ZeroDivisionError."""
    (tmp_path / "case.toml").write_text(UNLOADED)
    out = tmp_path / "run"
    args = ["--layers", "1"] if method == "mixed-ms" else []
    case = ["--case", str(tmp_path / "case.toml")]
    assert main(["run", *case, "--method", method, *args, "--reference", "--no-plots", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["e_u"] == 0.0 and summary["e_sigma"] == 0.0
