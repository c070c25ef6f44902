"""Mixed CEM-GMsFEM (Algorithm 4) offline phase: cell-block assembly, batched MUMPS solves, npz cache.

Verification: the local operators assembled from cell blocks equal the plain sparse
products Lᵀ·blockdiag(Ã)·L and blockdiag(B)·L of a straightforward construction of
the local basis; the batched patch solves equal SciPy's sparse LU on the same saddle-
point system; basis-independent Ω₁ quantities equal the values recorded with the
previous implementation (sparse products, column-by-column MUMPS solves, METIS).
Cache: a second construction loads identical data; other options, another β, a
corrupt file or a file of another configuration are never used; an unwritable
directory is an InputError raised before the build.
"""

import logging

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI
from multiscale_oracles import stage_two_reference

import fenics_contact  # noqa: F401  (must precede dolfinx)
from fenics_contact.errors import InputError
from fenics_contact.fem import linalg
from fenics_contact.hybrid.mixed import MixedHybridStep
from fenics_contact.multiscale import mixed_cem as mm
from fenics_contact.multiscale.cem.options import DEFAULT_S_FACTOR
from fenics_contact.multiscale.coarse import coarse_grid
from fenics_contact.multiscale.mixed_cem import omega1 as mixed_omega1
from fenics_contact.multiscale.mixed_cem import skeleton
from fenics_contact.problem import geometry, models

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the mixed CEM offline phase is serial")

#: Recorded with the previous implementation (h = 1/16, H = 1/4, model 2, β = √h, m = 1, l = 3,
#: g = default_rng(0).standard_normal(n_g)): ‖σ₁‖²_A, ‖u₁‖²_L², ‖u_post‖²_L², |σ₁n₁ at γ|.
#: Basis-independent on purpose: the λ = 0 eigenspace of interior cells (rigid motions) has
#: no preferred basis, so (r, w) and the coarse matrices change with round-off; σ₁, u₁ do not.
RECORDED_M1_L3 = (0.7574110178647683, 0.007215034028909427, 0.006159654402197488, 32.165147429047046)


@pytest.fixture(scope="module")
def omega1():
    """Ω₁ of h = 1/16, H = 1/4 (3 × 4 coarse cells): coarse grid, cell operators, topology."""
    cm = geometry.unit_square(16, 4)
    step = MixedHybridStep(models.get_model(2).on(cm), beta="sqrt-h")
    part = step.parts[0]
    grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
    ops = mm.cell_operators(step.sub[0], cm.H, "lambda+2mu", DEFAULT_S_FACTOR)
    topo = mm.Topology(step.sub[0].mesh, ops.P.shape[1])
    return cm, step, grid, ops, topo


def _build(omega1, cache_dir=None, sub=None, **options):
    cm, step, grid, _, _ = omega1
    opts = mm.MixedCEMOptions(**{"layers": 1, "nbasis": 3, "min_gap": None, **options})
    return mm.MixedMultiscaleOmega1(sub or step.sub[0], grid, opts, H=cm.H, cache_dir=cache_dir)


def _blockdiag(blocks):
    return sp.block_diag([sp.coo_matrix(b) for b in blocks], format="csr")


def _patch_cells(grid, i, layers):
    return np.sort(np.concatenate([grid.cells[j] for j in grid.patch(i, layers)]).astype(np.int64))


def _cases(grid):
    interior = int(np.flatnonzero((grid.ij[:, 0] == 1) & (grid.ij[:, 1] == 1))[0])
    on_gamma = int(np.flatnonzero(grid.ij[:, 0] == grid.ij[:, 0].max())[0])
    return [(interior, 0), (interior, 1), (on_gamma, 1), (0, 2)]


