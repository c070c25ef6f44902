"""The showcase's composite block (``problem.meshes.composite_block``) and the dense fallback of the CEM
local spectral problems that its stiff inclusions made necessary."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
from mpi4py import MPI

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.eigen import generalized_eigenpairs
from fenics_contact.multiscale import cem
from fenics_contact.multiscale.cem import spectral
from fenics_contact.problem.meshes import composite_block
from fenics_contact.problem.tags import Boundary, Subdomain
from fenics_contact.problem.validation import validate_contact_mesh


def _midpoints(cm, cells):
    x = cm.mesh.geometry.x
    return x[cm.mesh.geometry.dofmaps[0][cells]].mean(axis=1)


def test_composite_block_tags_coarse_grid_and_inclusions():
    a = 0.05
    cm, block = composite_block(a, refinement=0.25)
    validate_contact_mesh(cm)
    comm = cm.comm
    # every Ω₁ cell lies in one coarse square of side H = 4a (the grid is resolved)
    omega1 = cm.cell_tags.find(Subdomain.OMEGA1)
    assert cm.H == pytest.approx(4 * a) and comm.allreduce(int(np.sum(cm.coarse_cell[omega1] < 0)), MPI.SUM) == 0
    # Ω₂ is the top row of coarse squares: y > −H
    mid2 = _midpoints(cm, cm.cell_tags.find(Subdomain.OMEGA2))
    assert np.all(mid2[:, 1] > -block.H)
    assert np.all(_midpoints(cm, omega1)[:, 1] < -block.H)
    # γ cuts inclusions (the fibre under the contact among them); none touches a coarse grid line elsewhere
    boxes = np.array(block.inclusions)
    cut = (boxes[:, 2] < -block.H) & (boxes[:, 3] > -block.H)
    assert cut.sum() >= 3 and np.any(cut & (boxes[:, 0] < 0) & (boxes[:, 1] > 0))
    lines = -block.half_width + block.H * np.arange(int(round(2 * block.half_width / block.H)) + 1)
    assert not np.any((boxes[:, 0, None] < lines - 1e-12) & (boxes[:, 1, None] > lines + 1e-12))
    # the sides are ≥ 20a from Γ_C, clamped with the bottom; Γ_C is the top segment |x| <= 3a
    assert block.half_width - block.contact_width >= 20 * a
    fx = cm.mesh.geometry.x
    cm.mesh.topology.create_connectivity(1, 0)
    f2v = cm.mesh.topology.connectivity(1, 0)

    def on_contact(p):
        return np.all(np.abs(p[:, 1]) < 1e-12) and np.all(np.abs(p[:, 0]) <= 3 * a + 1e-12)

    def on_clamped(p):
        return np.all((np.abs(np.abs(p[:, 0]) - block.half_width) < 1e-12) | (np.abs(p[:, 1] + block.depth) < 1e-12))

    for tag, check in [(Boundary.GAMMA_C, on_contact), (Boundary.GAMMA_D, on_clamped)]:
        facets = cm.facet_tags.find(tag)
        points = fx[np.concatenate([f2v.links(f) for f in facets])] if facets.size else np.zeros((0, 3))
        assert check(points)
    # E from the block: the inclusions' cells (resolved by the mesh) are stiff
    E = block.modulus(1e3, 1.0)(_midpoints(cm, np.arange(cm.mesh.topology.index_map(2).size_local)).T)
    assert set(np.unique(E)) == {1.0, 1e3}


def test_composite_block_bad_sizes():
    with pytest.raises(InputError):
        composite_block(0.05, width=48.0)  # an even number of coarse columns: x = 0 on a grid line
    with pytest.raises(InputError):
        composite_block(-1.0)
    with pytest.raises(InputError):
        composite_block(0.05, inclusion=5.0)


def test_local_spectral_problem_falls_back_to_lapack(monkeypatch):
    """When Krylov–Schur keeps missing an eigenpair (as it did on a coarse cell cut through stiff inclusions:
    a triple zero and λ₄ ≈ 5e-3, clustered by the shift −1), the pairs come from the dense solver."""
    rng = np.random.default_rng(1)
    n = 60
    X = rng.standard_normal((n, n))
    S = sp.csr_matrix(X @ X.T + n * np.eye(n))
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    lam = np.concatenate([[0.0, 0.0, 0.0], np.linspace(5e-3, 1.0, n - 3)])
    L = np.linalg.cholesky(S.toarray())
    A = sp.csr_matrix(L @ Q @ np.diag(lam) @ Q.T @ L.T)  # A φ = λ S φ with the eigenvalues lam
    A = (A + A.T) * 0.5
    exact = scipy.linalg.eigh(A.toarray(), S.toarray(), eigvals_only=True)[:4]
    pairs = generalized_eigenpairs

    def missing_one(Ap, Sp, nev, kind, **kwargs):  # a Krylov–Schur that always loses the first pair
        values, vectors = pairs(Ap, Sp, nev, kind, **kwargs)
        return (values[1:], vectors[:, 1:]) if kind == "krylovschur" else (values, vectors)

    monkeypatch.setattr(spectral, "generalized_eigenpairs", missing_one)
    with monkeypatch.context() as m:  # without the fallback the miss is a ConvergenceError
        m.setattr(spectral, "DENSE_FALLBACK", 10)
        with pytest.raises(ConvergenceError, match="could not find all 4"):
            cem.local_spectral_problem(A, S, 4, eigensolver="krylovschur")
    values, vectors = cem.local_spectral_problem(A, S, 4, eigensolver="krylovschur")
    assert np.allclose(values, exact, atol=1e-10)
    assert np.allclose(vectors.T @ (S @ vectors), np.eye(4), atol=1e-10)
    assert np.allclose(A @ vectors, (S @ vectors) * values, atol=1e-8)
