"""Tests of the Arnold–Winther stress space (fenics_contact.fem.arnold_winther).

Run from the repository root:  .venv/bin/python -m pytest tests/fem/test_arnold_winther.py -q
"""

from __future__ import annotations

import basix
import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.mesh
import dolfinx_solver  # noqa: F401  (must precede dolfinx / petsc4py)
import numpy as np
import pytest
import ufl
from aw_fields import (
    exact_fields,
    free_displacement,
    locking_displacement,
    side_facets,
    sliding_displacement,
    unit_square,
)
from mpi4py import MPI

from fenics_contact.fem.arnold_winther import (
    ArnoldWintherSpace,
    lame_parameters,
    local_nodal_basis,
    solve_mixed_elasticity,
)

RATES = np.array([2.0, 3.0, 2.0])  # ‖u-u_h‖, ‖σ-σ_h‖, ‖div(σ-σ_h)‖
EDGE_VERTICES = [(1, 2), (0, 2), (0, 1)]


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def aw_polynomial(rng):
    """A random global element of the AW space: symmetric P2 + Airy stresses of quintics."""
    c2 = rng.standard_normal((6, 3))
    ca = rng.standard_normal(6)

    def sigma(x):
        X, Y = x[0], x[1]
        out = np.zeros((3, x.shape[1]))
        k = 0
        for d in range(3):
            for p in range(d, -1, -1):
                out += c2[k][:, None] * X**p * Y ** (d - p)
                k += 1
        for a in range(6):
            b = 5 - a
            if b >= 2:
                out[0] += ca[a] * b * (b - 1) * X**a * Y ** (b - 2) / 20
            if a >= 1 and b >= 1:
                out[1] -= ca[a] * a * b * X ** (a - 1) * Y ** (b - 1) / 20
            if a >= 2:
                out[2] += ca[a] * a * (a - 1) * X ** (a - 2) * Y**b / 20
        return out

    return sigma


def l2(expr, dx):
    return np.sqrt(abs(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(expr, expr) * dx))))


def errors(space, sol, u_ex, sigma_ex, f):
    dx = ufl.dx(domain=space.mesh, metadata={"quadrature_degree": 8})
    S = space.stress(sol.sigma)
    return np.array([l2(u_ex - sol.u, dx), l2(sigma_ex - S, dx), l2(ufl.div(S) + f, dx)])


def rates(errs: list[np.ndarray]) -> np.ndarray:
    e = np.array(errs)
    return np.log2(e[:-1] / e[1:])


# ---------------------------------------------------------------------------
# unit tests
# ---------------------------------------------------------------------------


