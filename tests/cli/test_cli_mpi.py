"""The command line on two ranks (``mpiexec -n 2 fenics-contact run``): rank 0 handles the directory, every rank
writes its part of the fields, and the numbers are those of the serial command (one process started by rank 0)."""

from pathlib import Path

import numpy as np
import pytest
import pyvista
from mpi4py import MPI
from mpi_jobs import on_every_rank, run_summary, serial_cli
from outcome import outcome_lines, run_files
from user_meshes import build_columns

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.cli import main

pytestmark = pytest.mark.mpi

ROOT = Path(__file__).parents[2]
CASES = ROOT / "cases"


def test_composite_case_on_two_ranks_matches_serial(shared_tmp_path):
    """Materials by group under MPI (the overlay groups read on rank 0, the subdomain centroids gathered)."""
    args = ["run", "--no-plots", "--case", str(CASES / "composite.toml"), "--set", "obstacle.indentation=0.008"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(shared_tmp_path / "parallel")]) == 0
    parallel = run_summary(shared_tmp_path / "parallel")
    assert parallel["mpi_ranks"] == 2 and serial["mpi_ranks"] == 1
    assert abs(parallel["contact_force"] - serial["contact_force"]) <= 1e-6 * serial["contact_force"]
    assert np.allclose(parallel["contact_zone"], serial["contact_zone"], rtol=0, atol=1e-12)


def test_two_ranks_write_one_directory(shared_tmp_path, capsys):
    out = shared_tmp_path / "mpi"
    stored = ROOT / "meshes" / "unit_square_n16_H4.msh"  # validated on 2 ranks
    assert main(["run", "--mesh", str(stored), "--H", "4", "--out", str(out)]) == 0
    summary = run_summary(out)
    assert summary["mpi_ranks"] == 2 and summary["converged"] is True
    assert {"E.png", "contact.png", "displacement.png", "history.png"} <= {p.name for p in out.iterdir()}
    fields = pyvista.read(out / "fields.pvd")[0]
    assert fields.n_points == 289 and fields.n_cells == 2 * 16 * 16  # both ranks' parts, 17 x 17 nodes once
    np.testing.assert_equal(
        summary["dofs"]["omega1"] + summary["dofs"]["omega2"] - summary["dofs"]["interface"], 2 * 17 * 17
    )
    # a bad mesh: exit 2, one line on stderr (rank 0), the run before untouched
    before = run_files(out)
    bad = shared_tmp_path / "bad.msh"
    if MPI.COMM_WORLD.rank == 0:
        build_columns(bad, gamma_c=("v0",), gamma_d=("b0", "b1", "b2", "t0", "t1", "t2", "v3"))
    MPI.COMM_WORLD.Barrier()
    capsys.readouterr()
    assert main(["run", "--mesh", str(bad), "--no-plots", "--out", str(out)]) == 2
    lines = on_every_rank(outcome_lines(capsys.readouterr().err))
    assert len(lines) == 1 and "not on the boundary of Omega2" in lines[0], lines
    MPI.COMM_WORLD.Barrier()
    assert all(MPI.COMM_WORLD.allgather(run_files(out) == before))
    assert sorted(p.name for p in shared_tmp_path.iterdir()) == ["bad.msh", "mpi"]
    # (the mixed method from 2 ranks: tests/fem/test_mpi_mixed.py writes the serial outputs)


@pytest.mark.parametrize("method, layers", [("primal-ms", "3"), ("mixed-ms", "2")])
def test_case_load_steps_multiscale_on_two_ranks_match_serial(shared_tmp_path, method, layers):
    """The same case's Algorithm 3 and 4 load steps on two ranks (offline phase shared out): the forces of the
    serial run (measured 6e-12 for Algorithm 3), the same iterations, every step certified."""
    args = [
        "run",
        "--no-plots",
        "--case",
        str(CASES / "composite.toml"),
        "--method",
        method,
        "--layers",
        layers,
        "--tol",
        "1e-8",
    ]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(shared_tmp_path / "parallel")]) == 0
    parallel = run_summary(shared_tmp_path / "parallel")
    for s, p in zip(serial["force_indentation"]["steps"], parallel["force_indentation"]["steps"], strict=True):
        assert abs(p["force"] - s["force"]) <= 1e-9 * abs(s["force"])
        assert p["converged"] and p["transmission_residual"] < 1e-8 and p["iterations"] == s["iterations"]


def test_mixed_ms_sliding_case_on_two_ranks_matches_serial(shared_tmp_path):
    """A press-and-drag Coulomb case with Algorithm 4 on two ranks (each holding the whole mesh, the offline phase
    of every load step's solver shared out): per step the serial forces, stick/slip counts and dissipation."""
    case = shared_tmp_path / "slide.toml"
    if MPI.COMM_WORLD.rank == 0:
        case.write_text(
            "[mesh]\nbuiltin = 'unit-square'\nh = 8\nH = 4\nclamped = ['left']\n[material]\nE = 1.0\nnu = 0.3\n"
            "[obstacle]\nshape = 'plane'\npoint = [1.0, 0.0]\nnormal = [-1.0, 0.0]\n"
            "motion = [[-0.01, 0.0], [-0.01, 0.01], [-0.01, 0.05]]\n[friction]\nlaw = 'coulomb'\nmu = 0.3\n"
            "[run]\ntol = 1e-10\n"
        )
    MPI.COMM_WORLD.Barrier()
    args = ["run", "--no-plots", "--case", str(case), "--method", "mixed-ms"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(shared_tmp_path / "parallel")]) == 0
    parallel = run_summary(shared_tmp_path / "parallel")
    steps = zip(serial["sliding"]["steps"], parallel["sliding"]["steps"], strict=True)
    for s, p in steps:
        assert p["converged"] and (p["stick_nodes"], p["slip_nodes"]) == (s["stick_nodes"], s["slip_nodes"])
        assert abs(p["normal_force"] - s["normal_force"]) <= 1e-10 * s["normal_force"]
        assert np.allclose(p["tangential_force"], s["tangential_force"], rtol=0, atol=1e-10 * s["normal_force"])
        assert abs(p["dissipation"] - s["dissipation"]) <= 1e-10 * max(abs(s["dissipation"]), 1e-300)
    assert parallel["sliding"]["steps"][-1]["slip_nodes"] > 0
