"""Shared patch factorizations of the primal CEM (``CEMOptions.patch_group``).

Unit checks: the groups partition the coarse cells (g × g blocks of a Cartesian grid, greedy groups of a
general partition), the group patch is the union of the cells' oversamplings, the option is validated and
keys the offline cache.  Verification: the bases of a group live on its patch; the Ω₁ Robin error with
groups of 2 × 2 cells is no worse than with one patch per cell (up to a small factor: each group patch holds
every K_{k,m} of its cells), and with one group of all of Ω₁ the multiscale solution is the fine one.
"""

import gc

import numpy as np
import pytest
from mpi4py import MPI
from omega1_robin import fine_robin_error, robin_data

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.errors import InputError
from fenics_contact.multiscale import cem
from fenics_contact.multiscale.coarse import grid_from_cells
from fenics_contact.problem import geometry, models

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="Algorithm 3 is serial (MPI: test_multiscale_mpi)")


@pytest.fixture(scope="module", autouse=True)
def _teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


def _grid(cm, *, cartesian: bool):
    dofmap, x = cm.mesh.geometry.dofmaps[0], cm.mesh.geometry.x
    return grid_from_cells(dofmap, x, cm.coarse_cell, cm.H if cartesian else None)


@pytest.mark.parametrize("g", [2, 3, 8])
def test_cartesian_groups_are_blocks(mesh_32_8, g):
    grid = _grid(mesh_32_8, cartesian=True)
    groups = grid.groups(g, 2)
    assert np.array_equal(np.sort(np.concatenate(groups)), np.arange(grid.size))  # a partition
    for cells in groups:
        block = grid.ij[cells] // g
        assert np.all(block == block[0])  # one g × g block each
        assert cells.size <= g * g
    assert len(groups) == int(np.ceil(8 / g)) ** 2
    assert [c.size for c in grid.groups(None, 2)] == [grid.size]


def test_general_partition_groups_are_greedy(mesh_32_8):
    grid = _grid(mesh_32_8, cartesian=False)
    assert grid.ij is None
    groups = grid.groups(2, 2)
    assert np.array_equal(np.sort(np.concatenate(groups)), np.arange(grid.size))
    for cells in groups:
        assert cells.size <= 4
        assert np.all(grid.distance(int(cells[0]))[cells] <= 1)
    assert len(groups) < grid.size


def test_group_patch_is_the_union_of_the_oversamplings(mesh_32_8):
    grid = _grid(mesh_32_8, cartesian=True)
    for cells in grid.groups(2, 2):
        union = np.unique(np.concatenate([grid.patch(int(k), 2) for k in cells]))
        assert np.array_equal(grid.group_patch(cells, 2), union)


@pytest.mark.parametrize("value", [0, -1, 1.5, "some", True, None])
def test_patch_group_validated(value):
    with pytest.raises(InputError, match="patch_group"):
        cem.CEMOptions(patch_group=value)


def test_patch_group_accepts_whole_numbers_and_the_whole_domain():
    assert cem.CEMOptions(patch_group=2.0).patch_group == 2
    assert cem.CEMOptions(patch_group=cem.WHOLE_DOMAIN).patch_group == cem.WHOLE_DOMAIN


def test_groups_keep_the_localization_and_the_whole_domain_is_exact(mesh_32_8, tmp_path):
    """Model 1, h = 1/32, H = 1/8, m = 2, l = 3: the Robin error against the fine solve with 2 × 2 groups is at
    most that of one patch per cell (measured 4.0e-2 against 4.5e-2), with one group of all of Ω₁ it is
    round-off (the global bases span the fine solution's correction); the bases of a group live on its patch;
    the cache keys the option (another file) and returns the space it stored."""
    model = models.get_model(1).on(mesh_32_8)
    errors, omegas = {}, {}
    for g in (1, 2, cem.WHOLE_DOMAIN):
        om, _, _ = cem.build_omega1_multiscale(
            model, cem=cem.CEMOptions(layers=2, nbasis=3, patch_group=g), cache_dir=tmp_path
        )
        assert om.cache_status == "built"
        errors[g] = fine_robin_error(om, robin_data(om))
        omegas[g] = om
    assert errors[2] <= 1.2 * errors[1], errors
    assert errors[cem.WHOLE_DOMAIN] < 1e-10, errors
    assert len(list(tmp_path.glob("cem_*.npz"))) == 3
    om = omegas[2]
    assert om.space.times["patch_problems"] == 16 and omegas[1].space.times["patch_problems"] == 56
    inc = cem.Incidence(om.ops, om.grid)
    groups, patches = cem.cell_groups(om.grid, cem.CEMOptions(layers=2, patch_group=2), 2)
    for cells, patch in zip(groups, patches):
        inner = inc.interior_dofs(patch)
        for k in cells:
            assert np.array_equal(om.space.basis[k].dofs, inner)
    again, _, _ = cem.build_omega1_multiscale(
        model, cem=cem.CEMOptions(layers=2, nbasis=3, patch_group=2), cache_dir=tmp_path
    )
    assert again.cache_status == "loaded" and again.space.patch_group == 2
    g = robin_data(om)
    assert np.array_equal(again.solver.solve(g), om.solver.solve(g))


@pytest.mark.parametrize("g", [1, 2, cem.WHOLE_DOMAIN])
def test_gram_matrices_of_grouped_bases(g):
    """The Gram matrices summed over the coarse cells the grouped supports cover (``covering``) are ZᵀKZ and
    ZᵀMZ of the assembled Z = [Ψ, N, N_f]: no cell a function reaches is left out.  The interface coordinates
    of a step give the same trace and norms."""
    om, _, _ = cem.build_omega1_multiscale(
        models.get_model(3).on(geometry.unit_square(32, 8)), cem=cem.CEMOptions(layers=1, patch_group=g)
    )
    covers = cem.covering(om.grid, 1, g, 2)
    assert g == cem.WHOLE_DOMAIN or max(c.size for c in covers) < om.grid.size  # supports are local
    space, ops = om.space, om.ops
    Z = np.hstack([space.Psi.toarray(), space.N.toarray(), space.Nf[:, None]])
    scale = np.abs(om.solver.GK).max()
    assert np.allclose(om.solver.GK, Z.T @ (ops.K @ Z), rtol=0, atol=1e-12 * scale)
    assert np.allclose(om.solver.GM, Z.T @ (ops.M @ Z), rtol=0, atol=1e-12 * np.abs(om.solver.GM).max())
    gdata = robin_data(om)
    u1 = om.solver.solve(gdata)
    t = om.interface_coordinates(gdata)
    assert np.allclose(om.interface_trace(t), om.interface_values(u1), rtol=0, atol=1e-12 * np.abs(u1).max())
    assert om.interface_norms2(t)[0] == pytest.approx(float(u1 @ (ops.K @ u1)), rel=1e-10)
