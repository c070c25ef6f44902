"""The monolithic solve and Algorithm 1 give the serial answer under ``mpiexec -n 2``."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from mpi_jobs import mpiexec as _mpiexec, run_result

SCRIPT = Path(__file__).with_name("mpi_check.py")
pytestmark = [pytest.mark.mpi, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own MPI job")]


def _run(prefix: list[str], *args: str) -> dict:
    return run_result(SCRIPT, prefix, *args, timeout=600)


@pytest.mark.skipif(_mpiexec() is None, reason="no mpiexec")
@pytest.mark.parametrize("model", ["1", "2"])
def test_two_ranks_match_serial(model):
    serial = _run([], "32", "8", model)
    parallel = _run([_mpiexec(), "-n", "2"], "32", "8", model)
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    assert parallel["newton_steps"] == serial["newton_steps"]
    assert parallel["active_sizes"] == serial["active_sizes"]
    assert parallel["iterations"] == serial["iterations"]
    assert np.allclose(parallel["active_set"], serial["active_set"], rtol=0, atol=1e-12)
    assert np.allclose(serial["active_set"], serial["ref_active_set"], rtol=0, atol=1e-12)
    for key in ("ref_norm", "hybrid_norm"):
        assert abs(parallel[key] - serial[key]) <= 1e-10 * serial[key], key
    assert np.allclose(parallel["rel_changes"], serial["rel_changes"], rtol=1e-6, atol=1e-12)
    assert np.allclose(parallel["sigma_c"], serial["sigma_c"], rtol=0, atol=1e-10 * np.abs(serial["sigma_c"]).max())
    assert serial["e_u"] < 1e-6 and parallel["e_u"] < 1e-6


@pytest.mark.skipif(_mpiexec() is None, reason="no mpiexec")
def test_two_ranks_match_serial_with_interface_newton():
    """Algorithm 1 + interface Newton on the heterogeneous strip (model 3): 2 ranks give the serial answer,
    which is the monolithic solution (Theorem 3.1), in the same number of Newton steps."""
    serial = _run([], "32", "8", "3", "newton")
    parallel = _run([_mpiexec(), "-n", "2"], "32", "8", "3", "newton")
    assert parallel["ranks"] == 2
    for run in (serial, parallel):
        assert run["converged"] and run["residuals"][-1] < 1e-10 and run["e_u"] < 1e-10, run
    assert parallel["interface_newton_steps"] == serial["interface_newton_steps"] <= 8
    assert parallel["iterations"] == serial["iterations"]
    assert abs(parallel["hybrid_norm"] - serial["hybrid_norm"]) <= 1e-10 * serial["hybrid_norm"]
    assert np.allclose(parallel["active_set"], serial["active_set"], rtol=0, atol=1e-12)
