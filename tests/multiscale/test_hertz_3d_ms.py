"""Algorithm 3 on the graded Hertz block: coarse boxes that follow the mesh grading, and Hertz on its own pressure.

Unit checks: ``partition.graded_coarse_cells`` (boxes no longer than a size function at their centre and corners)
gives the Cartesian partition for a constant size, the eight ¼-cubes and seven ½-cubes of the unit cube for a size
that grows with the distance from a corner, UNRESOLVED outside the chosen cells, and clear errors for a bad size;
the Hertz block's coarse cells cover Ω₁ and grow with the distance from the contact.  Verification: on the block at
contact cells a/10 (rigid sphere, a/R = 0.1, the symmetry planes on rollers) the energy error of Algorithm 3
against the fine (monolithic) solve falls at least fourfold per oversampling layer, the rollers hold in the CEM
space, and Algorithm 3's own pressure meets Hertz as the fine solve does.
"""

import gc

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.problem.analytic import hertz_sphere_errors, hertz_sphere_model, hertz_sphere_penalty
from fenics_contact.problem.meshes3d import hertz_coarse_size, unit_cube
from fenics_contact.problem.partition import (
    UNRESOLVED,
    cartesian_coarse_cells,
    centroid_coarse_cells,
    coarse_sizes,
    graded_coarse_cells,
)
from fenics_contact.problem.tags import Subdomain

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test (its MPI twin is in test_mpi_3d)")

A, R, E, NU = 0.1, 1.0, 1.0, 0.3  # a/R = 0.1; the block 20a


@pytest.fixture(scope="module", autouse=True)
def _teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


