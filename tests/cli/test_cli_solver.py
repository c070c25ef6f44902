"""``--solver``: the linear solver of the primal monolithic reference, on the command line and in a case file."""

import pytest
from mpi_jobs import run_summary

from fenics_contact.cli import RunOptions, main
from fenics_contact.errors import InputError


def test_the_reference_solved_with_amg_is_the_direct_one(tmp_path):
    """Algorithm 1 on model 2 with its monolithic reference by CG + AMG and by MUMPS: the same e_u (the
    reference agrees to the Krylov tolerance), the CG iterations reported per Newton step."""
    args = ["run", "--model", "2", "--h", "16", "--H", "4", "--reference", "--no-plots"]
    assert main([*args, "--solver", "amg", "--out", str(tmp_path / "amg")]) == 0
    assert main([*args, "--out", str(tmp_path / "auto")]) == 0
    amg, auto = run_summary(tmp_path / "amg"), run_summary(tmp_path / "auto")
    assert amg["reference_linear_solver"] == "amg" and auto["reference_linear_solver"] == "direct"
    assert len(amg["reference_krylov_iterations"]) == amg["reference_newton_steps"] > 0
    assert auto["reference_krylov_iterations"] is None
    assert amg["reference_active_set"] == auto["reference_active_set"]
    assert amg["e_u"] == pytest.approx(auto["e_u"], rel=1e-4, abs=1e-9)


def test_solver_is_checked_and_refused_where_no_primal_reference_runs():
    assert RunOptions(method="primal-ms", solver="amg").reference_options() == {"solver": "amg"}
    assert RunOptions().value("solver") == "auto" and RunOptions().method_options().get("solver") is None
    with pytest.raises(InputError, match="--solver must be one of"):
        RunOptions(solver="lu")
    with pytest.raises(InputError, match="--solver does not apply to --method mixed"):
        RunOptions(method="mixed", solver="amg")