# -- reference constructions ----------------------------------------------------------------------
def _reference_basis(ops, topo, cells, space):
    """L of X_h(ω) from sparse column slices of P: AW functions inside ω, then P·z at inner-boundary vertices.

    The null vector z at an inner-boundary vertex is defined up to its sign: the columns take
    the signs of ``space`` (the construction under test), after checking the shapes agree.
    """
    v_in = np.bincount(topo.c2v[cells].ravel(), minlength=topo.nv)
    e_in = np.bincount(topo.c2e[cells].ravel(), minlength=topo.ne)
    v_int = np.flatnonzero((v_in > 0) & (v_in == topo.v_deg))
    v_bnd = np.flatnonzero((v_in > 0) & (v_in < topo.v_deg))
    e_int = np.flatnonzero((e_in > 0) & (e_in == topo.e_deg))
    e_bnd = np.flatnonzero((e_in == 1) & (topo.e_deg == 2))
    inner = np.concatenate(
        [
            (3 * v_int[:, None] + np.arange(3)).ravel(),
            (3 * topo.nv + 4 * e_int[:, None] + np.arange(4)).ravel(),
            (3 * topo.nv + 4 * topo.ne + 3 * cells[:, None] + np.arange(3)).ravel(),
        ]
    )
    Pp = ops.P[mm.cell_rows(cells, 30)].tocsc()
    parts = [Pp[:, inner]]
    for v in v_bnd:
        rows = []
        for e in e_bnd[np.any(topo.e2v[e_bnd] == v, axis=1)]:
            d = topo.vx[topo.e2v[e, 1]] - topo.vx[topo.e2v[e, 0]]
            d /= np.linalg.norm(d)
            rows.append([[d[1], -d[0], 0.0], [0.0, d[1], -d[0]]])
        if rows:
            _, sv, vt = np.linalg.svd(np.vstack(rows))
            null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]
        else:
            null = np.eye(3)
        null = np.where(np.abs(null) < 1e-14, 0.0, null)
        if null.size:
            parts.append(Pp[:, 3 * v + np.arange(3)] @ sp.csr_matrix(null.T))
    L = sp.hstack(parts, format="csr")
    L.eliminate_zeros()
    assert space.L.shape == L.shape
    sign = np.where(np.asarray(space.L.multiply(L).sum(axis=0)).ravel() < 0, -1.0, 1.0)
    return (L @ sp.diags(sign)).tocsr()


def test_local_space_and_operators_match_sparse_products(omega1):
    _, _, grid, ops, topo = omega1
    for i, layers in _cases(grid):
        cells = _patch_cells(grid, i, layers)
        space = mm.local_stress_space(ops, topo, cells)
        L = _reference_basis(ops, topo, cells, space)
        assert abs(space.L - L).max() <= 1e-14 * abs(L).max()
        At, Bl = mm.local_operators(ops, space)
        At_ref = (L.T @ _blockdiag(ops.kt(cells)) @ L).tocsr()
        Bl_ref = (_blockdiag(ops.B[cells]) @ L).tocsr()
        assert abs(At - At_ref).max() <= 1e-13 * abs(At_ref).max()
        assert abs(Bl - Bl_ref).max() <= 1e-13 * abs(Bl_ref).max()
        assert abs(At - At.T).max() <= 1e-14 * abs(At).max()
        x = np.random.default_rng(i).standard_normal((space.size, 2))
        assert np.allclose(space.apply(x).reshape(-1, 2), L @ x, rtol=0, atol=1e-14 * np.abs(L @ x).max())


def test_batched_patch_solve_matches_scipy(omega1):
    _, _, grid, ops, topo = omega1
    aux = mm.stage_one(ops, topo, grid, 3)
    for i, layers in _cases(grid)[1:3]:
        space, lu, Z, *_ = mm.patch_system(ops, topo, grid, aux, grid.patch(i, layers))
        L = _reference_basis(ops, topo, space.cells, space)
        At = L.T @ _blockdiag(ops.kt(space.cells)) @ L
        Bl = _blockdiag(ops.B[space.cells]) @ L
        A = sp.bmat([[At, Bl.T, None], [Bl, None, -Z], [None, -Z.T, sp.identity(Z.shape[1])]], format="csc")
        rhs = np.random.default_rng(i).standard_normal((A.shape[0], 5))
        x = lu.solve(rhs)
        lu.destroy()
        x_ref = spla.splu(A).solve(rhs)
        assert np.linalg.norm(x - x_ref) <= 1e-10 * np.linalg.norm(x_ref)


