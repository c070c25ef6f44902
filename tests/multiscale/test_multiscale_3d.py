"""Algorithm 3 on tetrahedra: coarse cubes over the 3D channel model, six rigid motions per floating coarse cell,
the energy error falling with the oversampling layers, and the fine solution once the patches cover Ω₁.

Unit checks: the Cartesian grid of cubes (indices, sizes |K|^(1/3), 26-neighbour adjacency, eight colours), the
local spectral problem of a floating cube (six zero eigenvalues: the default l keeps them all, l = 3 cuts through
them), the roller components held in the Ω₁ CEM space, the offline cache in 3D.  Verification: the energy error
against the monolithic solution falls at least fourfold per layer, and with the patches covering Ω₁ (m = 3 on
3 × 4 × 4 cubes) Algorithm 3 is the fine hybrid solution, i.e. the monolithic one (the package docstring of
``multiscale.cem``: without localization u₁ is the fine Robin solution for any load).
"""

import gc

import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.multiscale import cem
from fenics_contact.multiscale.coarse import grid_from_cells
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.partition import cartesian_coarse_cells, coarse_sizes

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test (its MPI twin is in test_mpi_3d)")

H = 0.25  #: coarse cubes of side ¼ (and the strip Ω₂ one cube wide): Ω₁ holds 3 × 4 × 4 of them


@pytest.fixture(scope="module", autouse=True)
def _teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture(scope="module")
def cube():
    """The 3D channel model (contrast 1e3, the load in Ω₁) at h = 1/8 on cubes of side ¼, and its monolithic u_h."""
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(8, strip=H, H=H, comm=MPI.COMM_SELF))
    return problem, fc.solve(problem, "primal-monolithic")


def test_the_coarse_grid_of_cubes():
    cm = channels_3d_mesh(4, strip=0.5, H=0.5, comm=MPI.COMM_SELF)
    index, nx = cartesian_coarse_cells(cm.mesh, 0.5)
    assert nx == 2 and np.array_equal(np.bincount(index), np.full(8, 6 * 2**3))  # 8 cubes of 6 · 2³ tetrahedra
    assert np.array_equal(index, cm.coarse_cell) and cm.H == 0.5
    np.testing.assert_allclose(coarse_sizes(cm.mesh, index), 0.5, rtol=1e-12)  # |K|^(1/3)
    grid = grid_from_cells(cm.mesh.geometry.dofmaps[0], cm.mesh.geometry.x, index, 0.5)
    assert grid.size == 8 and grid.n_coarse == 2 and grid.ij.shape == (8, 3)
    np.testing.assert_allclose(grid.cell_size, 0.5, rtol=1e-12)
    assert grid.adjacency.toarray().all()  # every pair of the 2 × 2 × 2 cubes shares a vertex
    assert grid.num_colors == 8
    big = channels_3d_mesh(8, strip=0.25, H=0.25, comm=MPI.COMM_SELF)
    big_grid = grid_from_cells(big.mesh.geometry.dofmaps[0], big.mesh.geometry.x, big.coarse_cell, 0.25)
    neighbours = np.asarray(big_grid.adjacency.sum(axis=1)).ravel() - 1
    assert neighbours.max() == 26 and neighbours.min() == 7  # an inner cube, a corner cube
    assert big_grid.num_colors == 8  # (2 × 2 × 2 colouring of a grid of cubes)
    with pytest.raises(InputError, match="cubes of side H"):
        grid_from_cells(big.mesh.geometry.dofmaps[0], big.mesh.geometry.x, np.full(big.coarse_cell.size, -1), 0.3)


def test_a_floating_cube_keeps_its_six_rigid_motions(cube):
    """The default l (``RIGID_MOTIONS``) is 6 in 3D: every Λ_k > 0; l = 3 cuts through the six zeros (Λ = 0)."""
    problem, _ = cube
    om, _, _ = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=0))
    grid, aux = om.grid, om.space.aux
    assert cem.CEMOptions().modes(3) == 6 and cem.CEMOptions().modes(2) == 3
    assert om.nbasis_range == (6, 6) and om.spectral_gap > 1e-2
    # a cube touching neither Γ_D (x = 0, y = 0), the rollers (z = 0, 1) nor γ (x = ¾): i = 1, j ≥ 1, 1 ≤ k ≤ 2
    floating = [k for k, (i, j, kk) in enumerate(grid.ij) if i == 1 and j >= 1 and 1 <= kk <= 2]
    assert floating
    for k in floating:
        assert np.abs(aux.eigenvalues[k]).max() < 1e-8 * aux.gaps[k]
    three, _, _ = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=0, nbasis=3))
    assert three.nbasis_range == (3, 3) and three.spectral_gap < 1e-8


def test_the_rollers_hold_their_component_in_omega1(cube):
    problem, _ = cube
    om, _, _ = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=0))
    ops = om.ops
    x = ops.V.tabulate_dof_coordinates()
    on_roller = np.isclose(x[:, 2], 0.0) | np.isclose(x[:, 2], 1.0)
    held = ~ops.free.reshape(-1, 3)
    clamped = np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 1], 0.0)
    assert np.array_equal(held[:, 2], on_roller | clamped)  # u_z on z = 0, 1 and on Γ_D
    assert np.array_equal(held[:, 0], clamped) and np.array_equal(held[:, 1], clamped)
    assert ops.lifting is None  # (rollers are homogeneous: no lifting)


