"""Algorithm 3 for two bodies (``multiscale.pair``): each body's bulk a CEM-GMsFEM space, each coupled to its own
strip by Robin data, the interface Newton method on both strips.  On a layered pair (strata of contrast 1e3 with
inclusions, non-matching meshes) the energy error against Algorithm 1 (the fine monolithic solution) falls with
the oversampling layers, the forces balance to round-off, also with tractions on the bulks; what it cannot take
is refused."""

import dataclasses

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI
from pair_problems import strata_pair

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.two_body import stiffness
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.coarse import grid_from_cells
from fenics_contact.multiscale.pair import PairMultiscaleOptions, coarse_to_fine
from fenics_contact.problem.pair import Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial (the MPI runs: test_pair_multiscale_mpi.py)")

CONTRAST = 1e3
#: the energy error falls by at least this factor per oversampling layer from m = 2 (measured 28 and 23: the
#: command in docs/theory.md)
FACTOR = 10.0


def _pair(friction=None, top=(0.0, -0.005), tractions=None, n=16) -> TwoBodyProblem:
    m = two_blocks(n, n + 4, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    return strata_pair(m, friction, top, tractions=tractions, contrast=CONTRAST)


def test_the_energy_error_falls_with_the_oversampling_layers():
    problem = _pair()
    fine = fc.solve(problem, "primal", tol=1e-11)
    mono = fc.solve(problem, "primal-monolithic")
    u0 = fine.u.x.array
    assert np.linalg.norm(u0 - mono.u.x.array) <= 1e-8 * np.linalg.norm(u0)
    K = stiffness(problem, fine.u.function_space)
    errors = []
    for layers in (2, 3, 4):
        result = fc.solve(problem, "primal-ms", H=0.125, cem=CEMOptions(layers=layers), tol=1e-10)
        assert result.converged and result.interface_newton_steps <= 8
        assert result.force_balance() < 1e-12
        d = result.u.x.array - u0
        errors.append(np.sqrt((d @ (K @ d)) / (u0 @ (K @ u0))))
    assert errors[0] > FACTOR * errors[1] > FACTOR**2 * errors[2]
    assert errors[2] < 1e-3  # (measured 4.3e-4)


def test_tractions_on_the_bulks_enter_their_multiscale_load():
    """Tractions on both bodies' sides (on bulk and strip facets), frictionless and with Coulomb friction: with
    patches covering each bulk and every local mode Algorithm 1's solution, with few modes an energy error that
    falls with the layers."""
    tractions = {T.UPPER_LEFT: (20.0, 0.0), T.LOWER_RIGHT: (0.0, 5.0)}
    for law in (None, fc.Friction("coulomb", mu=0.3)):
        problem = _pair(law, tractions=tractions, n=8)
        fine = fc.solve(problem, "primal", tol=1e-11)
        ms = fc.solve(problem, "primal-ms", H=0.25, cem=CEMOptions(layers=20, nbasis=None), tol=1e-11)
        u0 = fine.u.x.array
        assert np.linalg.norm(ms.u.x.array - u0) <= 1e-8 * np.linalg.norm(u0)
        assert ms.force_balance() < 1e-12
    problem = _pair(fc.Friction("coulomb", mu=0.3), tractions=tractions)
    fine = fc.solve(problem, "primal", tol=1e-11)
    u0 = fine.u.x.array
    K = stiffness(problem, fine.u.function_space)
    errors = []
    for layers in (2, 3):
        d = fc.solve(problem, "primal-ms", H=0.125, cem=CEMOptions(layers=layers), tol=1e-10).u.x.array - u0
        errors.append(np.sqrt((d @ (K @ d)) / (u0 @ (K @ u0))))
    assert errors[0] > FACTOR * errors[1]  # (measured 3.8e-3 and 1.1e-4)


def test_a_strip_that_reaches_the_supports():
    """The lower block also held on its sides: its strip meets Γ_D, and the γ DOFs on the supports carry no
    interface unknown.  With patches covering each bulk and every local mode Algorithm 1's solution; with the rigid
    modes an energy error that falls with the layers, each solve in at most 8 interface Newton steps."""
    m = two_blocks(16, 20, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    held = (Support(T.LOWER_BOTTOM), Support(T.LOWER_LEFT), Support(T.LOWER_RIGHT), Support(T.UPPER_TOP, (0.0, -5e-3)))
    problem = dataclasses.replace(strata_pair(m, contrast=CONTRAST), supports=held)
    fine = fc.solve(problem, "primal", tol=1e-11)
    u0 = fine.u.x.array
    every = fc.solve(problem, "primal-ms", H=0.25, cem=CEMOptions(layers=20, nbasis=None), tol=1e-11)
    assert every.converged and np.linalg.norm(every.u.x.array - u0) <= 1e-12 * np.linalg.norm(u0)  # (measured 1.3e-15)
    K = stiffness(problem, fine.u.function_space)
    errors = []
    for layers in (2, 3):
        result = fc.solve(problem, "primal-ms", H=0.125, cem=CEMOptions(layers=layers), tol=1e-10)
        assert result.converged and result.interface_newton_steps <= 8
        assert result.force_balance() < 1e-12
        d = result.u.x.array - u0
        errors.append(np.sqrt((d @ (K @ d)) / (u0 @ (K @ u0))))
    assert errors[0] > FACTOR * errors[1]  # (measured 0.25 and 9.1e-3)


def test_what_two_body_algorithm_3_cannot_take_is_refused():
    problem = _pair()
    for bad in (0.0, -1.0, True):
        with pytest.raises(InputError, match="H must be"):
            PairMultiscaleOptions(bad)
    with pytest.raises(InputError, match="takes the options"):
        fc.solve(problem, "primal-ms", H=0.125, line_search="always")


def test_coarse_to_fine_is_H_over_h_on_a_grid_of_squares():
    """Squares of side H = 1/4 over the unit square meshed by squares of side h = 1/16, each cut into two
    triangles: the ratio of ``check_bulk`` is H/h = 4."""
    msh = dmesh.create_unit_square(MPI.COMM_SELF, 16, 16)
    nodes, x = msh.geometry.dofmaps[0], msh.geometry.x
    index = np.floor(x[nodes].mean(axis=1)[:, :2] * 4).astype(np.int64) @ np.array([1, 4])
    grid = grid_from_cells(nodes, x, index, 0.25)
    assert abs(coarse_to_fine(grid, nodes, x) - 4.0) < 1e-12


def test_a_bulk_too_coarse_for_H_is_refused_before_the_solve():
    """The lower block at 4 cells across (h = 1/4, height 1/2): its strip of 2 layers leaves a bulk of two cells,
    one per coarse square of side 1/4 (no interior DOFs for their bases) and is refused, as is the bulk that the
    strips take whole at 3 cells across; with a strip of one layer the same mesh and H run."""
    problem = _pair(n=4)
    with pytest.raises(InputError, match="body 1: the coarse cells of side H = 0.25 are not larger than"):
        fc.solve(problem, "primal-ms", H=0.25, cem=CEMOptions(layers=1))
    with pytest.raises(InputError, match="body 1: the strips .2 cell layers .* take the whole body"):
        fc.solve(_pair(n=3), "primal-ms", H=0.25, cem=CEMOptions(layers=1))
    result = fc.solve(problem, "primal-ms", H=0.25, cem=CEMOptions(layers=1), layers=1, tol=1e-10)
    assert result.converged and result.force_balance() < 1e-12
