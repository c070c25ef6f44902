"""Algorithm 4 with the boundary conditions of the fine mixed method on Ω₁.

Every untagged side traction free (σn = 0, essential in every local stress space), Γ_N groups with a
traction (σn = t: the lifting s₀, whose effect is a load that goes through the source correctors) and
a prescribed displacement on Γ_D (∫_ΓD u_D·τn, a stress-side load, also source-corrected).
"""

import logging

import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact  # noqa: F401  (must precede dolfinx)
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid
from fenics_contact.multiscale import mixed_cem as mm
from fenics_contact.multiscale.coarse import coarse_grid
from fenics_contact.multiscale.mixed import essential_traction_facets, l2_stress_error, solve_mixed_ms_hybrid
from fenics_contact.problem import geometry, models
from fenics_contact.problem.boundary import BoundaryConditions

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="Algorithm 4 tests run serially here")

NEWTON = IterationOptions(tol=1e-10, accel="newton")


def _data(x):
    return np.stack([0.01 * np.sin(3.0 * x[1]), 0.02 * x[1] ** 2])


BOUNDARY = BoundaryConditions(
    displacement=_data,  # u_D on Γ_D = {x = 0}
    tractions={"Gamma_N_top": lambda x: np.stack([0.3 + x[0], -0.5 * np.ones_like(x[0])])},
)


def _mesh(n: int, n_coarse: int):
    """The unit square clamped (or u_D) at x = 0 only: top Γ_N, bottom traction free (across γ)."""
    return geometry.unit_square(n, n_coarse, clamped=("left",), neumann={"top": "Gamma_N_top"})


@pytest.mark.slow
def test_full_space_reproduces_the_fine_problem_with_boundary_data():
    """All Stage I modes and patches covering Ω₁: the multiscale Ω₁ solution is the fine one of the constrained
    AW space with the lifting and u_D (stress, displacement, trace σn₁ incl. the lifting's, to round-off)."""
    cm = _mesh(8, 4)
    step = MixedHybridStep(models.get_model(2).with_(boundary=BOUNDARY).on(cm), beta="sqrt-h")
    part, sub = step.parts[0], step.sub[0]
    assert sub.spaces.lifted and sub.u_D is not None
    grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
    tf = essential_traction_facets(part.mesh, part.facet_tags)
    assert tf.size == 6 + 6  # bottom (free) and top (Γ_N) of Ω₁: 3/4 · 8 facets each
    om = mm.MixedMultiscaleOmega1(sub, grid, mm.MixedCEMOptions(layers=3, nbasis=None), H=cm.H, traction_free_facets=tf)
    assert om.ops.has_boundary_data and om.lifting is not None
    g = np.random.default_rng(0).standard_normal(om.co.n_g)
    r, w = om.solve(g)
    sub.solve(g)
    s_ref = (sub.P @ sub.c)[om.ops.dg_rows]  # the homogeneous part (σ = P c + s₀)
    u_ref = sub.u[om.ops.u_rows]
    assert np.sqrt(om.a_norm2(om.fine_stress(r, g) - s_ref) / om.a_norm2(s_ref)) < 1e-10  # measured 1e-14
    assert np.sqrt(om.m_norm2(om.fine_displacement(w, g) - u_ref) / om.m_norm2(u_ref)) < 1e-10
    t = sub.gamma_traction()  # N c + n₀
    assert np.abs(om.response.trace(g) - t).max() < 1e-10 * np.abs(t).max()
    assert np.abs(om.trace(r, g) - t).max() < 1e-10 * np.abs(t).max()


def test_without_source_correctors_boundary_data_warn(caplog):
    cm = _mesh(8, 4)
    step = MixedHybridStep(models.get_model(2).with_(boundary=BOUNDARY).on(cm), beta="sqrt-h")
    part = step.parts[0]
    grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
    with caplog.at_level(logging.WARNING, logger="fenics_contact.multiscale.mixed_cem"):
        mm.MixedMultiscaleOmega1(
            step.sub[0],
            grid,
            mm.MixedCEMOptions(layers=1, source_correction=False),
            H=cm.H,
            traction_free_facets=essential_traction_facets(part.mesh, part.facet_tags),
        )
    assert "without source correctors" in caplog.text