def test_omega1_unchanged_against_recorded_values(omega1):
    om = _build(omega1)
    g = np.random.default_rng(0).standard_normal(om.co.n_g)
    r, w = om.solve(g)
    values = (
        om.stress_norm2(r, g),
        om.l2_norm2(w, g),
        om.m_norm2(om.fine_displacement_post(r, g)),
        float(np.linalg.norm(om.trace(r, g))),
    )
    assert np.allclose(values, RECORDED_M1_L3, rtol=1e-10, atol=0)
    assert np.isclose(om.a_norm2(om.fine_stress(r, g)), values[0], rtol=1e-12)


# -- offline cache ---------------------------------------------------------------------------------
def _close(rtol):
    return lambda x, y: np.allclose(x, y, rtol=rtol, atol=rtol * np.abs(x).max())


def _assert_same_online(a, b, exact=True, fields_rtol=None):
    """Every online and output map of two Ω₁ objects agrees (bitwise when ``exact``).

    ``fields_rtol``: the fine fields only to this relative tolerance (after a cache load: the patch
    functions are stored in float32, rounding 6e-8); the coarse data are float64 in the file.
    """
    same = np.array_equal if exact else _close(1e-12)
    fields = same if fields_rtol is None else _close(fields_rtol)
    rng = np.random.default_rng(7)
    g = rng.standard_normal(a.co.n_g)
    (ra, wa), (rb, wb) = a.solve(g), b.solve(g)
    assert same(ra, rb) and same(wa, wb)
    assert same(a.trace(ra, g), b.trace(rb, g))
    assert fields(a.fine_stress(ra, g), b.fine_stress(rb, g))
    assert fields(a.fine_displacement(wa, g), b.fine_displacement(wb, g))
    assert fields(a.fine_displacement_post(ra, g), b.fine_displacement_post(rb, g))
    u = rng.standard_normal((a.ops.num_cells, 6))
    assert same(a.project(u), b.project(u))
    norms = [(x.stress_norm2(r, g), x.l2_norm2(w, g)) for x, r, w in ((a, ra, wa), (b, rb, wb))]
    assert same(np.array(norms[0]), np.array(norms[1]))


def test_cache_round_trip(omega1, tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="fenics_contact.multiscale.mixed_cem")
    assert _build(omega1).cache_status == "disabled"
    first = _build(omega1, tmp_path)
    assert first.cache_status == "built"
    assert first.cache_path.is_file() and first.cache_path.parent == tmp_path
    assert f"written to {first.cache_path}" in caplog.text
    second = _build(omega1, tmp_path)
    assert second.cache_status == "loaded"
    assert f"loaded from {second.cache_path}" in caplog.text
    assert "load" in second.times and "basis" not in second.times
    _assert_same_online(first, second, fields_rtol=1e-6)
    assert len(second.basis) == len(first.basis) and len(second.corr) == len(first.corr)
    # the build is deterministic: an uncached build agrees too
    _assert_same_online(_build(omega1), first)
    # the file holds the patch functions in float32, about 4 bytes per stored coefficient
    stored = sum(f.nbytes for f in first.basis + first.corr if f is not None) // 2
    assert first.cache_path.stat().st_size < 1.2 * stored + 10 * first.co.Gt.nbytes


def test_cache_with_the_load_corrector(tmp_path):
    """A load in Ω₁ (source correctors, data index n_g) and γ correctors on one cell: the round trip keeps them."""
    cm = geometry.unit_square(16, 4)
    model = models.get_model(2).with_(load=lambda x: np.stack([np.sin(3 * x[1]), 0.5 + 0 * x[0]]))
    step = MixedHybridStep(model.on(cm), beta="sqrt-h")
    part = step.parts[0]
    grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
    opts = mm.MixedCEMOptions(layers=1)
    first = mm.MixedMultiscaleOmega1(step.sub[0], grid, opts, H=cm.H, cache_dir=tmp_path)
    second = mm.MixedMultiscaleOmega1(step.sub[0], grid, opts, H=cm.H, cache_dir=tmp_path)
    assert (first.cache_status, second.cache_status) == ("built", "loaded")
    assert all(c is not None and c.index[-1] == first.co.n_g for c in second.corr)  # every cell is loaded
    _assert_same_online(first, second, fields_rtol=1e-6)


