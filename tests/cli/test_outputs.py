"""Outputs whole or absent: a reused --out holds exactly one run, a failed or killed run leaves it as it was,
stale temporaries are cleaned (ranks of an MPI run writing one directory together: test_cli_mpi.py)."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from outcome import run_files
from user_meshes import build_columns

from fenics_contact.cli import main
from fenics_contact.io import RUN_MARKER, OutputDirectory
from fenics_contact.multiscale.cache import OfflineCache, remove_stale_temporaries

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own processes")

SMALL = ["--h", "16", "--H", "4"]
RUN_FILES = {"fields.pvd", "fields", "contact.pvd", "contact", "summary.json", "summary.md", RUN_MARKER}


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _snapshot(directory: Path) -> dict[str, bytes]:
    return run_files(directory)


@pytest.mark.slow
def test_a_reused_out_holds_exactly_one_run(tmp_path):
    out = tmp_path / "run"
    assert main(["run", *SMALL, "--method", "mixed", "--out", str(out)]) == 0
    assert {"sigma.bp", "u.bp", "stress.png", "E.png"} <= {p.name for p in out.iterdir()}
    assert main(["run", *SMALL, "--model", "2", "--no-plots", "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == RUN_FILES  # nothing of the mixed run is left
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["method"], summary["model"]) == ("primal", 2)
    assert [p.name for p in tmp_path.iterdir()] == ["run"], "no staging or old directory is left beside it"


def test_only_a_directory_holding_just_a_runs_output_is_replaced(tmp_path):
    """A run's directory is replaced by the next run; once the user adds a file to it, or a directory holds a copied
    summary.json beside notes, it is the user's: refused (exit 2), nothing deleted."""
    out = tmp_path / "run"
    assert main(["run", *SMALL, "--no-plots", "--out", str(out)]) == 0
    assert main(["run", *SMALL, "--no-plots", "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == RUN_FILES
    (out / "notes.txt").write_text("mine")
    assert main(["run", *SMALL, "--no-plots", "--out", str(out)]) == 2
    assert (out / "notes.txt").read_text() == "mine" and {p.name for p in out.iterdir()} == RUN_FILES | {"notes.txt"}
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    (foreign / "summary.json").write_text((out / "summary.json").read_text())
    assert main(["run", *SMALL, "--no-plots", "--out", str(foreign)]) == 2
    assert {p.name for p in foreign.iterdir()} == {"notes.txt", "summary.json"}


def test_a_failed_run_leaves_the_previous_results_intact(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", *SMALL, "--no-plots", "--out", str(out)]) == 0
    before = _snapshot(out)
    # a numerical failure after the mesh and the staging directory exist
    assert main(["run", *SMALL, "--no-plots", "--E-high", "1e100", "--out", str(out)]) == 4
    assert capsys.readouterr().err.startswith("numerical failure:")
    assert _snapshot(out) == before
    # a user mesh refused after it was read
    bad = build_columns(tmp_path / "bad.msh", gamma=("v1",))
    assert main(["run", "--mesh", str(bad), "--no-plots", "--out", str(out)]) == 2
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.msh", "run"]


def test_staging_left_by_a_killed_run_is_removed(tmp_path):
    host = socket.gethostname()
    dead = tmp_path / f".fenics-contact-{_dead_pid()}@{host}-abc.partial"
    alive = tmp_path / f".fenics-contact-{os.getppid()}@{host}-def.partial"  # a live process: kept
    for d in (dead, alive):
        d.mkdir()
        (d / "fields.h5").write_bytes(b"truncated")
    with OutputDirectory(tmp_path / "run") as output:
        assert output.path.parent == tmp_path and output.path.name.endswith(".partial")
        assert not dead.exists() and alive.exists()
    assert not output.path.exists(), "an uncommitted staging directory is removed"
    assert not (tmp_path / "run").exists()
    shutil.rmtree(alive)


def test_stale_cache_temporaries_are_removed(tmp_path):
    host = socket.gethostname()
    dead = tmp_path / f"cem_x.abc.pid{_dead_pid()}@{host}.npz.tmp"
    live = tmp_path / f"cem_x.def.pid{os.getpid()}@{host}.npz.tmp"
    legacy_old, legacy_new = tmp_path / "tmp1.npz.tmp", tmp_path / "tmp2.npz.tmp"
    for p in (dead, live, legacy_old, legacy_new):
        p.write_bytes(b"partial")
    os.utime(legacy_old, (time.time() - 7200, time.time() - 7200))
    assert sorted(remove_stale_temporaries(tmp_path)) == sorted([dead, legacy_old])
    assert live.exists() and legacy_new.exists()


_KILLED_SAVE = """
import os, signal, sys
import numpy as np
import fenics_contact
from fenics_contact.multiscale import cache
from fenics_contact.multiscale.cache import OfflineCache

class Cache(OfflineCache):
    prefix = "test"
    @staticmethod
    def pack(obj):
        return {"a": obj}

write_array = np.lib.format.write_array

def write_then_die(fh, arr, **kwargs):
    write_array(fh, arr, **kwargs)  # the first array reaches the file, then kill -9 in the middle of the save
    fh.flush()
    os.kill(os.getpid(), signal.SIGKILL)

np.lib.format.write_array = write_then_die  # what cache.write_npz streams each array with
Cache(sys.argv[1]).save("k" * 40, np.ones(1 << 18))
"""


def test_kill_9_during_a_cache_save_leaves_a_temporary_that_the_next_use_removes(tmp_path):
    proc = subprocess.run([sys.executable, "-c", _KILLED_SAVE, str(tmp_path)], capture_output=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    orphans = list(tmp_path.glob("*.npz.tmp"))
    assert len(orphans) == 1 and orphans[0].stat().st_size > 1 << 20

    class Cache(OfflineCache):
        prefix = "test"

    assert Cache(tmp_path).load("k" * 40) == (None, "missing")
    assert not list(tmp_path.glob("*.npz.tmp"))


@pytest.mark.slow
def test_peak_rss_is_in_bytes():
    """``io.peak_rss_bytes`` (the benchmarks' peak memory) counts bytes: touching 300 MB more than the process
    ever held raises it by at least that much (a figure left in KiB or MiB would be 10³–10⁶ times too small)."""
    from fenics_contact.io import peak_rss_bytes

    before = peak_rss_bytes()
    extra = np.ones(before // 8 + 300_000_000 // 8)  # more than the old peak, so the peak must move
    after = peak_rss_bytes()
    assert after >= extra.nbytes - 50_000_000  # the array alone, up to the interpreter's share of the old peak
    assert after < 10 * (extra.nbytes + before)
