"""ZᵀKZ of Z = [Ψ, N, N_f] from the patch equations (``cem.equations``) equals the products of the functions
with the fine stiffness matrix (``cem.gram_matrices`` of a space without them) to round-off: one patch per
coarse cell, shared patches, one patch of all Ω₁ (no ring), and with the lifting of a prescribed displacement
in N_f's column; dependent functions (a singular ΨᵀAΨ) take the products."""

import numpy as np
import pytest

from fenics_contact.multiscale import cem
from fenics_contact.problem import models
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import unit_square


def _grams(om) -> tuple:
    """(ZᵀKZ from the patch equations, ZᵀKZ and ZᵀMZ as products of the bases)."""
    assert om.space.equations is None  # dropped once the Gram matrices are formed
    return om.solver.GK, *cem.gram_matrices(om.ops, om.grid, om.space)


@pytest.mark.parametrize("patch_group", [1, 2, "all"])
def test_stiffness_gram_from_the_patch_equations(patch_group):
    problem = models.get_model(3, E_high=100.0).on(unit_square(32, 8))
    om = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=2, nbasis=3, patch_group=patch_group))[0]
    GK, GK_direct, GM_direct = _grams(om)
    assert om.space.Nf is not None and np.any(om.space.correction_cells >= 0)  # all three kinds of column
    assert np.max(np.abs(GK - GK_direct)) < 1e-12 * np.max(np.abs(GK_direct))
    assert np.array_equal(om.solver.GM, GM_direct)
    assert np.array_equal(GK, GK.T)


def test_stiffness_gram_with_a_lifting():
    boundary = BoundaryConditions(displacement=(0.01, 0.002), tractions={"Gamma_N_top": (1.0, -0.5)})
    cm = unit_square(32, 8, clamped=("left",), neumann={"top": "Gamma_N_top"})
    problem = models.get_model(3, E_high=100.0).with_(boundary=boundary).on(cm)
    om = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=2, nbasis=3, patch_group=2))[0]
    assert om.ops.lifting is not None
    GK, GK_direct, _ = _grams(om)
    assert np.max(np.abs(GK - GK_direct)) < 1e-12 * np.max(np.abs(GK_direct))


def test_dependent_functions_take_the_products():
    """Every local mode kept on patches of all Ω₁: dependent bases (ΨᵀAΨ singular); the round-off of the patch
    equations would hide that, so ZᵀKZ is the products of the functions (the coarse rank that of V_h(Ω₁))."""
    om = cem.build_omega1_multiscale(
        models.get_model(1).on(unit_square(16, 4)), cem=cem.CEMOptions(layers=4, nbasis=cem.ALL_MODES)
    )[0]
    GK, GK_direct, _ = _grams(om)
    assert np.array_equal(GK, GK_direct)
    assert om.solver.factor.rank == int(np.count_nonzero(om.ops.free)) < om.space.size


def test_products_summed_per_pair_of_patch_problems():
    """The Gram matrices as products, summed per pair of patch problems over the coarse cells, are ZᵀKZ and ZᵀMZ
    of the assembled Z = [Ψ, N, N_f]; a γ vertex shared by two cells of a group has one Robin corrector in its
    patch problem (distinct columns per block), one shared by two groups a corrector in each (their sum)."""
    problem = models.get_model(3, E_high=100.0).on(unit_square(32, 8))
    om = cem.build_omega1_multiscale(problem, cem=cem.CEMOptions(layers=2, nbasis=3, patch_group=2))[0]
    space, ops = om.space, om.ops
    assert all(np.unique(b.columns).size == b.columns.size for b in space.blocks)
    shared = np.concatenate([p.columns for p in space.correction])
    assert 1 < len(space.correction) and shared.size > np.unique(shared).size  # γ DOFs corrected in two groups
    GK, GM = cem.gram_matrices(ops, om.grid, space)  # (no patch equations left: products)
    Z = np.hstack([space.Psi.toarray(), space.N.toarray(), space.Nf[:, None]])
    for G, W in ((GK, ops.K), (GM, ops.M)):
        exact = Z.T @ (W @ Z)
        assert np.max(np.abs(G - exact)) < 1e-12 * np.max(np.abs(exact))
