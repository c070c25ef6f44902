"""A two-body case with ``[friction]``: the shipped ``cases/fault_sliding.toml`` (layered blocks across a fault,
pressed, then sheared until the upper block slides) run from the command line.

* every load step's summary is the API's frictional path (the state carried from step to step);
* the last step slides: tangential force = μ × normal force, every slave node slipping; dissipation ≥ 0 per
  step, the run's the sum; the forces on the two sides balance;
* Algorithm 1 (``--method primal``) gives the monolithic path's forces and stick/slip counts;
* a bad ``[friction]`` table is refused with the key named (exit 2).
"""

import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.cli import main
from fenics_contact.problem.case import load_case

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body friction runs on one process")

CASE = Path(__file__).parents[2] / "cases" / "fault_sliding.toml"
MU = 0.6


def _run(out: Path, *args: str) -> dict:
    assert main(["run", "--case", str(CASE), "--no-plots", "--out", str(out), *args]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def monolithic(tmp_path_factory) -> dict:
    return _run(tmp_path_factory.mktemp("fault") / "mono")


def test_each_step_is_the_api_path_and_the_last_slides(monolithic):
    steps = monolithic["load_steps"]["steps"]
    case = load_case(CASE)
    assert monolithic["case"]["friction"] == {"law": "coulomb", "mu": MU, "stiffness-ratio": 1.0}
    built = case.build_mesh()
    state = None
    for k, row in enumerate(steps):
        solution = fc.solve(case.problem(built, step=k), "primal-monolithic", state=state)
        state = solution.state
        fs, fm = np.asarray(row["force_slave"]), np.asarray(row["force_master"])
        assert np.allclose(fs, solution.forces[0], rtol=1e-10, atol=1e-10 * np.linalg.norm(fs))
        assert np.linalg.norm(fs + fm) <= 1e-13 * np.linalg.norm(fs)
        assert row["force_balance"] < 1e-13
        assert row["friction"]["dissipation"] >= 0.0
        assert row["friction"]["slip_nodes"] == np.count_nonzero(solution.friction.slip)
    first, last = steps[0]["friction"], steps[-1]["friction"]
    assert first["slip_nodes"] == 0 and first["stick_nodes"] > 0  # pressed: the faces stick
    assert last["stick_nodes"] == 0 and last["slip_nodes"] > 0  # sheared past sliding
    assert abs(last["tangential_force"][0]) == pytest.approx(MU * last["normal_force"], rel=1e-10)
    assert monolithic["dissipation"] == pytest.approx(sum(s["friction"]["dissipation"] for s in steps), rel=1e-12)
    assert monolithic["dissipation"] > 0.0


def test_algorithm_1_gives_the_monolithic_path(tmp_path, monolithic):
    hybrid = _run(tmp_path / "a1", "--method", "primal")
    for row, mono in zip(hybrid["load_steps"]["steps"], monolithic["load_steps"]["steps"], strict=True):
        assert row["converged"] and row["iterations"] <= 8
        fs, ref = np.asarray(row["force_slave"]), np.asarray(mono["force_slave"])
        assert np.linalg.norm(fs - ref) <= 1e-8 * np.linalg.norm(ref)
        assert row["friction"]["slip_nodes"] == mono["friction"]["slip_nodes"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--set", 'friction.law="viscous"'], "friction.law"),
        (["--set", "friction.threshold=1.0"], "friction.threshold"),
        (["--set", "friction.mu=-0.1"], "the Coulomb coefficient mu must be a finite number >= 0"),
    ],
    ids=["law", "threshold-with-coulomb", "negative-mu"],
)
def test_a_bad_friction_table_is_refused(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main(["run", "--case", str(CASE), "--no-plots", "--out", str(out), *args]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_check_mesh_reports_the_friction_law(capsys):
    assert main(["check-mesh", "--case", str(CASE)]) == 0
    out = capsys.readouterr().out
    assert "coulomb friction, mu = 0.6 on the relative slip" in out
    assert "primal-ms can run" in out and "primal-ms: coarse squares of side 5 in each bulk" in out