@pytest.mark.slow
def test_cache_key_covers_options_and_beta(omega1, tmp_path):
    cm, step, grid, ops, _ = omega1
    base = _build(omega1, tmp_path)
    other = _build(omega1, tmp_path, layers=2)
    assert other.cache_status == "built" and other.cache_path != base.cache_path
    sub = step.sub[0]
    key = mm.mixed_offline_key(sub, ops, grid, base.options, H=cm.H)
    variants = [
        {"layers": 2},
        {"nbasis": 2},
        {"nbasis": None},
        {"weight": "2mu"},
        {"s_factor": 1.0},
        {"min_gap": 0.5},
        {"max_nbasis": 8},
    ]
    keys = {
        mm.mixed_offline_key(
            sub, ops, grid, mm.MixedCEMOptions(**{"layers": 1, "nbasis": 3, "min_gap": None, **v}), H=cm.H
        )
        for v in variants
    }
    assert len(keys) == len(variants) and key not in keys
    assert mm.mixed_offline_key(sub, ops, grid, base.options, H=0.5 * cm.H) != key
    # another β: another Ω₁ problem (Robin term), never the cached one
    step2 = MixedHybridStep(models.get_model(2).on(cm), beta=2.0 * step.beta)
    beta2 = _build(omega1, tmp_path, sub=step2.sub[0])
    assert beta2.cache_status == "built" and beta2.cache_path != base.cache_path
    assert _build(omega1, tmp_path, sub=step2.sub[0]).cache_status == "loaded"
    assert _build(omega1, tmp_path).cache_status == "loaded"


@pytest.mark.slow
def test_corrupt_or_foreign_cache_file_is_rebuilt(omega1, tmp_path, caplog):
    first = _build(omega1, tmp_path)
    path = first.cache_path
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    # one stored value changed: checksum mismatch
    bad = dict(arrays)
    bad["fn_b_0000000_sigma"] = bad["fn_b_0000000_sigma"].copy()
    bad["fn_b_0000000_sigma"][5] += 1.0
    np.savez(path, **bad)
    again = _build(omega1, tmp_path)
    assert again.cache_status == "rebuilt (invalid: checksum mismatch (corrupt file))"
    assert "rejected" in caplog.text
    _assert_same_online(first, again)  # both built
    assert _build(omega1, tmp_path).cache_status == "loaded"  # the rebuild rewrote the file
    # a file of another configuration under this name
    np.savez(path, **{**arrays, "key": np.array("0" * 64)})
    assert _build(omega1, tmp_path).cache_status == "rebuilt (invalid: stored key differs (another configuration))"
    # a truncated file
    with open(path, "r+b") as fh:
        fh.truncate(100)
    truncated = _build(omega1, tmp_path)
    assert truncated.cache_status.startswith("rebuilt (invalid: ")
    _assert_same_online(first, truncated)
    assert _build(omega1, tmp_path).cache_status == "loaded"


def test_unwritable_cache_directory_is_an_error_before_the_build(omega1, tmp_path):
    blocker = tmp_path / "not_a_directory"
    blocker.write_text("")
    with pytest.raises(InputError, match="not writable"):
        _build(omega1, blocker)
    with pytest.raises(InputError, match="not writable"):
        _build(omega1, blocker / "cache")


# -- Stage II by static condensation against one LU per patch ----------------------------------------
def _energy(ops, dofs, f, j):
    """Per column: (Ã-energy of the patch function f's stress on its j-th coarse cell, displacement L² mass)."""
    K = int(f.coarse[j])
    s = dofs.dg(ops, K, f.sigma[j])  # (|K|, 30, k)
    cells = dofs.cells[K]
    e_s = np.einsum("cak,cab,cbk->k", s, ops.kt(cells), s)
    u = f.u[j].reshape(cells.size, 6, -1)
    return e_s, np.einsum("cak,cab,cbk->k", u, ops.M[cells], u)