def _same_partition(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether two coarse indices group the cells alike (whatever the numbers)."""
    pairs = np.unique(np.stack([first, second]), axis=1)
    return np.unique(pairs[0]).size == pairs.shape[1] == np.unique(pairs[1]).size


def corner_size(x: np.ndarray) -> np.ndarray:
    """max(¼, |x|): ¼ at the corner x = 0, growing with the distance from it."""
    return np.maximum(0.25, np.linalg.norm(x, axis=0))


def test_graded_boxes_of_a_constant_size_are_the_cartesian_cubes():
    msh = unit_cube(8, comm=MPI.COMM_SELF).mesh
    index = graded_coarse_cells(msh, lambda x: np.full(x.shape[1], 0.25))
    assert _same_partition(index, cartesian_coarse_cells(msh, 0.25)[0])
    assert _same_partition(index, centroid_coarse_cells(msh, 0.25)[0])
    assert np.array_equal(np.unique(index), np.arange(64))  # numbered 0, 1, … over the boxes
    square = dmesh.create_unit_square(MPI.COMM_SELF, 8, 8)  # (any dimension: squares in the plane)
    flat = graded_coarse_cells(square, lambda x: np.full(x.shape[1], 0.5))
    assert _same_partition(flat, cartesian_coarse_cells(square, 0.5)[0]) and flat.max() == 3


def test_graded_boxes_grow_with_the_size_function():
    """max(¼, |x|) on the unit cube: the root is halved (¼ at the corner), the half at the corner halved again (¼
    there), the other seven halves are no longer than the size at their corners (½ and more): 8 + 7 boxes."""
    msh = unit_cube(8, comm=MPI.COMM_SELF).mesh
    index = graded_coarse_cells(msh, corner_size)
    sizes = coarse_sizes(msh, index)
    assert index.min() == 0 and sizes.size == 15
    np.testing.assert_allclose(np.sort(sizes), [0.25] * 8 + [0.5] * 7, rtol=1e-12)
    quarter = cartesian_coarse_cells(msh, 0.25)[0]
    assert _same_partition(np.stack([index, quarter]).T @ [1, 1000], quarter)  # a coarsening of the ¼-cubes
    centroids = msh.geometry.x[msh.geometry.dofmaps[0]].mean(axis=1)
    corner = np.all(centroids < 0.5, axis=1)
    assert np.unique(index[corner]).size == 8 and np.unique(index[~corner]).size == 7


def test_graded_boxes_of_chosen_cells_and_bad_sizes():
    cm = unit_cube(4, comm=MPI.COMM_SELF)
    omega1 = cm.cell_tags.find(Subdomain.OMEGA1)
    index = graded_coarse_cells(cm.mesh, corner_size, cells=omega1)
    others = np.setdiff1d(np.arange(index.size), omega1)
    assert np.all(index[others] == UNRESOLVED) and np.all(index[omega1] >= 0)
    with pytest.raises(InputError, match="positive and finite"):
        graded_coarse_cells(cm.mesh, lambda x: np.zeros(x.shape[1]))
    with pytest.raises(InputError, match="more than"):
        graded_coarse_cells(cm.mesh, lambda x: np.full(x.shape[1], 1e-4))


def test_the_hertz_block_coarse_boxes_follow_the_grading():
    """The quarter block at a/5: every Ω₁ cell in a coarse box, the boxes small under the contact, large far
    from it, each about ``coarse`` = 4 local cell sizes across (at most the size function at its corners)."""
    h = A / 5
    problem = hertz_sphere_model(A, h, radius=R, E=E, nu=NU, comm=MPI.COMM_SELF)
    cm = problem.cm
    omega1 = cm.cell_tags.find(Subdomain.OMEGA1)
    index = cm.coarse_cell[omega1]
    assert index.min() >= 0 and np.all(np.delete(cm.coarse_cell, omega1) == UNRESOLVED)
    sizes = coarse_sizes(cm.mesh, cm.coarse_cell)
    centroids = cm.mesh.geometry.x[cm.mesh.geometry.dofmaps[0][omega1]].mean(axis=1)
    distance = np.bincount(index, weights=np.linalg.norm(centroids, axis=1)) / np.bincount(index)
    near, far = np.argmin(distance), np.argmax(distance)
    assert sizes[near] < 0.25 * sizes[far]
    assert sizes[near] <= hertz_coarse_size(A, h)(np.array([[0.0], [0.0], [-2 * A]]))[0]


@pytest.fixture(scope="module")
def hertz():
    """The Hertz block at h_c = a/10 (its graded coarse boxes), δ = 10⁻³h_c/E*, and its fine monolithic solve."""
    h = A / 10
    problem = hertz_sphere_model(A, h, radius=R, E=E, nu=NU, comm=MPI.COMM_SELF)
    delta = hertz_sphere_penalty(h, E=E, nu=NU)
    return problem, delta, fc.solve(problem, "primal-monolithic", delta=delta)


def test_algorithm_3_on_the_hertz_block(hertz):
    """a/10, 29 coarse boxes of 6 modes (174 coarse DOFs for 1,185 fine Ω₁ DOFs): the energy error against the
    fine solve 0.11, 1.1e-2, 6.0e-4 for m = 1, 2, 3 (measured), at least fourfold per layer; the rollers x = 0 and
    y = 0 hold in Ω₁; the contact radius within a contact cell of Hertz's a for every m, and from m = 2 on the
    pressure's Hertz errors those of the fine solve (within 0.1 % of p₀ and of the L² norm)."""
    problem, delta, fine = hertz
    reference = hertz_sphere_errors(fine.profile, radius=R, E=E, nu=NU, h_contact=A / 10)
    errors = []
    for m in (1, 2, 3):
        result = fc.solve(problem, "primal-ms", delta=delta, layers=m, tol=1e-9, reference=fine.u)
        assert result.converged and result.history.transmission_residual < 1e-9
        assert result.history.newton_steps <= 8
        assert result.step.cem.nbasis == 6 and result.dofs["omega1_ms"] == 6 * result.step.omega1.grid.size
        errors.append(result.step.error_energy())
        hertz_m = hertz_sphere_errors(result.profile, radius=R, E=E, nu=NU, h_contact=A / 10)
        assert abs(hertz_m.radius - hertz_m.a) <= A / 10
        if m >= 2:
            assert abs(hertz_m.centre_error - reference.centre_error) <= 1e-3
            assert abs(hertz_m.l2_error - reference.l2_error) <= 1e-3
    assert errors[0] > 4 * errors[1] > 16 * errors[2], errors
    assert errors[0] < 0.3, errors
    for part in (result.u1, result.u2):
        u = part.x.array.reshape(-1, 3)
        x = part.function_space.tabulate_dof_coordinates()
        for axis in (0, 1):  # the rollers hold in Ω₁ (the CEM space) and in Ω₂
            assert np.abs(u[np.isclose(x[:, axis], 0.0), axis]).max() <= 1e-12 * np.abs(u).max()
