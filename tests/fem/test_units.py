"""Units: every method gives the same relative results whatever the units of stress and length.

The bar of ``fenics_contact.analytic`` (ν = 0, clamped at x = 0, pushed onto the wall at x = L or pulled off
it) with Young's modulus E and body force f = ±E/L on the unit square scaled by L: σ/E and u/L are those of
E = L = 1.  Each method runs at E = 2.1e5 (MPa), 2.1e11 (Pa), lengths L = 1e-3, 1e3, 1e6 and steel in
m on a mm-sized part, and must give the contact force/(E L), ‖u‖/L², the errors against the closed form and
the iteration and Newton counts of E = L = 1 (to 1e-8: each solve is backward stable in its own units; the
mixed saddle-point factorizations are equilibrated, ``fem.mixed_linear``).

The default penalty and transmission coefficients carry their units: ε = 1e-3·(h/L_ref)·E/L_ref and
α = E/√(h L_ref) (stress per length), δ = 1e-3·h/E and β = √(h L_ref)/E (length per stress), L_ref the body's
size (``ContactProblem.length``), so every run here uses the defaults.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from dolfinx import fem
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.linalg import DirectSolver, SparseFactor
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.fem.mixed import default_epsilon
from fenics_contact.fem.primal import default_penalty
from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep
from fenics_contact.problem.analytic import bar_model, bar_solution

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="mixed (Arnold–Winther) methods are serial")

N, N_COARSE = 16, 4  # h = 1/16, H = 1/4
#: (E, L): stress in MPa and Pa, lengths in mm-, km- and 1000-km-sized units, steel in Pa on a 1 mm part
UNITS = [(2.1e5, 1.0), (2.1e11, 1.0), (1.0, 1e-3), (1.0, 1e3), (1.0, 1e6), (2.1e11, 1e-3)]
METHODS = [
    "primal-monolithic",
    "primal",
    "primal-ms",
    "mixed-monolithic",
    pytest.param("mixed", marks=serial),
    pytest.param("mixed-ms", marks=serial),
]
RTOL = 1e-8


def _l2(expr, msh) -> float:
    form = fem.form(ufl.inner(expr, expr) * ufl.dx(domain=msh, metadata={"quadrature_degree": 6}))
    return float(np.sqrt(msh.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)))


def _counts(result) -> tuple:
    """Iterations and Newton steps: (Newton steps, factorizations) of a monolithic solve; (iterations, interface
    Newton steps) of a hybrid one."""
    if hasattr(result, "history"):
        return result.iterations, result.history.newton_steps
    return result.newton.steps, result.newton.factorizations


def _bar(method: str, f1: float, E: float, L: float, **options) -> dict:
    """The dimensionless results of the bar in units (E, L)."""
    cm = fc.unit_square(N, N_COARSE, clamped=("left",))
    cm.mesh.geometry.x[:, :2] *= L
    cm = cm._replace(h=cm.h * L, H=cm.H * L)
    result = fc.solve(bar_model(f1 * E / L, E=E).on(cm), method, **options)
    msh = cm.mesh
    X = ufl.SpatialCoordinate(msh)
    if method.startswith("mixed"):  # the penalized closed form of E = L = 1 (exact for the pushed mixed bar)
        exact = bar_solution(f1, epsilon=default_epsilon(1.0 / N, 1.0))
    else:
        exact = bar_solution(f1, delta=default_penalty(1.0 / N, 1.0))
    u_exact = ufl.as_vector([L * exact.u_x(X / L), 0.0])
    out = {
        "force": result.profile.force / (E * L),
        "u": _l2(result.u, msh) / L**2,
        "e_u": _l2(result.u - u_exact, msh) / _l2(u_exact, msh),
        "counts": _counts(result),
    }
    if method.startswith("mixed"):
        s_exact = ufl.as_vector([exact.sigma_xx(X / L), 0.0, 0.0])
        out["e_sigma"] = _l2(result.sigma / E - s_exact, msh) / _l2(s_exact, msh)
        out["sigma_end"] = exact.sigma_end
    return out


@pytest.mark.parametrize("f1", [1.0, -1.0], ids=["push", "pull"])
@pytest.mark.parametrize("method", METHODS)
def test_bar_in_any_units(method, f1):
    """The bar's dimensionless results and counts at E = L = 1 and in the units of ``UNITS`` agree to 1e-8."""
    ref = _bar(method, f1, 1.0, 1.0)
    if method.startswith("mixed"):  # the mixed bar's stress is the closed form (to round-off)
        assert ref["e_sigma"] < 1e-9 and abs(ref["force"] + ref["sigma_end"]) < 1e-9, ref
    for E, L in UNITS:
        got = _bar(method, f1, E, L)
        where = f"E = {E:g}, L = {L:g}: {got} against {ref}"
        assert got["counts"] == ref["counts"], where
        assert got["force"] == pytest.approx(ref["force"], rel=RTOL, abs=RTOL), where
        assert got["u"] == pytest.approx(ref["u"], rel=RTOL), where
        assert got["e_u"] == pytest.approx(ref["e_u"], rel=RTOL, abs=RTOL), where
        if method.startswith("mixed"):
            assert got["e_sigma"] < 1e-9 and abs(got["force"] + got["sigma_end"]) < 1e-9, where