def test_local_basis_is_nodal():
    """DOF functionals (evaluated independently from the DG P3 coefficients) of the basis = I."""
    rng = np.random.default_rng(1)
    n = 50
    ref = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    # random, reasonably shaped triangles of very different sizes and positions
    verts = ref[None] + 0.25 * rng.uniform(-1, 1, (n, 3, 2))
    scale = 10.0 ** rng.uniform(-3, 2, n)
    verts = verts * scale[:, None, None] + rng.uniform(-10, 10, (n, 1, 2))
    flip = rng.integers(0, 2, (n, 3)).astype(bool)

    el = basix.ufl.element("DG", "triangle", 3).basix_element
    coeffs = local_nodal_basis(verts, flip, np.asarray(el.points))  # (n, 10, 3, 24)

    def values_at(ref_pts):  # (n, m, 3, 24) through the DG P3 representation
        tab = el.tabulate(0, ref_pts)[0, :, :, 0]  # (m, 10)
        return np.einsum("mp,npjk->nmjk", tab, coeffs)

    dofs = np.zeros((n, 24, 24))
    dofs[:, :9] = values_at(ref).reshape(n, 9, 24)
    s, w = np.polynomial.legendre.leggauss(6)
    s, w = 0.5 * (s + 1), 0.5 * w
    for k, (a, b) in enumerate(EDGE_VERTICES):
        a_, b_ = np.where(flip[:, k], b, a), np.where(flip[:, k], a, b)
        ref_pts = ref[a_][:, None, :] + s[None, :, None] * (ref[b_] - ref[a_])[:, None, :]  # (n, q, 2)
        vals = np.stack([values_at(ref_pts[i])[i] for i in range(n)])  # (n, q, 3, 24)
        d = verts[np.arange(n), b_] - verts[np.arange(n), a_]
        t = d / np.linalg.norm(d, axis=1)[:, None]
        nrm = np.stack([t[:, 1], -t[:, 0]], axis=1)
        sig = np.stack(
            [np.stack([vals[:, :, 0], vals[:, :, 1]], 2), np.stack([vals[:, :, 1], vals[:, :, 2]], 2)], 2
        )  # (n, q, 2, 2, 24)
        sn = np.einsum("nqijk,nj->nqik", sig, nrm)
        snn, snt = np.einsum("nqik,ni->nqk", sn, nrm), np.einsum("nqik,ni->nqk", sn, t)
        for l, q in enumerate([np.ones_like(s), 2 * s - 1]):
            dofs[:, 9 + 4 * k + l] = np.einsum("q,nqk->nk", w * q, snn)
            dofs[:, 9 + 4 * k + 2 + l] = np.einsum("q,nqk->nk", w * q, snt)
    qp, qw = basix.make_quadrature(basix.CellType.triangle, 8)
    dofs[:, 21:] = np.einsum("q,nqjk->njk", qw / qw.sum(), values_at(qp))
    err = np.abs(dofs - np.eye(24)).max()
    print(f"\nmax |ℓ_i(φ_j) - δ_ij| = {err:.2e}")
    assert err < 1e-10, err


def test_rejects_non_triangles():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2, dolfinx.mesh.CellType.quadrilateral)
    with pytest.raises(ValueError, match="triangle"):
        ArnoldWintherSpace(mesh)


def test_dof_counts():
    mesh = unit_square(8)
    space = ArnoldWintherSpace(mesh)
    nv, ne, nc = 81, 3 * 64 + 16, 128
    assert space.num_dofs == 3 * nv + 4 * ne + 3 * nc
    assert space.prolongation.shape == (30 * nc, space.num_dofs)


@pytest.mark.parametrize("diagonal", [None, dolfinx.mesh.DiagonalType.crossed])
def test_normal_continuity_and_div_p1(diagonal):
    """Random AW function: σn continuous across edges (σtt is not), div σ ∈ P1 cellwise."""
    mesh = unit_square(6, diagonal=diagonal, jitter=0.3, seed=3)
    space = ArnoldWintherSpace(mesh)
    c = np.random.default_rng(4).standard_normal(space.num_dofs)
    S = space.stress(space.to_dg(c))
    n = ufl.FacetNormal(mesh)
    t = ufl.as_vector([-n[1], n[0]])
    dS = ufl.dS(domain=mesh)
    scale = l2(ufl.avg(S), dS)
    jump_n = l2(ufl.jump(S, n), dS) / scale  # σ⁺n⁺ + σ⁻n⁻
    jump_tt = l2(ufl.dot(S("+") * t("+"), t("+")) - ufl.dot(S("-") * t("+"), t("+")), dS) / scale
    print(f"\nrelative ‖[σn]‖ = {jump_n:.1e}, ‖[σtt]‖ = {jump_tt:.1e}")
    assert jump_n < 1e-11, jump_n
    assert jump_tt > 1e-2  # the space is not H1: the test above is not vacuous

    # div σ_h ∈ P1: interpolation DG2 -> DG1 -> DG2 of div σ_h is the identity
    V2 = dolfinx.fem.functionspace(mesh, ("DG", 2, (2,)))
    V1 = dolfinx.fem.functionspace(mesh, ("DG", 1, (2,)))
    d2 = dolfinx.fem.Function(V2)
    d2.interpolate(dolfinx.fem.Expression(ufl.div(S), V2.element.interpolation_points))
    d1 = dolfinx.fem.Function(V1)
    d1.interpolate(d2)
    d2b = dolfinx.fem.Function(V2)
    d2b.interpolate(d1)
    rel = np.abs(d2.x.array - d2b.x.array).max() / np.abs(d2.x.array).max()
    assert rel < 1e-10, rel


