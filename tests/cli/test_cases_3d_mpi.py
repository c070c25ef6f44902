"""3D case files on two ranks: the fibre block's material groups (cell midpoints gathered from every rank) and a
sphere's load steps give the serial command's numbers."""

from pathlib import Path

import numpy as np
import pytest
from mpi_jobs import run_summary, serial_cli

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.cli import main

pytestmark = pytest.mark.mpi

CASES = Path(__file__).parents[2] / "cases"


def test_fibre_case_on_two_ranks_matches_serial(shared_tmp_path):
    args = ["run", "--no-plots", "--case", str(CASES / "fibres_3d.toml"), "--set", "mesh.h=4"]
    args += ["--set", "mesh.contact-size=0.1", "--set", "obstacle.indentation=[0.006, 0.012]", "--reference"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(shared_tmp_path / "parallel")]) == 0
    parallel = run_summary(shared_tmp_path / "parallel")
    assert parallel["mpi_ranks"] == 2 and serial["mpi_ranks"] == 1
    assert parallel["e_u"] < 1e-8 and parallel["converged"]
    forces = [[step["force"] for step in s["force_indentation"]["steps"]] for s in (serial, parallel)]
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-7)


def test_algorithm_3_on_a_3d_case_on_two_ranks_matches_serial(shared_tmp_path):
    """The sphere case with its coarse cubes (primal-ms) and a load step: the serial run's forces and error."""
    args = ["run", "--no-plots", "--case", str(CASES / "sphere_3d.toml"), "--method", "primal-ms"]
    args += ["--set", "mesh.refinement=0.2", "--set", "obstacle.indentation=[0.005, 0.01]", "--reference"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(shared_tmp_path / "parallel")]) == 0
    parallel = run_summary(shared_tmp_path / "parallel")
    assert parallel["mpi_ranks"] == 2 and parallel["converged"]
    assert parallel["dofs"]["omega1_ms"] == serial["dofs"]["omega1_ms"]
    assert parallel["e_u"] == pytest.approx(serial["e_u"], rel=1e-8)
    forces = [[step["force"] for step in s["force_indentation"]["steps"]] for s in (serial, parallel)]
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-10)
