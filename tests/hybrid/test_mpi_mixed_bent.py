"""Algorithm 2 on a bent γ distributed over two ranks (the bends' data, the facet colours and the traces gathered
across ranks) is the serial run: the same iterations, fixed point and force."""

from pathlib import Path

import pytest

from mpi_jobs import mpiexec, run_result

SCRIPT = Path(__file__).with_name("mpi_bent_check.py")


@pytest.mark.skipif(mpiexec() is None, reason="needs mpiexec")
def test_algorithm_2_on_a_bent_interface_on_two_ranks_is_the_serial_run():
    serial = run_result(SCRIPT, [], timeout=600)
    parallel = run_result(SCRIPT, [mpiexec(), "-n", "2"], timeout=900)
    assert parallel["ranks"] == 2
    for run in (serial, parallel):
        assert run["converged"] and run["residual"] < 1e-10
        assert run["e_sigma"] < 1e-8 and run["e_u"] < 1e-8
        assert abs(run["force"] - run["force_split"]) < 1e-9 * abs(run["force_split"])
    assert parallel["iterations"] == serial["iterations"]
    assert abs(parallel["force"] - serial["force"]) < 1e-10 * abs(serial["force"])