def test_the_energy_error_falls_with_the_layers_in_3d(cube):
    """h = 1/8, H = 1/4, l = 6, contrast 1e3 with the load in Ω₁: e_E 0.34, 2.2e-3, 1.8e-13 for m = 1, 2, 3
    (measured); each layer divides it by at least 4, the interface Newton converges (certificate) in at most
    8 steps, and m = 3 (patches = Ω₁) is the monolithic solution."""
    problem, ref = cube
    errors = []
    for m in (1, 2, 3):
        result = fc.solve(problem, "primal-ms", layers=m, tol=1e-9, reference=ref.u)
        assert result.converged and result.history.transmission_residual < 1e-9
        assert result.history.newton_steps <= 8
        assert result.step.cem.nbasis == 6 and result.dofs["omega1_ms"] == 6 * 48
        errors.append(result.step.error_energy())
        u = result.u.x.array.reshape(-1, 3)
        x = result.u.function_space.tabulate_dof_coordinates()
        assert np.all(u[np.isclose(x[:, 2], 0.0) | np.isclose(x[:, 2], 1.0), 2] == 0.0)  # the rollers hold
    assert errors[0] > 4 * errors[1] > 16 * errors[2], errors
    assert errors[0] < 0.5 and errors[2] < 1e-8, errors
    np.testing.assert_array_equal(result.profile.active, ref.profile.active)


@pytest.mark.slow
def test_the_energy_error_falls_with_the_layers_at_h_1_16():
    """h = 1/16, H = 1/4: e_E 0.23 (m = 1) and 1.0e-3 (m = 2) measured; at least fourfold per layer."""
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(16, strip=H, H=H, comm=MPI.COMM_SELF))
    ref = fc.solve(problem, "primal-monolithic")
    errors = []
    for m in (1, 2):
        result = fc.solve(problem, "primal-ms", layers=m, tol=1e-9, reference=ref.u)
        assert result.converged and result.history.newton_steps <= 8
        errors.append(result.step.error_energy())
    assert errors[0] > 4 * errors[1] and errors[1] < 5e-3, errors


def test_the_offline_cache_in_3d(cube, tmp_path):
    """The 3D offline data are stored and read back (the same solution), under a key of their own."""
    problem, _ = cube
    first = fc.solve(problem, "primal-ms", layers=1, cache_dir=tmp_path, tol=1e-9)
    second = fc.solve(problem, "primal-ms", layers=1, cache_dir=tmp_path, tol=1e-9)
    assert first.step.omega1.cache_status == "built" and second.step.omega1.cache_status == "loaded"
    np.testing.assert_allclose(second.u.x.array, first.u.x.array, rtol=0, atol=1e-12 * np.abs(first.u.x.array).max())
    om = second.step.omega1
    key = cem.offline_key(om.ops, om.grid, second.step.cem, h=problem.cm.h)
    assert len(list(tmp_path.glob("cem_*.npz"))) == 1 and cem.PrimalOfflineCache(tmp_path).path(key).is_file()


def test_large_3d_patches_are_ordered_by_metis_with_the_same_bases(cube, monkeypatch):
    """3D patch problems from ``METIS_FROM_3D`` unknowns are ordered by METIS (MUMPS' INFOG(7) = 5: the ordering it
    used), the others and every 2D one by AMF; the bases, correctors and Gram matrices are the same to round-off."""
    from fenics_contact.fem.linalg import SparseFactor
    from fenics_contact.multiscale.cem import bases

    assert cem.patch_icntl(3, cem.METIS_FROM_3D) == {7: 5} and cem.patch_icntl(3, cem.METIS_FROM_3D - 1) == {7: 2}
    assert cem.patch_icntl(2, 10**7) == cem.PATCH_ICNTL == {7: 2}
    used = []

    class Recorded(SparseFactor):
        def destroy(self):
            used.append(self.ksp.getPC().getFactorMatrix().getMumpsInfog(7))
            super().destroy()

    monkeypatch.setattr(bases, "SparseFactor", Recorded)
    problem, _ = cube
    built = {}
    for threshold in (0, 10**9):  # every patch by METIS, every patch by AMF
        monkeypatch.setattr(bases, "METIS_FROM_3D", threshold)
        used.clear()
        om = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=1))[0]
        assert used and set(used) == {5 if threshold == 0 else 2}
        built[threshold] = (np.concatenate([b.values.ravel() for b in om.space.blocks]), om.space.Nf, om.solver.GM)
    for metis, amf in zip(built[0], built[10**9]):
        assert metis.shape == amf.shape
        assert np.abs(metis - amf).max() <= 1e-10 * np.abs(amf).max()


def test_mixed_ms_is_refused_in_3d_and_names_the_3d_methods(cube):
    problem, _ = cube
    with pytest.raises(InputError, match="plane problems.*'primal-ms'"):
        fc.solve(problem, "mixed-ms")


@pytest.mark.parametrize(("plane", "match"), [((0, 0.75), "interface γ"), ((2, 0.5), "no exterior facet")])
def test_a_roller_plane_through_gamma_or_inside_the_body_is_refused(cube, plane, match):
    """Before the offline phase: a roller plane must lie on the outer boundary of Ω₁ or Ω₂, not on γ."""
    problem, _ = cube
    moved = problem.with_(boundary=BoundaryConditions(rollers=(plane,)))
    with pytest.raises(InputError, match=match):
        fc.solve(moved, "primal-ms", layers=1)