def _relative_difference(ops, dofs, a, b):
    """max over the functions of ‖a − b‖/‖a‖ (stress in the Ã-norm, displacement in L²)."""
    worst = 0.0
    for fa, fb in zip(a, b):
        assert (fa is None) == (fb is None)
        if fa is None:
            continue
        assert np.array_equal(fa.coarse, fb.coarse) and np.array_equal(fa.index, fb.index)
        diff = mm.PatchFunctions(
            fa.coarse, fa.index, [x - y for x, y in zip(fa.sigma, fb.sigma)], [x - y for x, y in zip(fa.u, fb.u)]
        )
        num = sum(np.array(_energy(ops, dofs, diff, j)) for j in range(fa.coarse.size))
        den = sum(np.array(_energy(ops, dofs, fa, j)) for j in range(fa.coarse.size))
        worst = max(worst, float(np.sqrt(num / den).max()))
    return worst


def test_symmetric_factorization_and_its_lu_fallback(caplog):
    """``LocalFactor.symmetric`` (Stage II skeleton systems, given by their upper triangle) solves an SPD system
    by Cholesky, and an indefinite symmetric one (where Cholesky meets a negative pivot) through the LU of
    the full matrix, both to rounding."""
    rng = np.random.default_rng(5)
    n = 60
    Q = sp.random(n, n, density=0.1, random_state=7) + sp.eye(n)
    spd = (Q @ Q.T + sp.eye(n)).tocsr()
    indefinite = (spd - 3.0 * sp.diags(np.linspace(0.0, 1.0, n)) * spd.diagonal().max()).tocsr()
    assert np.linalg.eigvalsh(indefinite.toarray()).min() < 0
    b = rng.standard_normal((n, 3))
    for A, fallback in ((spd, False), (indefinite, True)):
        caplog.clear()
        with caplog.at_level(logging.DEBUG, logger=linalg.log.name):
            lu = mm.LocalFactor.symmetric(sp.triu(A).tocsr())
        assert ("LU instead of Cholesky" in caplog.text) == fallback
        try:
            x = lu.solve(b)
        finally:
            lu.destroy()
        assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_gram_of_cell_blocks():
    """``gram`` (the coarse operators' Σ_c F_cᵀ A_c F_c by batched Cholesky and a symmetric product) equals the plain
    sum, also when a block is not positive definite (then the general product is taken)."""
    rng = np.random.default_rng(6)
    X = rng.standard_normal((5, 24, 24))
    spd = X @ np.swapaxes(X, 1, 2) + 0.1 * np.eye(24)
    F = rng.standard_normal((5, 24, 7))
    for A in (spd, spd - 50.0 * np.eye(24)):
        ref = sum(F[c].T @ A[c] @ F[c] for c in range(5))
        assert np.linalg.norm(mm.gram(A, F) - ref) <= 1e-12 * np.linalg.norm(ref)
    assert np.linalg.eigvalsh(spd - 50.0 * np.eye(24)).min() < 0


def test_cell_blocks_read_off_the_csr_arrays():
    """``cell_blocks`` and ``row_blocks`` read the blocks straight off the CSR arrays when each cell's rows hold
    exactly the cell's columns; the result equals the general sparse extraction for cells whose columns are in
    increasing order, in another order, and for a matrix whose pattern does not allow the shortcut; for rows
    scattered over the matrix, for each cell's rows a whole block of consecutive rows (cells permuted), and for
    the cells' rows in row order (then the blocks of both are views of the matrix data)."""
    rng = np.random.default_rng(7)
    n, a, b = 6, 3, 4
    perm = rng.permutation(n * b)
    layouts = [
        rng.permutation(n * a).reshape(n, a),
        a * rng.permutation(n)[:, None] + np.arange(a),
        np.arange(n * a).reshape(n, a),
    ]
    for cols, rows in ((c, r) for c in (np.arange(n * b).reshape(n, b), perm.reshape(n, b)) for r in layouts):
        blocks = rng.standard_normal((n, a, b))
        A = sp.csr_matrix(
            (blocks.ravel(), (np.repeat(rows, b, axis=1).ravel(), np.tile(cols, (1, a)).ravel())),
            shape=(n * a, n * b + 1),
        )
        got = mm.cell_blocks(A, rows, cols)
        assert np.array_equal(got, blocks)
        if rows is layouts[2] and np.all(np.diff(cols, axis=1) > 0):
            assert np.shares_memory(got, A.data)  # the cells in row order, columns increasing: no copy
        general = A.tolil()
        general[rows[0, 0], n * b] = 1.0  # a row with a column outside its cell: no shortcut
        general = general.tocsr()
        assert np.array_equal(mm.cell_blocks(general, rows, cols), blocks)
        c, v = mm.row_blocks(A, rows)
        c0, v0 = mm.column_blocks(A[rows.ravel()], n, a)
        assert np.array_equal(c, c0) and np.array_equal(v, v0)
        if rows is layouts[2]:
            assert np.shares_memory(v, A.data)  # the cells' rows in row order: a view, no index array
        c, v = mm.row_blocks(general, rows)  # cell 0's rows differ in their columns: the general path
        c0, v0 = mm.column_blocks(general[rows.ravel()], n, a)
        assert np.array_equal(c, c0) and np.array_equal(v, v0)


