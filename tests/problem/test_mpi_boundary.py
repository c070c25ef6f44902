"""Boundary conditions and obstacles in the primal solves give the serial answer under ``mpiexec -n 2``."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from mpi_jobs import mpiexec as _mpiexec

SCRIPT = Path(__file__).with_name("mpi_boundary_check.py")
pytestmark = [pytest.mark.mpi, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own MPI job")]


def _run(prefix: list[str]) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run([*prefix, sys.executable, str(SCRIPT)], capture_output=True, text=True, env=env,
                          timeout=600)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    line = next(row for row in proc.stdout.splitlines() if row.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


@pytest.mark.skipif(_mpiexec() is None, reason="no mpiexec")
def test_two_ranks_match_serial_with_boundary_conditions_and_obstacles():
    serial = _run([])
    parallel = _run([_mpiexec(), "-n", "2"])
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    assert parallel["force"] == pytest.approx(serial["force"], rel=1e-10)
    assert parallel["l2"] == pytest.approx(serial["l2"], rel=1e-10)
    assert parallel["alg1_iterations"] == serial["alg1_iterations"] and parallel["alg1_e_u"] < 1e-8
    assert parallel["newton_converged"] and parallel["newton_steps"] == serial["newton_steps"] <= 8
    assert parallel["newton_e_u"] < 1e-10 and serial["newton_e_u"] < 1e-10
    assert np.allclose(parallel["hertz_forces"], serial["hertz_forces"], rtol=1e-10)
    assert np.allclose(parallel["hertz_zone"], serial["hertz_zone"], atol=1e-12)
