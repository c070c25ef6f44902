"""Helpers of the MPI tests (``@pytest.mark.mpi``, run by ``mpiexec -n 2 python -m mpi4py -m pytest -m mpi``).

Each such test computes on ``COMM_WORLD`` and compares with the serial answer: the same computation on
``COMM_SELF`` (every rank computes it), or a serial command line started by rank 0.  Every value an assert reads is
the same on every rank (:func:`on_every_rank`), so a failing assert fails on all ranks at once.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

from mpi4py import MPI

__all__ = ["on_every_rank", "run_summary", "serial_cli", "serial_env"]

#: the variables through which mpiexec (MPICH's hydra) reaches its processes: a child without them is a serial run
_LAUNCHER_PREFIXES = ("PMI_", "PMIX_", "MPI_LOCAL", "HYDRA_", "OMPI_")


def on_every_rank(value, comm: MPI.Comm = MPI.COMM_WORLD):
    """Rank 0's ``value`` on every rank (the numbers a rank-0 report holds, for collective asserts)."""
    return comm.bcast(value, root=0)


def serial_env() -> dict[str, str]:
    """The environment of a serial child process of an MPI rank: one thread, not a member of the running job."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(_LAUNCHER_PREFIXES)}
    return env | {"OMP_NUM_THREADS": "1"}


def serial_cli(*args: str, timeout: float = 900) -> tuple[int, str, dict | None]:
    """``fenics-contact ARGS`` as one serial process started by rank 0: (exit code, stderr, summary.json of its
    ``--out`` or None), the same on every rank."""
    result = None
    if MPI.COMM_WORLD.rank == 0:
        proc = subprocess.run(
            [sys.executable, "-m", "fenics_contact.cli", *args],
            capture_output=True,
            text=True,
            env=serial_env(),
            timeout=timeout,
        )
        summary = None
        if "--out" in args and proc.returncode == 0:
            path = Path(args[args.index("--out") + 1]) / "summary.json"
            summary = json.loads(path.read_text()) if path.exists() else None
        result = proc.returncode, proc.stderr, summary
    return on_every_rank(result)


def run_summary(out: Path) -> dict:
    """The ``summary.json`` of a run every rank has finished (written by rank 0), the same on every rank."""
    MPI.COMM_WORLD.Barrier()
    return on_every_rank(json.loads((Path(out) / "summary.json").read_text()) if MPI.COMM_WORLD.rank == 0 else None)
