"""Boundary facets of a (sub)mesh and point values of DG P3 stresses on them, as sparse evaluation matrices.

The mixed method evaluates the normal stress σ_c = n·σn at the Gauss–Lobatto nodes of Γ_C and the
traction σn at the nodes of γ.  ``BoundaryFacets`` gives the exterior facets of one tag whose cell this
rank owns (every exterior facet on exactly one rank), with their end points, outward unit normals and
per-edge Gauss–Lobatto nodes; ``stress_evaluation`` turns points in owned cells into a sparse matrix acting
on the owned DG P3 coefficients of (σ_xx, σ_xy, σ_yy).
"""

import basix
import basix.ufl
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError

__all__ = [
    "LOBATTO_S",
    "LOBATTO_W",
    "BoundaryFacets",
    "gll_function",
    "normal_weights",
    "owned_cell_facets",
    "reference_coordinates",
    "stress_evaluation",
    "tangent_of",
    "tangential_weights",
    "traction_weights",
]

#: 4-point Gauss–Lobatto rule on [0, 1] (``forms_mixed.CONTACT_QUADRATURE``).
LOBATTO_S = np.array([0.0, 0.5 - 0.5 / np.sqrt(5.0), 0.5 + 0.5 / np.sqrt(5.0), 1.0])
LOBATTO_W = np.array([1.0, 5.0, 5.0, 1.0]) / 12.0


def reference_coordinates(msh: dmesh.Mesh, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Reference coordinates (N, 2) of physical points x (N, 2) in affine triangles ``cells`` (N,)."""
    gx = msh.geometry.x[msh.geometry.dofmaps[0][cells]][:, :, :2]
    v0 = gx[:, 0]
    J = np.stack([gx[:, 1] - v0, gx[:, 2] - v0], axis=-1)
    return np.linalg.solve(J, (x - v0)[..., None])[..., 0]


def stress_evaluation(dg: fem.FunctionSpace, cells: np.ndarray, X: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Sparse E with (E s)_p = Σ_j weights[p, j] s_j(x_p) for owned DG P3 stress coefficients s.

    ``cells`` (N,) owned cells, reference points ``X`` (N, 2), component weights (N, 3) on (σ_xx, σ_xy, σ_yy).
    """
    el = dg.ufl_element().sub_elements[0].basix_element
    npts = np.asarray(cells).size
    n_dg = 3 * dg.dofmap.index_map.size_local
    if npts == 0:
        return sp.csr_matrix((0, n_dg))
    phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 10): basis function k at point p
    dofs = dg.dofmap.list[cells].astype(np.int64)  # (N, 10) block indices
    cols = 3 * dofs[:, :, None] + np.arange(3)  # (N, 10, 3)
    vals = phi[:, :, None] * weights[:, None, :]
    rows = np.broadcast_to(np.arange(npts)[:, None, None], cols.shape)
    E = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(npts, n_dg))
    E.eliminate_zeros()
    return E


def normal_weights(n: np.ndarray) -> np.ndarray:
    """Weights (N, 3) giving n·σn from (σ_xx, σ_xy, σ_yy)."""
    return np.stack([n[:, 0] ** 2, 2.0 * n[:, 0] * n[:, 1], n[:, 1] ** 2], axis=1)


def tangent_of(n: np.ndarray) -> np.ndarray:
    """The unit tangent t = (−n_y, n_x) of outward unit normals n (N, 2): the direction of σ_t = t·σn."""
    return np.stack([-n[:, 1], n[:, 0]], axis=1)


def tangential_weights(n: np.ndarray) -> np.ndarray:
    """Weights (N, 3) giving t·σn from (σ_xx, σ_xy, σ_yy), t = ``tangent_of(n)``."""
    t = tangent_of(n)
    return np.stack([t[:, 0] * n[:, 0], t[:, 0] * n[:, 1] + t[:, 1] * n[:, 0], t[:, 1] * n[:, 1]], axis=1)


