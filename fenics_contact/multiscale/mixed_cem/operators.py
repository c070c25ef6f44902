"""Cellwise operators of Ω₁ for the mixed CEM (Algorithm 4): ``CellOperators`` and ``cell_operators``.

The compliance, the Robin term on γ, the divergence, the masses and the κ̃-weighted mass as cell blocks of the
Ω₁ ``fem.mixed.MixedSubproblem`` (cell-major layout, ``blocks``), the interface maps C (Robin data → τ rows)
and E (σn₁ at the γ nodes), the AW prolongation by cell, and the boundary data: the traction lifting s₀
(σ = σ̂ + s₀, s₀n = t on Γ_N) and the stress-side load F = −(A s₀, τ) − β∫_γ(s₀n)·(τn) + ∫_ΓD u_D·(τn).
"""

from dataclasses import dataclass

import basix.ufl
import dolfinx.la
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from scipy.spatial import cKDTree

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.matrices import assemble_scipy
from fenics_contact.multiscale.cem.operators import kappa_tilde
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.blocks import cell_blocks, row_blocks
from fenics_contact.problem.tags import Boundary

__all__ = ["CellOperators", "cell_operators", "scale_to_cell_sizes"]


@dataclass(slots=True)
class CellOperators:
    """Cell blocks and interface maps of the Ω₁ mixed problem in the cell-major layout."""

    K: np.ndarray  #: (n, 30, 30) compliance (Aσ, τ)
    R: np.ndarray  #: (n_γ, 30, 30) β ∫_γ (σn)·(τn) on the cells ``gamma_cells`` (zero elsewhere)
    B: np.ndarray  #: (n, 6, 30) (div σ, v)
    M: np.ndarray  #: (n, 6, 6) L² mass of DG P1
    S: np.ndarray  #: (n, 6, 6) κ̃-weighted mass, κ̃ = (λ+2μ)H⁻²
    G: np.ndarray  #: (n, 6) −(f, v)
    C: sp.csr_matrix  #: (30 n, n_g) ∫_γ g·(τn₁), g by values (x, y) at the γ nodes
    E: sp.csr_matrix  #: (n_g, 30 n) σn₁ at the γ nodes (average of the two sides at vertices)
    num_aw: int  #: dim AW(Ω₁)
    dg_rows: np.ndarray  #: (n, 30) standard DG P3 index of each cell-major stress entry
    u_rows: np.ndarray  #: (n, 6) standard DG P1 index of each cell-major displacement entry
    gamma_cells: np.ndarray  #: sorted cells with a γ facet
    P_cols: np.ndarray  #: (n, w) AW indices of the nonzero columns of P in the rows of each cell (sorted, −1 pads)
    P_blocks: np.ndarray  #: (n, 30, w) those columns of P: P[rows of c][:, P_cols[c]]
    #: (n, 30) stress-side load of the boundary data, a functional on DG P3 stresses:
    #: −(A s₀, τ) − β∫_γ (s₀n)·(τn) + ∫_ΓD u_D·(τn); None (zero) without tractions and u_D
    F: np.ndarray | None = None
    #: (n, 30) the traction lifting s₀ (σ₁ = homogeneous part + s₀, s₀n = t on Γ_N); None without tractions
    s0: np.ndarray | None = None
    #: s of the equilibration D = diag(s I_σ, I_u/s, I_y) of the local saddle-point factorizations (the Ω₁
    #: subproblem's ``stress_scale``: s² ≈ E_ref, so D's blocks are O(1) in any units)
    scale: float = 1.0

    @property
    def has_boundary_data(self) -> bool:
        """Whether tractions or a prescribed displacement act on Ω₁ (a stress-side load F or a lifting s₀)."""
        return self.F is not None or self.s0 is not None

    @property
    def num_cells(self) -> int:
        return self.K.shape[0]

    def kt(self, cells: np.ndarray) -> np.ndarray:
        """Blocks (|cells|, 30, 30) of Ã = compliance + β ∫_γ (σn)·(τn) (only γ cells carry the Robin term)."""
        cells = np.asarray(cells, dtype=np.int64)
        out = self.K[cells]
        k = np.searchsorted(self.gamma_cells, cells)
        on = (k < self.gamma_cells.size) & (self.gamma_cells[np.minimum(k, self.gamma_cells.size - 1)] == cells)
        if np.any(on):
            out[on] += self.R[k[on]]
        return out

    @property
    def P(self) -> sp.csr_matrix:
        """The AW prolongation (30 n × dim AW), rows cell-major (rebuilt from the cell blocks)."""
        n, a, w = self.P_blocks.shape
        rows = np.broadcast_to((a * np.arange(n)[:, None, None] + np.arange(a)[None, :, None]), self.P_blocks.shape)
        cols = np.broadcast_to(self.P_cols[:, None, :], self.P_blocks.shape)
        keep = (cols >= 0) & (self.P_blocks != 0.0)
        return sp.csr_matrix((self.P_blocks[keep], (rows[keep], cols[keep])), shape=(a * n, self.num_aw))

    @property
    def num_gamma_values(self) -> int:
        return self.C.shape[1]


