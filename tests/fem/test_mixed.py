"""Mixed penalized contact (fenics_contact.fem.mixed, forms_mixed): forms, Newton, complementarity, bad input.

Run from the repository root:  .venv/bin/python -m pytest tests/fem/test_mixed.py -q
"""

import dolfinx
import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.mixed import default_epsilon, solve_mixed_monolithic
from fenics_contact.fem.mixed_newton import exact_line_search
from fenics_contact.fem.mixed_subproblem import MixedSubproblem
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.transmission import split_mesh
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import ContactMesh, unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.tags import Boundary

#: the paper's contact zones (its test set-up), per model
CONTACT_ZONE = {1: (0.0, 0.5), 2: (0.4, 0.6)}


@pytest.fixture(scope="module")
def mesh32():
    return unit_square(32, 16)


@pytest.fixture(scope="module")
def solutions(mesh32):
    return {m: solve_mixed_monolithic(get_model(m).on(mesh32)) for m in (1, 2)}


def _scipy(A):
    indptr, indices, data = A.getValuesCSR()
    return sp.csr_matrix((data, indices, indptr), shape=A.getSize())


@pytest.mark.slow
def test_contact_term_matches_the_ufl_form():
    """Q-based penalty residual and Jacobian = the UFL forms with the Gauss–Lobatto contact measure."""
    cm = unit_square(16, 4)
    fields = material_fields(cm.mesh, get_model(2))
    eps = 1e-2
    prob = MixedSubproblem(cm.mesh, cm.facet_tags, fields, epsilon=eps, beta=None, prefix="t_q_")
    rng = np.random.default_rng(0)
    prob.c[:] = rng.standard_normal(prob.n_sigma)
    s = prob.Q @ prob.c
    assert 0.2 < np.mean(s > 0) < 0.8  # both signs present
    sig = prob.sigma_function()
    t, ds_ = ufl.TestFunction(prob.dg), ufl.TrialFunction(prob.dg)
    n = ufl.FacetNormal(cm.mesh)
    dc = forms_mixed.contact_measure(cm.mesh, cm.facet_tags)(Boundary.GAMMA_C)
    inv = fem.Constant(cm.mesh, PETSc.ScalarType(1 / eps))
    r_ufl = dolfinx.fem.assemble_vector(fem.form(forms_mixed.contact_penalty(sig, t, n, inv, dc)))
    r_ufl = prob.P.T @ r_ufl.array[: prob.P.shape[0]]
    r_q = prob.contact_nodes.penalty_force(s)
    assert np.allclose(r_ufl, r_q, atol=1e-10 * np.abs(r_q).max())
    J = dolfinx.fem.petsc.assemble_matrix(fem.form(forms_mixed.contact_penalty_jacobian(sig, ds_, t, n, inv, dc)))
    J.assemble()
    J_ufl = (prob.P.T @ _scipy(J) @ prob.P).toarray()
    J_q = prob.contact_nodes.penalty_matrix(s > 0).toarray()
    assert np.allclose(J_ufl, J_q, atol=1e-10 * np.abs(J_q).max())
    # the energy's derivative is the residual: J(σ + h e_k) − J(σ − h e_k) ≈ 2h r_k
    k = int(np.argmax(np.abs(r_q)))
    e = np.zeros(prob.n_sigma)
    e[k] = 1e-6

    def energy(c):
        prob.c[:] = c
        return prob.complementary_energy()

    c0 = prob.c.copy()
    grad = (energy(c0 + e) - energy(c0 - e)) / 2e-6
    assert np.isclose(grad, (prob.Kt @ c0)[k] + r_q[k], rtol=1e-5)


def test_robin_data_space_holds_the_traces_exactly():
    """C N = R: data g = σn (the trace, evaluated at the γ nodes) reproduces the Robin form exactly,
    so the update g ← g − 2βσn is exact in the data space (continuous P3 on γ)."""
    cm = unit_square(16, 4)
    parts = split_mesh(cm)
    for i, part in enumerate(parts):
        prob = MixedSubproblem(
            part.mesh,
            part.facet_tags,
            material_fields(part.mesh, get_model(1)),
            epsilon=1e-3 if i == 1 else None,
            beta=1.0,
            prefix=f"t_cn{i}_",
        )
        CN = (prob.C @ prob.N).toarray()
        R = prob.R.toarray()
        assert np.abs(CN - R).max() < 1e-11 * np.abs(R).max()
        # nodes: vertices + 2 per edge of γ
        assert prob.gamma_points.shape[0] == 3 * 16 + 1


