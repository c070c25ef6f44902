"""Algorithm 1 for two bodies on two ranks (``hybrid.two_body_mpi``): both subdomains solved in parallel, the pair
reduced to the interface data and the contact rows on every rank.  On a layered pair (strata of contrast 1e3
with inclusions, non-matching meshes, an overhanging upper block) the result is the serial one (``mpiexec -n 2``,
against the same problem on ``COMM_SELF``; also on 3 ranks) to 1e-10, frictionless and along a Coulomb
press-then-shear path, in at most 8 interface Newton steps; in 3D alike; and a case file run with
``--method primal`` is the serial run, as is the fault sliding case with ``--method primal-ms``."""

from pathlib import Path

import numpy as np
import pytest
import scipy.spatial
from mpi4py import MPI
from mpi_jobs import on_every_rank, run_summary, serial_cli
from pair_problems import STRATA_PATHS, assert_serial_pair, strata_steps, tilted_pair

import fenics_contact as fc
from fenics_contact.cli import main

pytestmark = pytest.mark.mpi

CONTRAST = 1e3
CASES = Path(__file__).parents[2] / "cases"


def _path(comm: MPI.Comm, law, path) -> list:
    state, out = None, []
    for problem in strata_steps(comm, law, path, contrast=CONTRAST):
        out.append(fc.solve(problem, "primal", tol=1e-11, state=state))
        state = out[-1].state
    return out


def _vertex_error(parallel, serial) -> float:
    """max |u_parallel − u_serial| / max |u_serial| over the vertices (matched by position and body), every rank."""
    V = parallel.function_space
    n = V.dofmap.index_map.size_local
    rows = np.column_stack([V.tabulate_dof_coordinates()[:n, :2], parallel.x.array.reshape(-1, 2)[:n]])
    parts = V.mesh.comm.gather(rows, root=0)
    error = None
    if parts is not None:
        rows = np.vstack(parts)
        xs = serial.function_space.tabulate_dof_coordinates()[:, :2]
        us = serial.x.array.reshape(-1, 2)
        tree = scipy.spatial.cKDTree(xs)
        # a position on the contact faces holds a node of each body: the serial value nearest in u
        error = 0.0
        for x, u in zip(rows[:, :2], rows[:, 2:], strict=True):
            near = tree.query_ball_point(x, 1e-12)
            error = max(error, min(np.max(np.abs(u - us[j])) for j in near))
        error /= np.max(np.abs(us))
        assert rows.shape[0] == xs.shape[0]
    return on_every_rank(error)


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize(("law", "path"), **STRATA_PATHS)
def test_two_ranks_give_the_serial_algorithm_1(law, path):
    parallel, serial = _path(MPI.COMM_WORLD, law, path), _path(MPI.COMM_SELF, law, path)
    assert MPI.COMM_WORLD.size > 1
    for p, s in zip(parallel, serial, strict=True):
        assert_serial_pair(p, s, law)
        assert p.iterations <= 8
        assert _vertex_error(p.u, s.u) < 1e-10
    if law is not None:
        assert np.any(parallel[-1].friction.slip)


@pytest.mark.parametrize(
    ("case", "method"),
    [("two_blocks.toml", "primal"), ("fault_sliding.toml", "primal"), ("fault_sliding.toml", "primal-ms")],
)
def test_a_two_body_case_on_two_ranks_is_the_serial_run(shared_tmp_path, case, method):
    """Algorithm 1, and Algorithm 3 (each rank solves the serial pair, ``multiscale.pair_replica``), from a case
    file: the serial forces, strips and stick/slip at every step; the fault slides by its last step."""
    assert main(["check-mesh", "--case", str(CASES / case), "--method", method]) == 0
    args = ["run", "--case", str(CASES / case), "--method", method, "--no-plots"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    out = shared_tmp_path / "parallel"
    assert main([*args, "--out", str(out)]) == 0
    parallel = run_summary(out)
    assert parallel["mpi_ranks"] == 2 and serial["mpi_ranks"] == 1
    for p, s in zip(parallel["load_steps"]["steps"], serial["load_steps"]["steps"], strict=True):
        for key in ("force_slave", "force_master"):
            assert np.linalg.norm(np.subtract(p[key], s[key])) <= 1e-10 * np.linalg.norm(s[key])
        assert p["force_balance"] < 1e-12
        assert p["strip_cells"] == s["strip_cells"]
        if "friction" in s:
            assert p["friction"]["slip_nodes"] == s["friction"]["slip_nodes"]
    if case == "fault_sliding.toml":
        assert parallel["load_steps"]["steps"][-1]["friction"]["slip_nodes"] > 0


def test_two_ranks_give_the_serial_algorithm_1_in_three_dimensions():
    """A partial contact of two blocks in 3D, one-layer strips: the serial forces and the monolithic ones."""
    parallel = fc.solve(tilted_pair(MPI.COMM_WORLD, (5, 6), dim=3), "primal", tol=1e-11, layers=1)
    serial = fc.solve(tilted_pair(MPI.COMM_SELF, (5, 6), dim=3), "primal", tol=1e-11, layers=1)
    mono = fc.solve(tilted_pair(MPI.COMM_WORLD, (5, 6), dim=3), "primal-monolithic")
    assert parallel.converged and parallel.iterations <= 8
    assert 0 < np.count_nonzero(serial.slave.active) < serial.slave.active.size
    for fp, fs, fm in zip(parallel.forces, serial.forces, mono.forces, strict=True):
        assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
        assert np.linalg.norm(fp - fm) <= 1e-9 * np.linalg.norm(fm)
    assert parallel.force_balance() < 1e-12
