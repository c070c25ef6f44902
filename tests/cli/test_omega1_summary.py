"""The summary of a ``primal-ms`` run reports ``omega1_check``: Algorithm 3's multiscale Ω₁ against the fine Ω₁
solve for the run's interface data (``result.omega1_check``), for the run and for each load step."""

import json

import numpy as np
import pytest
from layered_case import write_layered_case
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.cli import main
from fenics_contact.multiscale.cem import CEMOptions

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="compares with a serial solve")


def _summary(out) -> dict:
    return json.loads((out / "summary.json").read_text())


def test_the_run_reports_the_check_of_its_solve(tmp_path):
    """The summary's value is the one the API's Algorithm 3 computes on the same problem and options."""
    out = tmp_path / "run"
    assert (
        main(
            ["run", "--method", "primal-ms", "--h", "16", "--H", "4", "--layers", "2", "--no-plots", "--out", str(out)]
        )
        == 0
    )
    summary = _summary(out)
    problem = fc.models.model_1().on(fc.unit_square(16, 4))
    result = fc.solve(problem, "primal-ms", cem=CEMOptions(layers=2))
    assert summary["omega1_check"] == pytest.approx(result.omega1_check, rel=1e-6)
    assert 0 < summary["omega1_check"] < 1


def test_every_load_step_reports_its_check(tmp_path):
    """Once in contact the layered problem is linear in the depth, so the interface data scale with it and the
    relative check is the same at every step; the last step is the run's own solve."""
    out = tmp_path / "run"
    case = write_layered_case(tmp_path)
    assert main(["run", "--case", str(case), "--method", "primal-ms", "--no-plots", "--out", str(out)]) == 0
    summary = _summary(out)
    checks = np.array([step["omega1_check"] for step in summary["force_indentation"]["steps"]])
    assert checks.shape == (3,) and np.all(checks > 0)
    assert np.ptp(checks) <= 1e-6 * checks[0]
    assert summary["omega1_check"] == pytest.approx(checks[-1], rel=1e-6)


def test_other_methods_report_none(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "--method", "primal", "--h", "16", "--H", "4", "--no-plots", "--out", str(out)]) == 0
    assert _summary(out)["omega1_check"] is None