def test_interpolation_reproduces_aw_polynomials():
    mesh = unit_square(5, warp=0.03, jitter=0.2)
    space = ArnoldWintherSpace(mesh)
    rng = np.random.default_rng(5)
    sigma = aw_polynomial(rng)
    exact = dolfinx.fem.Function(space.dg)
    exact.interpolate(sigma)
    err = np.abs(space.to_dg(space.interpolate(sigma)).x.array - exact.x.array).max()
    assert err < 1e-10 * np.abs(exact.x.array).max(), err

    # a symmetric P3 field with div ∉ P1 is not in the space, so it is not reproduced
    def cubic(x):
        return np.stack([x[0] ** 3, 0 * x[0], 0 * x[0]])

    exact.interpolate(cubic)
    err = np.abs(space.to_dg(space.interpolate(cubic)).x.array - exact.x.array).max()
    assert err > 1e-4


@pytest.mark.parametrize("angle", [0.0, 0.4])
def test_constrained_space_functions(angle):
    """Reduced space: σn·t ≡ 0 on the 'right' side, σn ≡ 0 on the 'bottom' side (incl. the corner)."""
    mesh = unit_square(5, jitter=0.3, angle=angle)
    right, bottom = side_facets(mesh, angle, "right"), side_facets(mesh, angle, "bottom")
    space = ArnoldWintherSpace(mesh, zero_tangential_facets=right, zero_traction_facets=bottom)
    full = ArnoldWintherSpace(mesh)
    # removed: right 5 edges x 2 σn·t moments, bottom 5 edges x 4 moments, 6 bottom vertices x 2
    # (σn = 0), 5 right vertices x 1 (σn·t = 0); at the corner σn·t = 0 is implied by σn = 0
    assert space.num_dofs == full.num_dofs - 10 - 20 - 12 - 5
    c = np.random.default_rng(6).standard_normal(space.num_dofs)
    S = space.stress(space.to_dg(c))
    tags = np.concatenate([right, bottom])
    values = np.concatenate([np.full(right.size, 1), np.full(bottom.size, 2)]).astype(np.int32)
    order = np.argsort(tags)
    mt = dolfinx.mesh.meshtags(mesh, 1, tags[order], values[order])
    ds = ufl.ds(domain=mesh, subdomain_data=mt)
    n = ufl.FacetNormal(mesh)
    t = ufl.as_vector([-n[1], n[0]])
    scale = l2(S, ds)
    assert l2(ufl.dot(S * n, t), ds(1)) / scale < 1e-12
    assert l2(S * n, ds(2)) / scale < 1e-12
    if angle == 0.0:
        assert l2(S[0, 1], ds(1)) / scale < 1e-12  # σ_xy = 0 on x = 1
    assert l2(ufl.dot(S * n, n), ds(1)) / scale > 1e-2  # normal stress stays free
    # an AW field satisfying both conditions is reproduced by the reduced interpolant:
    # in the unrotated frame σ ∈ P2 with σ_xy = p (1-x) y, σ_yy = y q1 (so σ_xy = 0 on x = 1,
    # σ_xy = σ_yy = 0 on y = 0); the mesh frame sees σ'(x) = Q σ(Qᵀx) Qᵀ
    rng = np.random.default_rng(7)
    a2, p, q1 = rng.standard_normal(6), rng.standard_normal(), rng.standard_normal(3)
    c_, s_ = np.cos(angle), np.sin(angle)
    Q = np.array([[c_, -s_], [s_, c_]])

    def sigma(x):
        X, Y = Q.T @ x[:2]
        sxx = a2 @ np.stack([np.ones_like(X), X, Y, X * X, X * Y, Y * Y])
        sxy = p * (1 - X) * Y
        syy = Y * (q1 @ np.stack([np.ones_like(X), X, Y]))
        S0 = np.array([[sxx, sxy], [sxy, syy]])  # (2, 2, N)
        S1 = np.einsum("ij,jkn,lk->iln", Q, S0, Q)
        return np.stack([S1[0, 0], S1[0, 1], S1[1, 1]])

    exact = dolfinx.fem.Function(space.dg)
    exact.interpolate(sigma)
    err = np.abs(space.to_dg(space.interpolate(sigma)).x.array - exact.x.array).max()
    assert err < 1e-10 * np.abs(exact.x.array).max(), err