@pytest.mark.slow
def test_condensed_stage_two_equals_per_patch_lu(omega1):
    """The substructured Stage II (coarse cells condensed onto the skeleton) solves the same patch systems
    as one sparse LU per patch: bases, Robin and source correctors agree to rounding, also with a
    traction-free side of Ω₁ (vertex functions on it), loads f and F on every coarse cell and 1–2 layers.

    (m = 0 is left out: on an interior coarse cell, whose whole boundary is traction free, the stress part of
    the Stage II solution is not unique and both constructions return different ones; measured stress-equation
    residuals O(1) for both.)"""
    import dataclasses

    from dolfinx import mesh as dmesh

    _, step, grid, ops, topo = omega1
    msh = step.sub[0].mesh
    msh.topology.create_connectivity(1, 2)
    bfacets = dmesh.exterior_facet_indices(msh.topology)
    top = bfacets[np.isclose(dmesh.compute_midpoints(msh, 1, bfacets)[:, 1], 1.0)]
    rng = np.random.default_rng(3)
    loaded = dataclasses.replace(
        ops,
        G=rng.standard_normal(ops.G.shape),  # f, and the stress-side load F
        F=rng.standard_normal((ops.num_cells, 30)),
    )  # of boundary data
    dofs = mm.CoarseCellDofs.of(ops, grid)
    for tp in (topo, mm.Topology(msh, ops.num_aw, top)):
        aux = mm.stage_one(loaded, tp, grid, 3)
        for layers in (1, 2):
            new = mm.stage_two(loaded, tp, grid, aux, layers, dofs=dofs)
            ref = stage_two_reference(loaded, tp, grid, aux, layers, dofs=dofs)
            assert all(c is not None and c.index[-1] == ops.num_gamma_values for c in new[1])  # load everywhere
            assert _relative_difference(loaded, dofs, ref[0], new[0]) < 1e-10
            assert _relative_difference(loaded, dofs, ref[1], new[1]) < 1e-10


def test_back_substitution_with_and_without_the_kept_factors(omega1, monkeypatch):
    """The back substitution of the condensed Stage II uses each coarse cell's LU kept from the condensation, up to
    ``KEEP_FACTORS_BYTES`` per rank, and assembles and factorizes the others again: the same bases and correctors
    (to the rounding of these saddle-point systems, 1e-10 as against one LU per patch above; measured 2.4e-13: a new
    LU solves for M_II⁻¹ b_I as the condensation did) whether all, some or none are kept, with loads on every cell
    (the own right-hand sides)."""
    import dataclasses

    _, _, grid, ops, topo = omega1
    loaded = dataclasses.replace(ops, G=np.random.default_rng(4).standard_normal(ops.G.shape))
    dofs = mm.CoarseCellDofs.of(ops, grid)
    aux = mm.stage_one(loaded, topo, grid, 3)
    ref = mm.stage_two(loaded, topo, grid, aux, 1, dofs=dofs)
    for budget in (0.0, 2.0e6):  # none kept; two of the 12 kept (0.6–0.8 MB each)
        monkeypatch.setattr(skeleton, "KEEP_FACTORS_BYTES", budget)
        new = mm.stage_two(loaded, topo, grid, aux, 1, dofs=dofs)
        assert _relative_difference(loaded, dofs, ref[0], new[0]) < 1e-10
        assert _relative_difference(loaded, dofs, ref[1], new[1]) < 1e-10


