"""Algorithm 1 on tetrahedra: its fixed point is the monolithic solution (Theorem 3.1) on the 3D channel model,
the interface Newton reaches it in a few steps at every h, and the strip, rollers and tags of a 3D problem."""

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.meshes3d import unit_cube
from fenics_contact.problem.models import get_model
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary, Subdomain
from fenics_contact.problem.validation import validate_contact_mesh


def _hybrid_and_monolithic(problem: ContactProblem, **options):
    ref = fc.solve(problem, "primal-monolithic")
    return fc.solve(problem, "primal", reference=ref.u, **options), ref


@pytest.mark.parametrize("contrast", [1e3, 1e6])
def test_the_fixed_point_is_the_monolithic_solution_on_the_3d_channel_model(contrast):
    """Theorem 3.1 in 3D: stiff channels through γ to Γ_C, the load in Ω₁, a traction-free side and rollers;
    the interface Newton's pair is glued (certificate below tol) and equals the monolithic u_h."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(8))
    result, ref = _hybrid_and_monolithic(problem, tol=1e-9)
    assert result.converged and result.history.transmission_residual < 1e-9
    assert result.e_u <= 1e-8
    assert result.history.newton_steps <= 8
    np.testing.assert_array_equal(result.profile.active, ref.profile.active)
    assert result.profile.force == pytest.approx(ref.profile.force, rel=1e-8)
    assert 0 < np.count_nonzero(result.profile.active) < result.profile.active.size  # contact on part of Γ_C
    f = result.step.sub[0].fields.f.x.array
    assert np.abs(f).max() > 0 and np.abs(result.step.sub[1].fields.f.x.array).max() == 0  # the load is in Ω₁


@pytest.mark.slow
def test_interface_newton_steps_do_not_grow_with_h_in_3d():
    """Contrast 1e6: the interface Newton (local front resolution on the contact surface) takes at most 8 steps,
    no more at h = 1/16 than at h = 1/8, and lands on the monolithic solution at every h."""
    steps = []
    for n in (8, 12, 16):
        problem = channels_3d(E_high=1e6).on(channels_3d_mesh(n))
        result, _ = _hybrid_and_monolithic(problem, tol=1e-9)
        assert result.converged and result.e_u <= 1e-8, n
        steps.append(result.history.newton_steps)
    assert max(steps) <= 8 and steps[-1] <= steps[0], steps


def test_anderson_reaches_the_same_fixed_point_in_3d():
    """The Robin iteration itself (vertex quadrature on the surface γ, nodal E-scaled α), Anderson-accelerated."""
    problem = channels_3d(E_high=1e2).on(channels_3d_mesh(6))
    result, _ = _hybrid_and_monolithic(problem, tol=1e-8, accel="anderson")
    assert result.converged and result.history.transmission_residual < 1e-8
    assert result.e_u < 1e-6


def _box_tags(n: int):
    """The unit cube of n³ × 6 tetrahedra with only Γ_C (x = 1, tag 1) and Γ_D (x = 0, tag 2) tagged."""
    msh = dmesh.create_unit_cube(MPI.COMM_WORLD, n, n, n, dmesh.CellType.tetrahedron)
    fdim = msh.topology.dim - 1
    found = [dmesh.locate_entities_boundary(msh, fdim, lambda x, c=c: np.isclose(x[0], c)) for c in (1.0, 0.0)]
    entities = np.concatenate(found)
    values = np.concatenate([np.full(f.size, tag, dtype=np.int32) for f, tag in zip(found, (1, 2))])
    order = np.argsort(entities)
    return msh, dmesh.meshtags(msh, fdim, entities[order].astype(np.int32), values[order])


def test_the_automatic_strip_in_3d_and_algorithm_1_on_it():
    """A mesh that tags only Γ_C and Γ_D: Ω₂ is the band of cells along the contact surface, γ a surface
    between Ω₁ and Ω₂ (checked by the 3D mesh validation), and Algorithm 1 on it is the monolithic solve."""
    msh, tags = _box_tags(6)
    problem = ContactProblem.from_meshtags(
        msh,
        tags,
        contact=1,
        clamped=2,
        youngs_modulus=lambda x: np.where(x[1] > 0.5, 10.0, 1.0),
        poisson_ratio=0.3,
        load=(1.0, 0.0, -0.5),
        strip_width=0.25,
    )
    cm = problem.cm
    omega2 = cm.cell_tags.find(Subdomain.OMEGA2)
    n_owned = msh.topology.index_map(3).size_local
    centroids = dmesh.compute_midpoints(msh, 3, omega2[omega2 < n_owned])
    assert cm.comm.allreduce(float(centroids[:, 0].min(initial=1.0)), op=MPI.MIN) >= 0.75 - 1e-12
    assert cm.comm.allreduce(int(cm.facet_tags.find(Boundary.INTERFACE).size), op=MPI.SUM) > 0
    result, _ = _hybrid_and_monolithic(problem, tol=1e-9)
    assert result.converged and result.e_u <= 1e-8


def test_rollers_of_each_part_and_a_roller_on_gamma_is_refused():
    """The symmetry plane x = 0 bounds Ω₁ only, z = 0 both parts: each part takes its own; a plane through γ
    is refused."""
    cm = unit_cube(4, clamped=("ymin",), strip=0.25)
    base = dict(youngs_modulus=1.0, poisson_ratio=0.3, load=(1.0, 0.5, 0.2), mesh=cm)
    problem = ContactProblem(**base, boundary=BoundaryConditions(rollers=((0, 0.0), (2, 0.0))))
    result, ref = _hybrid_and_monolithic(problem, tol=1e-9)
    assert result.converged and result.e_u <= 1e-8
    u = result.u.x.array.reshape(-1, 3)
    X = result.u.function_space.tabulate_dof_coordinates()
    for axis in (0, 2):
        assert np.abs(u[np.isclose(X[:, axis], 0.0), axis]).max(initial=0.0) == 0.0  # u_i = 0 on its plane
    assert ref.profile.force > 0
    on_gamma = ContactProblem(**base, boundary=BoundaryConditions(rollers=((0, 0.75),)))
    with pytest.raises(InputError, match="interface γ"):
        fc.solve(on_gamma, "primal")


def test_3d_validation_finds_a_gamma_that_is_not_the_interface():
    cm = channels_3d_mesh(4)
    validate_contact_mesh(cm)
    tdim = cm.mesh.topology.dim
    # Ω₂ one cell wider: the old γ now lies inside Ω₂, the new common boundary is untagged
    midpoints = dmesh.compute_midpoints(cm.mesh, tdim, cm.cell_tags.indices)[:, 0]
    values = np.where(midpoints > 0.5, int(Subdomain.OMEGA2), int(Subdomain.OMEGA1)).astype(np.int32)
    moved = ContactMesh(
        cm.mesh,
        dmesh.meshtags(cm.mesh, tdim, cm.cell_tags.indices, values),
        cm.facet_tags,
        cm.h,
        cm.H,
        cm.coarse_cell,
        cm.neumann_names,
    )
    with pytest.raises(MeshTagError, match="gamma"):
        validate_contact_mesh(moved)


def test_the_other_methods_refuse_3d_and_name_the_3d_methods():
    problem = channels_3d().on(channels_3d_mesh(2))
    for method in ("mixed", "mixed-ms", "mixed-monolithic"):
        with pytest.raises(InputError, match="'primal'"):
            fc.solve(problem, method)
    assert get_model(4).description == channels_3d().description


def test_contact_patches_and_the_fronts_on_a_surface():
    """The Γ_C unknowns of a 3D contact surface: one patch per connected piece with the grid neighbours (edges
    and diagonals); the windows of the local front resolution are the nodes within w − 1 rings of a front."""
    from fenics_contact.hybrid.fronts import LocalFronts, contact_chains, contact_patches

    y, z = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    face = np.column_stack([np.ones(y.size), y.ravel(), z.ravel()]) * 0.1
    far = face + np.array([0.0, 2.0, 0.0])  # a second piece, far away
    points = np.vstack([face, far])
    patches = contact_patches(points)
    assert [p[0].size for p in patches] == [30, 30] and contact_chains(points)[0][0].size == 30
    degree = np.diff(patches[0][1].indptr)
    assert degree.min() == 3 and degree.max() == 8  # a corner; an inner node with its 8 neighbours
    active = np.zeros(60, dtype=bool)
    active[:30][y.ravel() <= 1] = True  # the columns y = 0, 1 of the first piece in contact
    M = np.eye(60)
    windows = LocalFronts(patches, M, np.ones(60), width=2).windows(active)
    assert len(windows) == 1  # the front between y = 1 and y = 2, one ring on either side: y = 0 … 3
    assert np.array_equal(np.sort(windows[0]), np.flatnonzero(y.ravel() <= 3))