# ---------------------------------------------------------------------------
# convergence
# ---------------------------------------------------------------------------


def convergence(u_fn_of_lmbda, *, nu, warp=0.0, angle=0.0, sizes=(4, 8, 16), tangential=False, traction=False):
    E = 1.0
    lmbda = lame_parameters(E, nu)[0]
    errs = []
    for n in sizes:
        mesh = unit_square(n, warp=warp, angle=angle)
        kw = {}
        if tangential:
            kw["zero_tangential_facets"] = side_facets(mesh, angle, "right")
        if traction:
            kw["zero_traction_facets"] = side_facets(mesh, angle, "right")
        space = ArnoldWintherSpace(mesh, **kw)
        u, sigma, f = exact_fields(mesh, u_fn_of_lmbda(lmbda), E, nu, angle)
        sol = solve_mixed_elasticity(space, E=E, nu=nu, f=f, u_D=u)
        errs.append(errors(space, sol, u, sigma, f))
    return np.array(errs), rates(errs)


@pytest.mark.parametrize(("nu", "warp"), [(0.3, 0.0), (0.4999, 0.0), (0.3, 0.03), (0.4999, 0.03), (0.49999999, 0.03)])
def test_convergence_dirichlet(nu, warp):
    """Homogeneous Dirichlet, locking-prone u = curl ψ + w/λ: rates (2, 3, 2) uniformly in λ."""
    errs, r = convergence(locking_displacement, nu=nu, warp=warp)
    print(f"\nnu={nu} warp={warp}\nerrors (u, sigma, div):\n{errs}\nrates:\n{r}")
    assert np.all(r[-1] >= 0.9 * RATES), r
    assert errs[-1, 1] < 1e-3


def test_convergence_zero_tangential_traction():
    """σn·t = 0 essential on the side x = 1 (normal displacement natural), Dirichlet elsewhere.

    Repeated on the mesh and solution rotated by 0.4 rad (a slanted sliding side): the discrete
    problem is rotation-equivariant, so the errors must agree to round-off.
    """
    errs, r = convergence(lambda lmbda: sliding_displacement, nu=0.3, warp=0.03, tangential=True)
    print(f"\nerrors (u, sigma, div):\n{errs}\nrates:\n{r}")
    assert np.all(r[-1] >= 0.9 * RATES), r
    errs_rot, _ = convergence(
        lambda lmbda: sliding_displacement, nu=0.3, warp=0.03, angle=0.4, tangential=True, sizes=(4, 8)
    )
    assert np.allclose(errs_rot, errs[:2], rtol=1e-8), (errs_rot, errs[:2])


def test_convergence_traction_free():
    """σn = 0 essential on the right side, Dirichlet elsewhere."""
    errs, r = convergence(lambda lmbda: free_displacement, nu=0.3, angle=0.4, traction=True)
    print(f"\nerrors (u, sigma, div):\n{errs}\nrates:\n{r}")
    assert np.all(r[-1] >= 0.9 * RATES), r