#: the obstacle cases' mesh (h = 1/8, H = 1/4) and layered patch: E = 1 | 10³ | 10 across γ (x = 3/4), on the grid
N_OBSTACLE = 8
LAYERS, MODULI = np.array([0.0, 3 / 8, 7 / 8, 1.0]), np.array([1.0, 1e3, 10.0])


def _obstacle_case(case: str, L: float) -> fc.ContactProblem:
    """The layered patch (a plane moved in by 10⁻³, ν = 0) or a cylinder (R = 2, moved 0.02 into the side x = 1
    around y = ½, E = 1, ν = 0.3), every length of it scaled by L."""
    if case == "layers":

        def E(x: np.ndarray) -> np.ndarray:
            return MODULI[np.clip(np.searchsorted(LAYERS, x[0] / L, side="right") - 1, 0, MODULI.size - 1)]

        wall = fc.Plane((L, 0.0), (-1.0, 0.0)).indented(1e-3 * L, (-1.0, 0.0))
        return fc.ContactProblem(youngs_modulus=E, poisson_ratio=0.0, obstacle=wall, name="layers")
    cylinder = fc.Circle((3.0 * L, 0.5 * L), 2.0 * L).indented(0.02 * L, (-1.0, 0.0))
    return fc.ContactProblem(youngs_modulus=1.0, poisson_ratio=0.3, obstacle=cylinder, name="cylinder")


def _obstacle_run(method: str, case: str, L: float) -> dict:
    """The dimensionless results of ``_obstacle_case`` in the length unit L, with every default."""
    cm = fc.unit_square(N_OBSTACLE, N_COARSE, clamped=("left",))
    cm.mesh.geometry.x[:, :2] *= L
    cm = cm._replace(h=cm.h * L, H=cm.H * L)
    result = fc.solve(_obstacle_case(case, L).on(cm), method)
    out = {
        "force": result.profile.force / L,  # (E = 1 on Γ_C: a force per unit thickness is a stress times L)
        "u": _l2(result.u, cm.mesh) / L**2,
        "counts": _counts(result),
    }
    if case == "layers":  # the piecewise linear u_x of the exact (unpenalized) solution
        X = ufl.SpatialCoordinate(cm.mesh)
        p = 1e-3 / float(np.sum(np.diff(LAYERS) / MODULI))
        u_x = (
            -p
            * L
            * ufl.conditional(
                ufl.lt(X[0], LAYERS[1] * L),
                X[0] / L,
                ufl.conditional(
                    ufl.lt(X[0], LAYERS[2] * L),
                    LAYERS[1] + (X[0] / L - LAYERS[1]) / MODULI[1],
                    LAYERS[1] + (LAYERS[2] - LAYERS[1]) / MODULI[1] + (X[0] / L - LAYERS[2]) / MODULI[2],
                ),
            )
        )
        exact = ufl.as_vector([u_x, 0.0])
        out["e_u"] = _l2(result.u - exact, cm.mesh) / _l2(exact, cm.mesh)
    return out