@pytest.mark.parametrize("number", [1, 2])
def test_monolithic_contact_and_complementarity(mesh32, solutions, number):
    """Globalized Newton converges; σ_c ≤ 0 where u_c = 0, tensile stress only at the penalty level;
    the DG displacement trace agrees with u_c; the contact zone is the paper's and the primal one."""
    cm, sol = mesh32, solutions[number]
    hist = sol.newton
    assert hist.steps <= 10 and hist.factorizations <= hist.steps
    assert sol.epsilon == pytest.approx(default_epsilon(cm.h, 1.0))
    prof = sol.profile
    assert prof.penetration == 0.0  # the mixed penalty never penetrates
    smax = np.abs(prof.sigma_c).max()
    assert prof.max_tensile <= sol.epsilon * np.abs(prof.u_c).max() * (1 + 1e-12)
    assert prof.max_tensile < 1e-4 * smax
    assert np.all(prof.u_c[prof.active] == 0.0) and np.all(prof.u_c[~prof.active] < 0.0)
    # the DG P1 displacement trace: ≈ 0 where in contact, ≈ u_c in the gap (first order in h)
    _, un = sol.problem.displacement_normal_trace()
    gap = np.abs(prof.u_c).max()
    assert np.abs(un[prof.active]).max() < 0.05 * gap
    assert np.abs(un[~prof.active] - prof.u_c[~prof.active]).max() < 0.05 * gap
    lo, hi = prof.active_interval()
    zone = CONTACT_ZONE[number]
    assert abs(lo - zone[0]) < 0.02 and abs(hi - zone[1]) < 0.04, (lo, hi)
    primal = solve_primal_monolithic(get_model(number).on(cm), delta=default_penalty(cm.h, 1.0))
    plo, phi = primal.profile.active_interval()
    assert abs(lo - plo) <= 1.5 * cm.h and abs(hi - phi) <= 1.5 * cm.h, ((lo, hi), (plo, phi))


@pytest.mark.slow
def test_line_search_path_reaches_the_same_solution(mesh32, solutions):
    """Exact line search on J at every step: J decreases monotonically, same solution, and the
    step length minimizes J along the direction (checked against a fine grid)."""
    cm, ref = mesh32, solutions[2]
    fields = material_fields(cm.mesh, get_model(2))
    prob = MixedSubproblem(
        cm.mesh, cm.facet_tags, fields, epsilon=ref.epsilon, beta=None, prefix="t_ls_", line_search="always"
    )
    hist = prob.solve()
    J = np.array(hist.energies[1:])  # after the first (feasibility-restoring) step
    assert np.all(np.diff(J) <= 1e-12 * np.abs(J).max()), J
    assert any(t < 1.0 for t in hist.step_lengths)
    d = prob.c - ref.problem.c
    assert np.sqrt(prob.stress_norm2(d) / prob.stress_norm2(ref.problem.c)) < 1e-9

    # line search against brute force, from a point off the solution along a random feasible direction
    rng = np.random.default_rng(1)
    prob.c += 1e-2 * np.abs(prob.c).max() * rng.standard_normal(prob.n_sigma)
    s = prob.Q @ prob.c
    F1, F2 = prob.gradient(np.zeros(prob.n_sigma))
    prob.factorize_for(s > 0)
    dc, _ = prob.linear_solve(-F1, np.zeros_like(F2))
    t = exact_line_search(prob, dc, s, prob.Q @ dc, np.zeros(prob.n_sigma))
    c0 = prob.c.copy()

    def energy(tau):
        prob.c[:] = c0 + tau * dc
        return prob.complementary_energy()

    grid = np.linspace(0.0, 1.0, 2001)
    values = np.array([energy(tau) for tau in grid])
    assert energy(t) <= values.min() + 1e-12 * abs(values.min())


def test_penalty_limit():
    """The tensile stress left is ε·max|u_c| and the solutions converge as ε → 0 (linearly)."""
    cm = unit_square(16, 4)
    model = get_model(1)
    sols = [solve_mixed_monolithic(model.on(cm), epsilon=eps) for eps in (1e-3, 1e-4, 1e-5)]
    tensile = [s.profile.max_tensile for s in sols]
    assert tensile[0] > 5 * tensile[1] > 25 * tensile[2]
    prob = sols[-1].problem
    diffs = [np.sqrt(prob.stress_norm2(a.problem.c - sols[-1].problem.c)) for a in sols[:2]]
    assert diffs[0] > 5 * diffs[1]