def traction_weights(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights (N, 3) giving the x and y components of σn."""
    zero = np.zeros(n.shape[0])
    return np.stack([n[:, 0], n[:, 1], zero], axis=1), np.stack([zero, n[:, 0], n[:, 1]], axis=1)


def owned_cell_facets(msh: dmesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """The facets (of a tag) whose first cell is owned by this rank: every exterior facet on exactly one rank."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    facets = np.asarray(facets, dtype=np.int32)
    if facets.size == 0:
        return facets
    first = f2c.array[f2c.offsets[facets]]
    return facets[first < msh.topology.index_map(tdim).size_local]


class BoundaryFacets:
    """Exterior facets of one tag whose cell this rank owns: cells, end points, outward unit normals."""

    def __init__(self, msh: dmesh.Mesh, facets: np.ndarray) -> None:
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        msh.topology.create_connectivity(tdim - 1, 0)
        msh.topology.create_connectivity(0, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        self.facets = owned_cell_facets(msh, facets)
        counts = np.diff(f2c.offsets)[self.facets]
        if msh.comm.size == 1 and np.any(counts != 1):
            raise InputError("a boundary-tagged facet is not on the boundary of the (sub)mesh")
        self.cells = f2c.array[f2c.offsets[self.facets]].astype(np.int32)
        f2v = msh.topology.connectivity(tdim - 1, 0).array.reshape(-1, 2)
        self.vertices = f2v[self.facets].astype(np.int32)  # topology vertices of the end points a, b
        x = msh.geometry.x[:, :2]
        if self.facets.size:
            geo = dmesh.entities_to_geometry(msh, 0, self.vertices.ravel().astype(np.int32)).reshape(-1, 2)
        else:
            geo = np.zeros((0, 2), dtype=np.int32)
        self.a, self.b = x[geo[:, 0]], x[geo[:, 1]]
        d = self.b - self.a
        self.length = np.linalg.norm(d, axis=1)
        n = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.maximum(self.length[:, None], 1e-300)
        centre = x[msh.geometry.dofmaps[0][self.cells]][:, :, :2].mean(axis=1)
        flip = np.sum(n * (0.5 * (self.a + self.b) - centre), axis=1) < 0
        n[flip] *= -1.0
        self.normal = n

    def lobatto_nodes(self, vertex_gid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Nodes of the per-edge 4-point Gauss–Lobatto rule, per facet (not merged).

        Returns points (4F, 2), weights (4F,), the facet's cell, the outward normal, and the
        global number of vertex nodes (−1 inside edges).
        """
        pts = self.a[:, None, :] + LOBATTO_S[None, :, None] * (self.b - self.a)[:, None, :]  # (F, 4, 2)
        wts = self.length[:, None] * LOBATTO_W[None, :]
        F = self.facets.size
        vertex = np.full((F, 4), -1, dtype=np.int64)
        if F:
            vertex[:, 0], vertex[:, 3] = vertex_gid[self.vertices[:, 0]], vertex_gid[self.vertices[:, 1]]
        cells = np.repeat(self.cells, 4)
        normals = np.repeat(self.normal, 4, axis=0)
        return pts.reshape(-1, 2), wts.ravel(), cells, normals, vertex.ravel()

    def locate(self, points: np.ndarray, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
        """(found, facet): whether each point lies on one of these facets, and the index (into ``facets``) of one."""
        if self.facets.size == 0 or points.shape[0] == 0:
            return np.zeros(points.shape[0], dtype=bool), np.zeros(points.shape[0], dtype=np.int64)
        d = self.b - self.a
        rel = points[:, None, :] - self.a[None, :, :]  # (P, F, 2)
        s = np.einsum("pfi,fi->pf", rel, d) / self.length[None, :] ** 2
        dist = np.linalg.norm(rel - s[..., None] * d[None], axis=-1)
        ok = (dist <= tol * self.length[None, :]) & (s >= -tol) & (s <= 1 + tol)
        return ok.any(axis=1), np.argmax(ok, axis=1)


def gll_function(msh: dmesh.Mesh, field) -> fem.Function:
    """A scalar P3 function with its edge nodes at the 4-point Gauss–Lobatto points, interpolating ``field``.

    Non-finite values (a signed distance undefined away from Γ_C) are set to 0.
    """
    el = basix.ufl.element("Lagrange", msh.basix_cell(), 3, lagrange_variant=basix.LagrangeVariant.gll_warped)
    fn = fem.Function(fem.functionspace(msh, el))
    with np.errstate(invalid="ignore"):
        fn.interpolate(lambda x: np.asarray(field(x), dtype=np.float64).reshape(-1))
    fn.x.array[~np.isfinite(fn.x.array)] = 0.0
    return fn