@pytest.mark.parametrize("case", ["layers", pytest.param("cylinder", marks=pytest.mark.slow)])
@pytest.mark.parametrize("method", METHODS)
def test_obstacles_in_any_units(method, case):
    """The layered patch and a cylinder pressed into the side, lengths in units 10³ times smaller and larger: the
    contact force/L, ‖u‖/L², the error against the closed form (layers) and the iteration and Newton counts of
    L = 1, with every default (ε, α, β from h/L_ref, δ = 10⁻³h/E)."""
    ref = _obstacle_run(method, case, 1.0)
    assert ref["force"] > 0
    if case == "layers" and method != "mixed-ms":  # the patch test: exact up to the penalty (primal: δ/C, 1e-5);
        assert ref["e_u"] < 1e-4, ref  # (Algorithm 4's u₁ is the coarse U_aux displacement)
    for L in (1e-3, 1e3):
        got = _obstacle_run(method, case, L)
        where = f"L = {L:g}: {got} against {ref}"
        assert got["counts"] == ref["counts"], where
        for key in ("force", "u", "e_u"):
            if key in ref:
                assert got[key] == pytest.approx(ref[key], rel=RTOL, abs=RTOL * 1e-3), where


@pytest.mark.parametrize("method", ["primal", pytest.param("mixed", marks=serial)])
def test_fixed_point_iteration_in_any_units(method):
    """The plain fixed-point iteration (several iterations, no Newton update) takes as many iterations with the
    same transmission residuals in physical units as with E = L = 1."""
    options = fc.IterationOptions(tol=1e-8, accel="none")
    ref = _bar(method, 1.0, 1.0, 1.0, options=options)
    assert ref["counts"][0] > 2
    for E, L in [(2.1e11, 1.0), (2.1e5, 1e3)]:
        got = _bar(method, 1.0, E, L, options=options)
        assert got["counts"] == ref["counts"], (E, L, got, ref)
        assert got["force"] == pytest.approx(ref["force"], rel=RTOL), (E, L, got, ref)


@serial
@pytest.mark.parametrize("eigensolver", ["lapack", "krylovschur"])
def test_mixed_cem_offline_is_dimensionless(eigensolver):
    """Algorithm 4's offline phase at E = 2.1e11 (Pa): the Stage I eigenvalues (dense, or SLEPc shift-and-invert
    of the equilibrated pencil) and the coarse saddle-point matrix [[ΨᵀÃΨ, (ΠᵀBΨ)ᵀ], [ΠᵀBΨ, 0]] are those of
    E = 1 (the S-orthonormal modes make the coarse matrix dimensionless: its dense LU needs no scaling)."""

    def offline(E: float):
        cm = fc.unit_square(N, N_COARSE, clamped=("left",))
        step = MixedMultiscaleHybridStep(bar_model(E, E=E).on(cm), cem=fc.MixedCEMOptions(eigensolver=eigensolver))
        o = step.omega1
        co = o.co
        ms = slice(0, co.n_ms)
        return np.concatenate(o.aux.values), np.diff(o.aux.offsets), co.Gt[ms, ms].copy(), co.Bm[:, ms].copy()

    (lam0, l0, G0, B0), (lam, l, G, B) = offline(1.0), offline(2.1e11)
    assert np.array_equal(l, l0)
    assert np.allclose(lam, lam0, rtol=RTOL, atol=1e-10 * lam0.max())
    # the modes of a repeated eigenvalue are a basis of their span: compare what does not depend on the basis
    for X, X0 in ((G, G0), (B.T @ B, B0.T @ B0)):
        assert np.allclose(
            np.linalg.eigvalsh(0.5 * (X + X.T)),
            np.linalg.eigvalsh(0.5 * (X0 + X0.T)),
            rtol=RTOL,
            atol=RTOL * np.abs(X0).max(),
        )