@pytest.mark.slow
def test_algorithm4_with_boundary_data_converges_to_algorithm2():
    """Model 2 (inclusions, contrast 10³), u_D at x = 0, a traction on the top, the bottom free: the error against
    the monolithic mixed solve falls with m (≥ 10× per layer), and at m = 3 (patches covering Ω₁, H = 1/4) the
    multiscale space holds the fine solution: Algorithm 4 gives Algorithm 2's fixed point."""
    cm = _mesh(16, 4)
    model = models.get_model(2).with_(boundary=BOUNDARY)
    ref = solve_mixed_monolithic(model.on(cm))
    alg2 = solve_mixed_hybrid(model.on(cm), reference=ref, options=NEWTON)
    assert alg2.converged and alg2.e_sigma < 1e-2  # the split-interface floor, O(h²): measured 3.2e-3
    res = {
        m: solve_mixed_ms_hybrid(model.on(cm), cem=mm.MixedCEMOptions(layers=m), reference=ref, options=NEWTON)
        for m in (1, 2, 3)
    }
    assert all(r.converged for r in res.values())
    e = [res[m].e_sigma for m in (1, 2, 3)]
    assert e[1] < e[0] / 10, e
    assert abs(e[2] - alg2.e_sigma) < 1e-6 * alg2.e_sigma, (e, alg2.e_sigma)
    assert l2_stress_error(res[3].sigma, alg2.sigma) < 1e-8  # the lifting is in the glued stress too
    assert res[3].profile.force == pytest.approx(alg2.profile.force, rel=1e-9)


@pytest.mark.slow
def test_algorithm4_free_sides_heterogeneous_strip_against_algorithm2():
    """Hard case: model 3 (channels through γ up to Γ_C, γ cutting inclusions, loads in Ω₁; contrast 10³), clamped
    at x = 0 only, a traction on the top, the bottom traction free; h = 1/32, H = 1/4.  Algorithm 4 against
    Algorithm 2: L² stress difference 2.7e-4 at m = 2, round-off at m = 3 (patches covering Ω₁)."""
    cm = geometry.unit_square(32, 4, clamped=("left",), neumann={"top": "Gamma_N_top"})
    model = models.get_model(3, E_high=1e3).with_(boundary=BoundaryConditions(tractions={"Gamma_N_top": (0.2, -0.5)}))
    alg2 = solve_mixed_hybrid(model.on(cm), options=NEWTON)
    assert alg2.converged
    diff = {}
    for m in (2, 3):
        res = solve_mixed_ms_hybrid(model.on(cm), cem=mm.MixedCEMOptions(layers=m), options=NEWTON)
        assert res.converged
        diff[m] = (l2_stress_error(res.sigma, alg2.sigma), abs(res.profile.force / alg2.profile.force - 1))
    # measured: (2.7e-4, 9.2e-5) at m = 2, (7e-11, 1e-12) at m = 3
    assert diff[2][0] < 1e-3 and diff[2][1] < 1e-3, diff
    assert diff[3][0] < 1e-8 and diff[3][1] < 1e-9, diff


@pytest.mark.slow
def test_cache_keeps_and_keys_the_boundary_data(tmp_path):
    """The offline cache stores the boundary data's load (Φᵀ F) and is keyed by it: another traction is a new file;
    the loaded data give the same trace and stresses (lifting included in the trace)."""
    cm = _mesh(8, 4)
    built = {}
    for name, t in (("a", (0.2, -0.5)), ("b", (0.2, -0.6))):
        model = models.get_model(2).with_(boundary=BoundaryConditions(displacement=_data, tractions={"Gamma_N_top": t}))
        step = MixedHybridStep(model.on(cm), beta="sqrt-h")
        part = step.parts[0]
        grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
        tf = essential_traction_facets(part.mesh, part.facet_tags)
        oms = [
            mm.MixedMultiscaleOmega1(
                step.sub[0], grid, mm.MixedCEMOptions(layers=1), H=cm.H, cache_dir=tmp_path, traction_free_facets=tf
            )
            for _ in range(2)
        ]
        assert [om.cache_status for om in oms] == ["built", "loaded"]
        g = np.random.default_rng(3).standard_normal(oms[0].co.n_g)
        (r0, _), (r1, _) = oms[0].solve(g), oms[1].solve(g)
        assert np.array_equal(oms[0].response.trace(g), oms[1].response.trace(g))
        s0, s1 = oms[0].fine_stress(r0, g), oms[1].fine_stress(r1, g)
        assert np.abs(s0 - s1).max() < 1e-6 * np.abs(s0).max()  # patch functions stored in float32
        built[name] = oms[0]
    assert built["a"].cache_path != built["b"].cache_path
    assert not np.allclose(built["a"].co.Fphi, built["b"].co.Fphi)
