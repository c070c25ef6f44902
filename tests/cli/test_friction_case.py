"""Case files with friction: ``[friction]`` and ``[obstacle] motion`` read, refused when wrong, and a sliding path
run through the command line with its summary."""

import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.cli import main
from fenics_contact.errors import InputError
from fenics_contact.problem.case import load_case
from fenics_contact.problem.friction import Friction

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

SLIDE = """
description = "a block pressed by a plane and dragged along it"
[mesh]
builtin = "unit-square"
h = 8
H = 4
clamped = ["left"]
[material]
E = 1.0
nu = 0.3
[obstacle]
shape = "plane"
point = [1.0, 0.0]
normal = [-1.0, 0.0]
{obstacle}
[friction]
{friction}
[run]
tol = 1e-10
"""
MOTION = "motion = [[-0.01, 0.0], [-0.01, 0.01], [-0.01, 0.05]]"


def _case(tmp_path: Path, obstacle: str = MOTION, friction: str = 'law = "coulomb"\nmu = 0.3') -> Path:
    path = tmp_path / "slide.toml"
    path.write_text(SLIDE.format(obstacle=obstacle, friction=friction))
    return path


def test_friction_and_motion_are_read(tmp_path):
    case = load_case(_case(tmp_path))
    assert case.friction == Friction("coulomb", mu=0.3)
    assert case.obstacle.motions == ((-0.01, 0.0), (-0.01, 0.01), (-0.01, 0.05))
    tresca = load_case(_case(tmp_path, friction='law = "tresca"\nthreshold = 0.01\nstiffness-ratio = 2.0'))
    assert tresca.friction == Friction("tresca", threshold=0.01, stiffness_ratio=2.0)


@pytest.mark.parametrize(
    "obstacle, friction, message",
    [
        (MOTION, 'law = "dry"', "friction.law"),
        (MOTION, 'law = "coulomb"', "friction.mu is required"),
        (MOTION, 'law = "coulomb"\nmu = 0.3\nthreshold = 1.0', "unknown key 'friction.threshold'"),
        (MOTION, 'law = "tresca"\nthreshold = -1.0', "Tresca threshold"),
        ("motion = []", 'law = "coulomb"\nmu = 0.3', "obstacle.motion"),
        ("motion = [[0.0, 0.0]]\nindentation = 0.01", 'law = "coulomb"\nmu = 0.3', "one of the two"),
    ],
)
def test_bad_friction_cases_are_refused(tmp_path, obstacle, friction, message):
    with pytest.raises(InputError, match=message):
        load_case(_case(tmp_path, obstacle, friction))


def test_a_sliding_case_runs(tmp_path):
    """Algorithm 1 through the command line: the last step slides (no stick node, tangential force μ times the
    normal force), every step dissipates ≥ 0, and the summary's friction entry is the path's last step."""
    out = tmp_path / "out"
    assert main(["run", "--no-plots", "--case", str(_case(tmp_path)), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    steps = summary["sliding"]["steps"]
    assert len(steps) == 3 and all(s["converged"] for s in steps)
    assert all(s["dissipation"] >= 0.0 for s in steps) and summary["sliding"]["dissipation"] > 0.0
    last = steps[-1]
    assert last["stick_nodes"] == 0 and last["slip_nodes"] > 0
    assert abs(np.hypot(*last["tangential_force"]) / (0.3 * last["normal_force"]) - 1.0) < 1e-10
    assert summary["friction"]["tangential_force"] == last["tangential_force"]
    assert (out / "fields.pvd").exists()


@pytest.mark.parametrize("method", ["mixed", "mixed-ms"])
def test_the_mixed_algorithms_run_a_sliding_case(tmp_path, method):
    """Algorithms 2 and 4 through the command line: every step converges and dissipates ≥ 0, the last one slides
    along y."""
    out = tmp_path / "out"
    args = ["run", "--no-plots", "--case", str(_case(tmp_path)), "--method", method, "--out", str(out)]
    assert main(args) == 0
    steps = json.loads((out / "summary.json").read_text())["sliding"]["steps"]
    assert all(s["converged"] for s in steps) and all(s["dissipation"] >= 0.0 for s in steps)
    assert steps[-1]["slip_nodes"] > 0 and abs(steps[-1]["tangential_force"][0]) < 1e-12


def test_check_mesh_lets_every_method_run_friction(tmp_path, capsys):
    assert main(["check-mesh", "--case", str(_case(tmp_path))]) == 0
    out = capsys.readouterr().out
    assert all(f"{m} can run" in out for m in ("primal", "mixed", "primal-ms", "mixed-ms")), out
