"""Algorithm 1 for two deformable bodies (``hybrid.two_body``): a contact strip on each side, each bulk coupled to
it by Robin data; the fixed point is the monolithic two-body solution."""

import numpy as np
import pytest
from mpi4py import MPI
from pair_problems import hertz_cylinder_pair

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions, strip_cells
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body contact runs on one process")

H1, H2 = 0.5, 0.4


@pytest.mark.parametrize("accel", ["newton", "anderson"])
def test_algorithm_1_for_two_bodies_reaches_the_monolithic_solution(accel):
    """A strip on each side, each bulk coupled to it by Robin data on its γ: the fixed point is the monolithic
    two-body solution (vertex quadrature on γ), reached by the interface Newton method in a few evaluations of
    T and by Anderson acceleration to its tolerance; layered lower block (contrast 1e3), overhanging upper one."""
    m = two_blocks(10, 14, heights=(H1, H2), offset=0.2)
    layers = lambda x: np.where(np.floor(-x[1] / 0.1) % 2 == 0, 1e3, 1.0)  # noqa: E731
    problem = TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, layers, 0.3), Body(T.UPPER, 2.0, 0.25)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, (0.0, -0.005))),
    )
    reference = fc.solve(problem, "primal-monolithic")
    tol = 1e-10 if accel == "newton" else 1e-8
    result = fc.solve(problem, "primal", accel=accel, tol=tol)
    assert result.converged and result.transmission_residual < tol
    error = np.linalg.norm(result.u.x.array - reference.u.x.array) / np.linalg.norm(reference.u.x.array)
    assert error < 10 * tol
    assert np.allclose(result.forces[0], reference.forces[0], rtol=10 * tol, atol=0.0)
    assert result.force_balance() < 1e-12
    assert result.iterations <= (8 if accel == "newton" else 400)
    assert 0 < result.strip.size < m.mesh.topology.index_map(2).size_local


@pytest.mark.parametrize("basis", ["dual", "standard"])
@pytest.mark.parametrize("slave", ["cylinder", "block"])
def test_algorithm_1_on_the_two_body_hertz_pair(slave, basis):
    """An elastic cylinder (R = 5, E = 2, ν = 0.25) on a block (E = 1, ν = 0.3), contact cells a/10, either body
    the slave, either pressure basis: Algorithm 1 reaches the monolithic solution to 1e-8 in at most 8 interface
    Newton steps (measured with the dual basis: 6 steps, 2e-13; 5 at a/20, 6 at a/40,
    ``benchmarks/results/two_body.md``)."""
    problem = hertz_cylinder_pair(slave, refinement=0.5, basis=basis)
    reference = fc.solve(problem, "primal-monolithic")
    result = fc.solve(problem, "primal", tol=1e-8)
    assert result.converged and result.interface_newton_steps <= 8
    error = np.linalg.norm(result.u.x.array - reference.u.x.array) / np.linalg.norm(reference.u.x.array)
    assert error < 1e-8
    assert result.force_balance() < 1e-12


def test_strips_grow_by_layers_and_options_are_validated():
    m = two_blocks(6, 8, heights=(H1, H2))
    problem = TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 1.0, 0.3)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP)),
    )
    sizes = [strip_cells(problem, k).size for k in (1, 2, 3)]
    assert sizes[0] < sizes[1] < sizes[2]
    assert np.all(np.isin(strip_cells(problem, 1), strip_cells(problem, 2)))
    for bad in ({"layers": 0}, {"accel": "multigrid"}, {"alpha_scale": -1.0}, {"tol": 0.0}):
        with pytest.raises(InputError):
            TwoBodyHybridOptions(**bad)