@pytest.mark.slow
def test_condensed_stage_two_at_contrast_1e6_nearly_incompressible():
    """The hard case of the condensed Stage II: model 3 (channels through γ, inclusions cut by γ) at contrast 10⁶
    with ν = 0.4999, the top and the bottom traction free, the default Stage I rule (more modes where Λ is
    small).  Against one LU per patch the bases agree to 2.3e-6 and the correctors to 4.6e-8 (measured; the same
    with LU instead of Cholesky for the skeleton systems: the rounding of these ill-conditioned patch systems,
    1e-10 at contrast 10³ above)."""
    from fenics_contact.multiscale.mixed import essential_traction_facets

    cm = geometry.unit_square(16, 4, clamped=("left",))
    step = MixedHybridStep(models.get_model(3, E_high=1e6, nu=0.4999).on(cm), beta="sqrt-h")
    part = step.parts[0]
    grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
    ops = mm.cell_operators(step.sub[0], cm.H, "lambda+2mu", DEFAULT_S_FACTOR)
    topo = mm.Topology(step.sub[0].mesh, ops.P.shape[1], essential_traction_facets(part.mesh, part.facet_tags))
    dofs = mm.CoarseCellDofs.of(ops, grid)
    aux = mm.stage_one(ops, topo, grid, 3, 0.1, 32)
    new = mm.stage_two(ops, topo, grid, aux, 1, dofs=dofs)
    ref = stage_two_reference(ops, topo, grid, aux, 1, dofs=dofs)
    assert _relative_difference(ops, dofs, ref[0], new[0]) < 1e-5
    assert _relative_difference(ops, dofs, ref[1], new[1]) < 1e-6


@pytest.mark.slow
def test_algorithm4_unchanged_by_the_condensed_stage_two(monkeypatch):
    """Algorithm 4 end to end (load in Ω₁ and Ω₂): coarse operators, e_σ, e_u and the solution fields equal
    those computed with one LU per patch (``stage_two_reference``) to 1e-10."""
    from fenics_contact.fem.mixed import solve_mixed_monolithic
    from fenics_contact.hybrid.iteration import IterationOptions
    from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid

    cm = geometry.unit_square(16, 4)
    model = models.get_model(2).with_(
        load=models.band_load([(0.25, 0.875, 0.3, 0.7, 2.0), (0.5, 0.875, 0.7, 1.0, -1.0)])
    )
    ref = solve_mixed_monolithic(model.on(cm))
    runs = []
    for stage_two in (mm.stage_two, stage_two_reference):
        monkeypatch.setattr(mixed_omega1, "stage_two", stage_two)
        runs.append(
            solve_mixed_ms_hybrid(
                model.on(cm),
                cem=mm.MixedCEMOptions(layers=2),
                reference=ref,
                options=IterationOptions(tol=1e-10, max_iterations=400),
            )
        )
    new, old = runs
    assert new.converged and old.converged
    co_new, co_old = new.step.omega1.co, old.step.omega1.co
    for name in mm.COARSE_ARRAYS:
        x, y = getattr(co_new, name), getattr(co_old, name)
        assert np.linalg.norm(x - y) <= 1e-10 * np.linalg.norm(y), name
    # the errors are relative to the reference's norm: a change δ·‖u‖ of the solution moves them by up to δ, so
    # they must agree to 1e-10 absolutely, as the fields do (e_u_post = 3e-4 here and moves by 5e-14, i.e.
    # 1.7e-10 of itself: Arnold–Winther bases that differ by rounding, 1e-14, move it that much)
    for attr in ("e_sigma", "e_u", "e_u_post"):
        assert abs(getattr(new, attr) - getattr(old, attr)) <= 1e-10, attr
    for a, b in ((new.sigma, old.sigma), (new.u, old.u)):
        assert np.linalg.norm(a.x.array - b.x.array) <= 1e-10 * np.linalg.norm(b.x.array)