def test_sliding_side_ignores_tangential_data():
    """With σn·t = 0 on x = 1 only the normal part of u_D acts there: a tangential perturbation
    of u_D supported on x = 1 changes nothing, while it does change the unconstrained solution."""
    mesh = unit_square(8, warp=0.03)
    right = side_facets(mesh, 0.0, "right")
    u, sigma, f = exact_fields(mesh, sliding_displacement, 1.0, 0.3)
    x = ufl.SpatialCoordinate(mesh)
    delta = ufl.as_vector([0, x[0] * x[1] * (1 - x[1])])  # tangential on x = 1, 0 on the other sides
    change = []
    for kw in ({"zero_tangential_facets": right}, {}):
        space = ArnoldWintherSpace(mesh, **kw)
        a = solve_mixed_elasticity(space, E=1.0, nu=0.3, f=f, u_D=u)
        b = solve_mixed_elasticity(space, E=1.0, nu=0.3, f=f, u_D=u + delta)
        change.append(np.abs(a.sigma.x.array - b.sigma.x.array).max() / np.abs(a.sigma.x.array).max())
    assert change[0] < 1e-10, change
    assert change[1] > 1e-2, change


def test_timing_report():
    """Prints sizes and timings at h = 1/32 (the 1/64 numbers are in the report)."""
    mesh = unit_square(32)
    space = ArnoldWintherSpace(mesh)
    u, sigma, f = exact_fields(mesh, locking_displacement(lame_parameters(1.0, 0.3)[0]), 1.0, 0.3)
    sol = solve_mixed_elasticity(space, E=1.0, nu=0.3, f=f, u_D=u)
    print(f"\nAW dofs {space.num_dofs}, u dofs {sol.u.x.array.size}, timings {sol.timings}")
    assert space.num_dofs == 3 * 33**2 + 4 * (3 * 32 * 32 + 2 * 32) + 3 * 2 * 32 * 32


def test_prolongation_built_from_cell_blocks_equals_coo():
    """``cell_rows_csr`` (the CSR matrix of P built straight from the cell blocks, sorted) equals SciPy's COO
    construction, with its general path taken when the rows do not cover the matrix once."""
    import scipy.sparse as sp

    from fenics_contact.fem.arnold_winther.prolongation import cell_rows_csr

    rng = np.random.default_rng(3)
    n, a, b = 5, 4, 3
    rows = rng.permutation(n * a).reshape(n, a)
    cols = rng.integers(0, 9, size=(n, b))
    cols[:, 1] = (cols[:, 0] + 1) % 9
    cols[:, 2] = (cols[:, 0] + 4) % 9  # distinct columns per cell, in any order
    blocks = rng.standard_normal((n, a, b))
    coo = sp.csr_matrix(
        (blocks.ravel(), (np.repeat(rows, b, axis=1).ravel(), np.tile(cols, (1, a)).ravel())), shape=(n * a, 9)
    )
    order = np.argsort(cols, axis=1)  # each cell's columns increasing, as the space keeps them
    scols, sblocks = np.take_along_axis(cols, order, axis=1), np.take_along_axis(blocks, order[:, None, :], axis=2)
    assert np.all(np.diff(scols, axis=1) > 0)
    for shape in ((n * a, 9), (n * a + 2, 9)):  # the second: two empty rows, the general path
        P = cell_rows_csr(sblocks, rows, scols, shape)
        assert P.has_sorted_indices and P.shape == shape
        assert np.array_equal(P[: n * a].toarray(), coo.toarray())
    # rows 0, 1, 2, … cell by cell (a serial DG numbering): the data is a view of the blocks
    inorder = np.arange(n * a).reshape(n, a)
    P = cell_rows_csr(sblocks, inorder, scols, (n * a, 9))
    assert np.shares_memory(P.data, sblocks) and P.has_sorted_indices
    assert np.array_equal(
        P.toarray(),
        sp.csr_matrix(
            (blocks.ravel(), (np.repeat(inorder, b, axis=1).ravel(), np.tile(cols, (1, a)).ravel())), shape=(n * a, 9)
        ).toarray(),
    )