def test_equilibrated_direct_solver():
    """A saddle-point matrix with a compliance block 1e-12 times its divergence block, given equilibrated (D J D,
    D = diag(s I, I/s), s = 2^20): the solves are those of J (against a dense solve)."""
    rng = np.random.default_rng(3)
    n, m = 12, 5
    G = rng.standard_normal((n, n))
    K = 1e-12 * (G @ G.T + n * np.eye(n))
    B = rng.standard_normal((m, n))
    J = np.block([[K, B.T], [B, np.zeros((m, m))]])
    s = 2.0**20
    d = np.concatenate([np.full(n, s), np.full(m, 1.0 / s)])
    b = rng.standard_normal(n + m)
    x_ref = np.linalg.solve(J, b)
    solver = DirectSolver(MPI.COMM_SELF, prefix="test_units_equilibrated_", scaling=d)
    A = scipy_to_petsc(sp.csr_matrix(d[:, None] * J * d[None, :]))
    rhs, x = A.createVecs()
    try:
        solver.set_operator(A)
        rhs.array[:] = b
        solver.solve(rhs, x)
        assert np.allclose(x.array, x_ref, rtol=1e-10, atol=1e-10 * np.abs(x_ref).max())
        assert np.array_equal(rhs.array, b)  # the right-hand side is left as it is
    finally:
        for obj in (solver, A, rhs, x):
            obj.destroy()
    lu = SparseFactor.from_csr(sp.csr_matrix(J), scaling=d)
    try:
        X = lu.solve(np.column_stack([b, 2.0 * b]))
    finally:
        lu.destroy()
    assert np.allclose(X, np.column_stack([x_ref, 2.0 * x_ref]), rtol=1e-10, atol=1e-10 * np.abs(x_ref).max())


def test_factorization_failure_names_its_cause():
    """A singular matrix: the error names the PETSc reason and MUMPS' INFOG(1), INFOG(2), and what to do."""
    singular = sp.csr_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    A = scipy_to_petsc(singular)
    solver = DirectSolver(MPI.COMM_SELF, prefix="test_units_singular_")
    try:
        with pytest.raises(
            ConvergenceError,
            match=r"test_units_singular_: factorization failed \(PETSc PC failed "
            r"reason FACTOR_\w+ \(\d\); MUMPS INFOG\(1\) = -10, INFOG\(2\) = \d+: the matrix is "
            r"numerically singular\. A singular matrix",
        ):
            solver.set_operator(A)
    finally:
        solver.destroy()
        A.destroy()
    with pytest.raises(ConvergenceError, match=r"INFOG\(1\) = -10.*numerically singular"):
        SparseFactor.from_csr(singular)


def _hertz_run(method: str, E: float, L: float) -> dict:
    """The Hertz block (a cylinder of radius 5a·20 on the graded block of ``hertz_block``) with Young's modulus E
    and every length times L, with every default: the dimensionless force, contact half-width and counts."""
    from fenics_contact.problem.analytic import hertz_errors, hertz_model
    from fenics_contact.problem.meshes import hertz_block

    a, radius, nu, depth = 0.05, 5.0, 0.3, 1.2e-3
    cm, spec = hertz_block(a, refinement=0.5)
    cm.mesh.geometry.x[:, :2] *= L
    cm = cm._replace(h=cm.h * L)
    result = fc.solve(hertz_model(radius=radius * L, E=E, nu=nu, depth=depth * L).on(cm), method)
    errors = hertz_errors(result.profile, radius=radius * L, E=E, nu=nu, h_contact=spec.h_contact * L)
    return {
        "force": result.profile.force / (E * L),
        "half_width": errors.half_width / L,
        "peak_error": errors.peak_error,
        "l2_error": errors.l2_error,
        "counts": _counts(result),
    }


@pytest.mark.slow
@pytest.mark.parametrize(
    "method",
    [
        "primal-monolithic",
        "primal",
        pytest.param("mixed-monolithic", marks=serial),
        pytest.param("mixed", marks=serial),
    ],
)
def test_hertz_block_in_any_units(method):
    """The Hertz block with lengths 10³ times larger in MPa, in Pa, and 10³ times smaller in Pa: the force/(E L)
    and the contact half-width/L of E = L = 1 to 1e-8, the pressure errors against Hertz (relative to p₀) to
    1e-9 and the same Newton counts."""
    ref = _hertz_run(method, 1.0, 1.0)
    assert ref["force"] > 0 and ref["l2_error"] < 0.05, ref
    for E, L in [(2.1e5, 1e3), (2.1e11, 1.0), (2.1e11, 1e-3)]:
        got = _hertz_run(method, E, L)
        where = f"E = {E:g}, L = {L:g}: {got} against {ref}"
        assert got["counts"] == ref["counts"], where
        for key in ("force", "half_width"):
            assert got[key] == pytest.approx(ref[key], rel=RTOL), where
        for key in ("peak_error", "l2_error"):  # differences from the exact pressure, relative to p₀: absolute
            assert got[key] == pytest.approx(ref[key], abs=0.1 * RTOL), where