def test_split_interface_space(mesh32, solutions):
    """X̃_h adds one σ_tt function per γ vertex; its solution is close to the AW one at this H."""
    cm = mesh32
    split = solve_mixed_monolithic(get_model(1).on(cm), split_interface=True)
    ref = solutions[1]
    assert split.dofs["sigma"] == ref.dofs["sigma"] + 33
    diff = split.sigma.x.array - ref.sigma.x.array
    rel = np.linalg.norm(diff) / np.linalg.norm(ref.sigma.x.array)
    assert 1e-8 < rel < 1e-2, rel


def test_nearly_incompressible_monolithic():
    """ν = 0.4999: Newton converges and the stress stays bounded (no locking blow-up)."""
    cm = unit_square(16, 4)
    sols = [solve_mixed_monolithic(get_model(1, nu=nu).on(cm)) for nu in (0.35, 0.4999)]
    norms = [np.sqrt(s.problem.stress_norm2(s.problem.c)) for s in sols]
    assert all(s.newton.steps <= 12 for s in sols)
    smax = [np.abs(s.sigma.x.array).max() for s in sols]
    assert 0.2 < smax[1] / smax[0] < 5.0, smax
    assert np.all(np.isfinite(norms))


# -- bad input -----------------------------------------------------------------------------


def test_rejects_poisson_ratio_out_of_range():
    cm = unit_square(8, 4)
    for nu in (0.5, 0.6, -1.0):
        with pytest.raises(InputError, match="Poisson"):
            solve_mixed_monolithic(get_model(1, nu=nu).on(cm))


def test_rejects_non_triangular_mesh():
    msh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4, dolfinx.mesh.CellType.quadrilateral)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = dolfinx.mesh.exterior_facet_indices(msh.topology)
    ft = dolfinx.mesh.meshtags(msh, tdim - 1, facets, np.full(facets.size, int(Boundary.GAMMA_C), dtype=np.int32))
    cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int32)
    ct = dolfinx.mesh.meshtags(msh, tdim, cells, np.ones_like(cells))
    cm = ContactMesh(msh, ct, ft, 0.25, 0.25, np.full(cells.size, -1, dtype=np.int32))
    with pytest.raises(InputError, match="triangle"):
        solve_mixed_monolithic(get_model(1).on(cm))


@pytest.mark.parametrize("eps", [0.0, -1e-3, float("nan")])
def test_rejects_bad_penalty(eps):
    cm = unit_square(8, 4)
    with pytest.raises(InputError):
        solve_mixed_monolithic(get_model(1).on(cm), epsilon=eps)


def test_default_epsilon_does_not_glue_the_soft_part_of_a_heterogeneous_contact_boundary(mesh32):
    """Model 3 at contrast 1e6: stiff channels and soft material share Γ_C.  The default ε is taken from the
    softest material there; with the stiffest (the former default) the soft part stayed glued to the wall:
    contact force 20 % below the primal one, tensile σ_c 0.22.  Now the forces agree to 1 % and the tensile
    stress left is at the penalty level."""
    from fenics_contact.fem.mixed import contact_modulus

    cm = mesh32
    problem = get_model(3, E_high=1e6).on(cm)
    fields = problem.fields
    assert contact_modulus(cm.mesh, cm.facet_tags, fields.E, smallest=True) == pytest.approx(1.0)
    assert contact_modulus(cm.mesh, cm.facet_tags, fields.E) == pytest.approx(1e6)
    mixed = solve_mixed_monolithic(problem)
    assert mixed.epsilon == pytest.approx(default_epsilon(cm.h, 1.0))
    primal = solve_primal_monolithic(problem, delta=default_penalty(cm.h, 1e6))
    f_mixed, f_primal = mixed.profile.force, primal.profile.force
    assert abs(f_mixed - f_primal) < 0.01 * abs(f_primal), (f_mixed, f_primal)
    assert mixed.profile.max_tensile < 1e-4 * np.abs(mixed.profile.sigma_c).max()
    mixed.free()