def _trace_operator(
    msh: dmesh.Mesh, dg: fem.FunctionSpace, gamma: np.ndarray, points: np.ndarray, facet: np.ndarray | None = None
) -> sp.csr_matrix:
    """σn (outward normal) at ``points`` on the γ facets, cell-major columns; averaged where two facets meet
    (``facet``: per point the index into ``gamma`` of the one facet to use, −1 for any)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    geo = dmesh.entities_to_geometry(msh, tdim - 1, gamma)
    x = msh.geometry.x[:, :2]
    a, b = x[geo[:, 0]], x[geo[:, 1]]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    cells = f2c.array[f2c.offsets[gamma]].astype(np.int64)  # a γ facet is on ∂Ω₁: one cell
    n = np.stack([d[:, 1], -d[:, 0]], axis=1) / length[:, None]
    centre = x[msh.geometry.dofmaps[0][cells]].mean(axis=1)
    n[np.sum(n * (0.5 * (a + b) - centre), axis=1) < 0] *= -1.0
    # (point, facet) incidences
    rel = points[:, None, :] - a[None]
    s = np.einsum("pfi,fi->pf", rel, d) / length[None] ** 2
    dist = np.linalg.norm(rel - s[..., None] * d[None], axis=-1)
    on = (dist <= 1e-10 * length[None]) & (s >= -1e-10) & (s <= 1 + 1e-10)
    if facet is not None:
        on &= (facet[:, None] < 0) | (facet[:, None] == np.arange(gamma.size)[None, :])
    pi, fi = np.nonzero(on)
    if np.unique(pi).size != points.shape[0]:
        raise RuntimeError("a γ node lies on no γ facet")
    weight = 1.0 / np.bincount(pi, minlength=points.shape[0])[pi]
    c = cells[fi]
    gx = x[msh.geometry.dofmaps[0][c]]
    J = np.stack([gx[:, 1] - gx[:, 0], gx[:, 2] - gx[:, 0]], axis=-1)
    X = np.linalg.solve(J, (points[pi] - gx[:, 0])[..., None])[..., 0]
    el = dg.ufl_element().sub_elements[0].basix_element
    phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 10)
    nn = n[fi]
    rows, cols, vals = [], [], []
    base = 30 * c[:, None] + 3 * np.arange(10)[None, :]  # (N, 10)
    for comp, (j, w) in enumerate([(0, nn[:, 0]), (1, nn[:, 1]), (1, nn[:, 0]), (2, nn[:, 1])]):
        row = 2 * pi + (0 if comp < 2 else 1)
        rows.append(np.repeat(row, 10))
        cols.append((base + j).ravel())
        vals.append((phi * (w * weight)[:, None]).ravel())
    ncell = msh.topology.index_map(tdim).size_local
    E = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * points.shape[0], 30 * ncell)
    )
    E.sum_duplicates()
    return E


def _bent_trace_operator(msh: dmesh.Mesh, dg: fem.FunctionSpace, gamma: np.ndarray, bends) -> sp.csr_matrix:
    """σn at the γ nodes as the stored data values of ``bends`` (``fem.mixed_interface.GammaBends``): averaged
    where two facets meet at a straight vertex, each side of a bend on its own facet, the two sides' values
    projected onto the bend's data space (the coefficients in its orthonormal basis)."""
    x = msh.geometry.x[:, :2]
    mid = x[dmesh.entities_to_geometry(msh, msh.topology.dim - 1, gamma)].mean(axis=1)
    n = bends.points.shape[0]
    plain = np.setdiff1d(np.arange(n), bends.nodes)
    side_facets = [cKDTree(mid).query(bends.side_midpoints[:, side])[1] for side in range(2)]
    points = np.concatenate([bends.points[plain], bends.points[bends.nodes], bends.points[bends.nodes]])
    facet = np.concatenate([np.full(plain.size, -1), *side_facets])
    copy_row = np.concatenate([2 * plain, 2 * bends.nodes, 2 * n + 2 * np.arange(bends.nodes.size)])
    E = _trace_operator(msh, dg, gamma, points, facet).tocoo()
    rows = copy_row[E.row // 2] + E.row % 2
    copies = sp.csr_matrix((E.data, (rows, E.col)), shape=(bends.num_copy_values, E.shape[1]))
    return (bends.basis.T @ copies).tocsr()


def cell_operators(sub, H: float, weight: str = "lambda+2mu", s_factor: float = 1.0) -> CellOperators:
    """Cell-major operators of the Ω₁ ``fem.mixed.MixedSubproblem`` ``sub`` (Robin β, no contact)."""
    msh, ft, fields = sub.mesh, sub.facet_tags, sub.fields
    if sub.beta is None:
        raise InputError("the Ω₁ subproblem needs a Robin coefficient β")
    tdim = msh.topology.dim
    ncell = msh.topology.index_map(tdim).size_local
    dg, U = sub.dg, sub.U
    dg_rows = (3 * dg.dofmap.list[:ncell].astype(np.int64)[:, :, None] + np.arange(3)).reshape(ncell, 30)
    u_rows = (2 * U.dofmap.list[:ncell].astype(np.int64)[:, :, None] + np.arange(2)).reshape(ncell, 6)
    s, t = ufl.TrialFunction(dg), ufl.TestFunction(dg)
    w, v = ufl.TrialFunction(U), ufl.TestFunction(U)
    n = ufl.FacetNormal(msh)
    ds = forms_mixed.boundary_measure(msh, ft)
    gamma = ft.find(Boundary.INTERFACE)
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    gamma_cells = np.unique(f2c.array[f2c.offsets[gamma]]).astype(np.int64)  # a γ facet is on ∂Ω₁: one cell
    K = cell_blocks(assemble_scipy(forms_mixed.compliance_form(s, t, fields.lmbda, fields.mu)), dg_rows, dg_rows)
    R = cell_blocks(
        assemble_scipy(forms_mixed.robin_form(s, t, n, 1.0, ds(Boundary.INTERFACE))),
        dg_rows[gamma_cells],
        dg_rows[gamma_cells],
    )
    B = cell_blocks(assemble_scipy(forms_mixed.divergence_form(s, v)), u_rows, dg_rows)
    M = cell_blocks(assemble_scipy(forms_mixed.mass_form(w, v)), u_rows, u_rows)
    kt = (
        kappa_tilde(fields.lmbda, fields.mu, H, s_factor)
        if weight == "lambda+2mu"
        else s_factor * 2.0 * fields.mu / H**2
    )
    S = cell_blocks(assemble_scipy(kt * ufl.inner(w, v) * ufl.dx), u_rows, u_rows)
    Gv = fem.assemble_vector(fem.form(forms_mixed.load_form(fields.f, v)))
    Gv.scatter_reverse(dolfinx.la.InsertMode.add)
    G = Gv.array[u_rows]
    F, s0 = _boundary_loads(sub, dg_rows, t, n, ds)
    # interface data: continuous vector P3 on γ, nodes ordered as sub.gamma_points
    Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
    blocks = fem.locate_dofs_topological(Lam, tdim - 1, gamma)
    coords = Lam.tabulate_dof_coordinates()[blocks, :2]
    order = np.lexsort((coords[:, 0], coords[:, 1]))
    blocks, coords = blocks[order], coords[order]
    size = float(np.max(np.abs(sub.gamma_points), initial=0.0))  # (the match is relative: any length unit)
    if coords.shape != sub.gamma_points.shape or not np.allclose(coords, sub.gamma_points, atol=1e-12 * size):
        raise RuntimeError("the γ nodes do not match the Ω₁ subproblem's interface nodes")
    if sub.interface.bends.bent:  # the data space of the bends (``fem.mixed_interface.GammaBends``)
        C = sub.interface.C_dg[dg_rows.ravel()].tocsr()
        E = _bent_trace_operator(msh, dg, gamma, sub.interface.bends)
    else:
        g = ufl.TrialFunction(Lam)
        Cfull = assemble_scipy(forms_mixed.robin_data_form(g, t, n, ds(Boundary.INTERFACE)))
        C = Cfull[dg_rows.ravel()][:, (2 * blocks[:, None] + np.arange(2)).ravel()].tocsr()
        E = _trace_operator(msh, dg, gamma, coords)
    # the local spaces start from the full (unconstrained) AW space, also where τn = 0 sides constrain sub.space
    space = sub.space
    num_full = 3 * msh.topology.index_map(0).size_local + 4 * msh.topology.index_map(1).size_local + 3 * ncell
    if space.num_dofs_full != num_full:
        raise RuntimeError("the full AW prolongation does not have the raw serial numbering")
    if space.dg is dg and np.array_equal(space.dg_rows, dg_rows):  # the space's own blocks (no CSR P, no copy)
        P_cols, P_blocks = space.cell_prolongation()
    else:
        P_cols, P_blocks = row_blocks(space.full_prolongation, dg_rows)
    if s0 is not None:  # the lifting is a load: (div σ̂, v) = −(f, v) − (div s₀, v), σ = σ̂ + s₀
        G = G - np.einsum("cab,cb->ca", B, s0)
        lift = -np.einsum("cab,cb->ca", K, s0)
        lift[gamma_cells] -= sub.beta * np.einsum("cab,cb->ca", R, s0[gamma_cells])
        F = lift if F is None else F + lift
    return CellOperators(
        K,
        sub.beta * R,
        B,
        M,
        S,
        G,
        C,
        E,
        int(num_full),
        dg_rows,
        u_rows,
        gamma_cells,
        P_cols,
        P_blocks,
        F,
        s0,
        sub.stress_scale,
    )


def _boundary_loads(sub, dg_rows: np.ndarray, t, n, ds) -> tuple:
    """(∫_ΓD u_D·(τn) as a cell-major (n, 30) functional or None, the lifting s₀ cell-major or None).

    The boundary data of the Ω₁ ``MixedSubproblem`` ``sub``: its traction lifting ``sub.s0``
    (DG P3; σn = t on Γ_N) and its prescribed displacement ``sub.u_D`` (P3 on Γ_D).  Traction-free
    and traction sides are essential in the local spaces (``Topology(traction_free_facets=)``).
    """
    s0 = None
    if getattr(sub, "_lifted", False):
        s0 = np.ascontiguousarray(sub.s0[dg_rows])
    F = None
    if getattr(sub, "u_D", None) is not None:
        Fv = fem.assemble_vector(fem.form(forms_mixed.robin_data_form(sub.u_D, t, n, ds(Boundary.GAMMA_D))))
        Fv.scatter_reverse(dolfinx.la.InsertMode.add)
        F = np.ascontiguousarray(Fv.array[dg_rows])
    return F, s0


def scale_to_cell_sizes(ops: CellOperators, grid: CoarseGrid, H: float) -> None:
    """κ̃ = c κ H_k⁻² with the size H_k of each coarse cell when the grid gives one (``cell_size``: √|K_k|,
    a user partition); a Cartesian grid has H_k = H and nothing changes."""
    sizes = getattr(grid, "cell_size", None)
    if sizes is None:
        return
    for k, Hk in enumerate(np.asarray(sizes, dtype=float)):
        factor = (H / Hk) ** 2
        if abs(factor - 1.0) > 1e-10:
            ops.S[np.asarray(grid.cells[k], dtype=np.int64)] *= factor