def test_skeleton_factorizations_reuse_the_analysis_of_a_pattern():
    """``ReusedAnalysis``: a second SPD matrix with the pattern of a kept one is factorized on the kept analysis
    (no new factorization object) and solves exactly as a fresh factorization does; a matrix of that pattern that
    is not positive definite falls back to a fresh LU that the caller owns; other patterns are factorized afresh,
    and at most ``keep`` factorizations are kept."""
    rng = np.random.default_rng(3)
    n = 40

    def spd(pattern_seed: int, shift: float = 0.0) -> sp.csr_matrix:
        r = np.random.default_rng(pattern_seed)
        mask = sp.random(n, n, density=0.15, random_state=r, format="csr")
        mask = mask + mask.T + sp.eye(n)
        vals = mask.copy()
        vals.data = rng.standard_normal(vals.nnz)
        vals = vals + vals.T
        vals = vals + sp.diags(np.abs(vals).sum(axis=1).A1 + 1.0 - shift)  # diagonally dominant unless shifted
        return sp.triu(vals, format="csr")

    cache = linalg.ReusedAnalysis(keep=2)
    b = rng.standard_normal((n, 3))
    first = spd(0)
    lu0, own0 = cache.factor(first)
    assert not own0 and lu0.positive and len(cache.entries) == 1
    second = spd(0)  # the same pattern, other values
    assert np.array_equal(second.indptr, first.indptr) and np.array_equal(second.indices, first.indices)
    lu1, own1 = cache.factor(second)
    assert lu1 is lu0 and not own1  # the kept factorization, refactorized
    fresh = linalg.SparseFactor.symmetric(second.copy())
    x, x_fresh = lu1.solve(b), fresh.solve(b)
    fresh.destroy()
    full = (second + sp.triu(second, 1).T).toarray()
    assert np.abs(full @ x - b).max() < 1e-10 * np.abs(b).max()
    assert np.array_equal(x, x_fresh)  # the same ordering: the same factors
    indefinite = spd(0, shift=1e3)  # same pattern, negative pivots
    lu2, own2 = cache.factor(indefinite)
    assert own2 and not lu2.positive and not cache.entries  # the kept one was dropped, the LU is the caller's
    full = (indefinite + sp.triu(indefinite, 1).T).toarray()
    assert np.abs(full @ lu2.solve(b) - b).max() < 1e-8 * np.abs(b).max() * np.linalg.cond(full)
    lu2.destroy()
    for seed in (1, 2, 3):
        cache.factor(spd(seed))
    assert len(cache.entries) == 2  # the two most recent patterns
    cache.release()
    assert not cache.entries


@pytest.mark.slow
def test_stage_two_analyses_each_skeleton_pattern_once(monkeypatch):
    """Serially the patches are grouped by class (``_patch_classes``: translates), so MUMPS analyses each
    distinct skeleton sparsity pattern once (h = 1/64, H = 1/16, m = 3: 81 patterns among 240 patches against 144
    analyses in index order; here h = 1/32, H = 1/8, m = 2)."""
    import hashlib

    patterns, fresh = [], []
    factor, symmetric = linalg.ReusedAnalysis.factor, mm.LocalFactor.symmetric.__func__

    def counting_factor(self, upper):
        patterns.append(hashlib.sha1(upper.indptr.tobytes() + upper.indices.tobytes()).hexdigest())
        return factor(self, upper)

    def counting_symmetric(cls, upper):
        fresh.append(1)
        return symmetric(cls, upper)

    monkeypatch.setattr(linalg.ReusedAnalysis, "factor", counting_factor)
    monkeypatch.setattr(mm.LocalFactor, "symmetric", classmethod(counting_symmetric))
    cm = geometry.unit_square(32, 8)
    step = MixedHybridStep(models.get_model(2).on(cm), beta="sqrt-h")
    grid = coarse_grid(step.parts[0].mesh, step.parts[0].cell_map, cm.coarse_cell, cm.H)
    ops, topo, aux = mm.stage_one_of(step.sub[0], grid, mm.MixedCEMOptions(layers=2), H=cm.H)
    mm.stage_two(ops, topo, grid, aux, 2)
    assert len(patterns) == grid.size == 56
    assert len(fresh) == len(set(patterns)) < grid.size  # one analysis per pattern, not one per patch
