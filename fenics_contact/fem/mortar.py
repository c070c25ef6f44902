"""Contact surfaces of P1 meshes, closest-point projection, and the segment-to-segment contact quadrature.

The contact integral of two bodies lives on the slave surface Γ_C; each quadrature point x is projected
onto the master surface Γ_C_other (closest point π(x) on the reference configuration, computed once: small
deformation and small sliding).  With ν = −n_m the master's outward unit normal at π(x) and the initial gap
g = (π(x) − x)·ν, the penetration of a displacement u is

    s(u)(x) = (u_s(x) − u_m(π(x)))·ν − g,      (s > 0: the bodies overlap),

linear in u: s = B u − g, one row of B per quadrature point (ν·N_i(x) on the slave facet's vertices,
−ν·M_j(π(x)) on the master facet's, both P1).  The penalty term is Σ_q (w_q/δ) (s_q)⁺ (B v)_q.

Quadrature (``ContactQuadrature``): in 2D each slave segment is cut at the projections of the master
vertices, and each piece gets a Gauss rule: the slave and master P1 traces are then both linear on each piece,
so the integrals of a piecewise linear (s)⁺ against both bodies' test functions are exact where (s)⁺ is
linear, and the contact patch test (a uniform pressure across a flat, non-matching interface) holds to
round-off.  In 3D the same holds with each slave triangle cut by the master triangles projected onto its plane
(``fem.clipping``: polygon clipping, the pieces fan-triangulated, a Gauss rule on each triangle); a point of
a piece takes its master triangle's orthogonal projection when it lies in it (the closest point where the
master is flat or convex), the closest-point search otherwise.  The forces on the two sides are equal and
opposite to round-off in any dimension: the rows of B sum to ν − ν = 0 over the components (partitions of
unity).
"""

from typing import NamedTuple

import basix
import numpy as np
import scipy.sparse as sp
import scipy.spatial
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.fem import clipping
from fenics_contact.problem.pair import PRESSURE_BASES

__all__ = [
    "Surface",
    "Projection",
    "ContactQuadrature",
    "surface",
    "project",
    "contact_quadrature",
    "nodal_gaps",
    "weight_functions",
]


#: barycentric tolerance of "the orthogonal projection lies in the facet"
_INSIDE = 1e-10


class Surface(NamedTuple):
    """The P1 facets of a tagged surface: per facet its vertices' coordinates (F, k, gdim) and DOF blocks
    (F, k), its outward unit normal (F, gdim) and measure (F,) (k = gdim vertices per facet)."""

    coords: np.ndarray
    blocks: np.ndarray
    normals: np.ndarray
    measures: np.ndarray

    @property
    def nodes(self) -> np.ndarray:
        """The DOF blocks of the surface's vertices (sorted, unique)."""
        return np.unique(self.blocks)

    def lumped(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(nodes, ∫ N_p ds, nodal outward normal: the facet normals averaged with the facet measures)."""
        nodes, inverse = np.unique(self.blocks, return_inverse=True)
        inverse = inverse.reshape(self.blocks.shape)
        k = self.blocks.shape[1]
        weights = np.bincount(inverse.ravel(), np.repeat(self.measures / k, k), minlength=nodes.size)
        normal = np.zeros((nodes.size, self.normals.shape[1]))
        for c in range(self.normals.shape[1]):
            normal[:, c] = np.bincount(
                inverse.ravel(), np.repeat(self.measures * self.normals[:, c], k), minlength=nodes.size
            )
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        return nodes, weights, normal

    def node_coordinates(self) -> np.ndarray:
        """The coordinates of ``nodes``, in their order."""
        nodes, first = np.unique(self.blocks.ravel(), return_index=True)
        return self.coords.reshape(-1, self.coords.shape[2])[first]


def _facet_normal(coords: np.ndarray) -> np.ndarray:
    """Unit normals of facets (F, k, gdim), orientation arbitrary."""
    if coords.shape[2] == 2:
        t = coords[:, 1] - coords[:, 0]
        n = np.stack([t[:, 1], -t[:, 0]], axis=1)
    else:
        n = np.cross(coords[:, 1] - coords[:, 0], coords[:, 2] - coords[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def surface(V: fem.FunctionSpace, facet_tags: dmesh.MeshTags, tag: int) -> Surface:
    """The local facets of ``tag`` with their vertices, the P1 space ``V``'s DOF blocks there and outward
    normals (exterior facets of simplices; the P1 DOFs of a cell follow its geometry nodes)."""
    msh = V.mesh
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    msh.topology.create_connectivity(tdim, tdim - 1)
    f2c, c2f = msh.topology.connectivity(tdim - 1, tdim), msh.topology.connectivity(tdim, tdim - 1)
    ref_facets = basix.topology(msh.basix_cell())[tdim - 1]
    facets = facet_tags.find(tag)
    coords = np.zeros((facets.size, tdim, gdim))
    blocks = np.zeros((facets.size, tdim), dtype=np.int64)
    inward = np.zeros((facets.size, gdim))
    x, gdofs = msh.geometry.x[:, :gdim], msh.geometry.dofmaps[0]
    for i, f in enumerate(facets):
        c = f2c.links(f)[0]
        local = int(np.flatnonzero(c2f.links(c) == f)[0])
        verts = np.asarray(ref_facets[local])
        nodes = gdofs[c]
        coords[i] = x[nodes[verts]]
        blocks[i] = V.dofmap.cell_dofs(c)[verts]
        inward[i] = x[nodes].mean(axis=0) - coords[i, 0]
    normals = _facet_normal(coords) if facets.size else np.zeros((0, gdim))
    normals *= -np.sign(np.sum(normals * inward, axis=1))[:, None]
    edges = coords[:, 1:] - coords[:, :1]
    gram = np.einsum("fid,fjd->fij", edges, edges)
    measures = np.sqrt(np.abs(np.linalg.det(gram))) / (1.0 if tdim == 2 else 2.0) if facets.size else np.zeros(0)
    return Surface(coords, blocks, normals, measures)


def _closest_on_simplex(points: np.ndarray, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of simplices to points: barycentric coordinates (n, k) and the orthogonal projection's
    "inside" flag, for points (n, gdim) and one simplex per point (n, k, gdim)."""
    n, k, _ = verts.shape
    if k == 1:
        return np.ones((n, 1)), np.ones(n, dtype=bool)
    edges = verts[:, 1:] - verts[:, :1]
    gram = np.einsum("nid,njd->nij", edges, edges)
    rhs = np.einsum("nid,nd->ni", edges, points - verts[:, 0])
    lam = np.linalg.solve(gram, rhs[..., None])[..., 0]
    bary = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)
    inside = np.all(bary >= -_INSIDE, axis=1)
    out = ~inside
    if np.any(out):  # the closest point lies on a face: the best of the faces (drop one vertex each)
        best = np.full(np.count_nonzero(out), np.inf)
        best_bary = np.zeros((best.size, k))
        for drop in range(k):
            keep = [j for j in range(k) if j != drop]
            sub, _ = _closest_on_simplex(points[out], verts[out][:, keep])
            closest = np.einsum("nk,nkd->nd", sub, verts[out][:, keep])
            dist = np.linalg.norm(points[out] - closest, axis=1)
            better = dist < best
            best[better] = dist[better]
            full = np.zeros((best.size, k))
            full[:, keep] = sub
            best_bary[better] = full[better]
        bary[out] = best_bary
    return np.clip(bary, 0.0, 1.0), inside


class Projection(NamedTuple):
    """Closest points on a surface: per point its facet, barycentric coordinates there, the direction
    ν = −n (n the facet's outward normal), the gap g = (π(x) − x)·ν, and ``found``: the point faces the
    surface (its orthogonal projection lies in a facet, or its closest point is a vertex inside the surface)."""

    facet: np.ndarray
    bary: np.ndarray
    nu: np.ndarray
    gap: np.ndarray
    found: np.ndarray


def project(points: np.ndarray, target: Surface, *, candidates: int = 12, hint: np.ndarray | None = None) -> Projection:
    """Closest-point projection of ``points`` (n, gdim) onto the surface ``target``, over the ``candidates``
    facets with the nearest midpoints.  ``hint``: a facet per point (−1: none) whose orthogonal projection is
    taken where it lies in the facet (the closest point when the surface is flat or convex there), the
    others searched as without it."""
    if hint is not None:
        near = np.flatnonzero(hint >= 0)
        bary, inside = _closest_on_simplex(points[near], target.coords[hint[near]])
        take, rest = near[inside], np.setdiff1d(np.arange(points.shape[0]), near[inside])
        first = project(points[rest], target, candidates=candidates) if rest.size else None
        facet = np.zeros(points.shape[0], dtype=np.int64)
        out_bary = np.zeros((points.shape[0], target.coords.shape[1]))
        found = np.ones(points.shape[0], dtype=bool)
        facet[take], out_bary[take] = hint[take], bary[inside]
        if first is not None:
            facet[rest], out_bary[rest], found[rest] = first.facet, first.bary, first.found
        nu = -target.normals[facet]
        closest = np.einsum("nk,nkd->nd", out_bary, target.coords[facet])
        return Projection(facet, out_bary, nu, np.sum((closest - points) * nu, axis=1), found)
    n = points.shape[0]
    num = target.coords.shape[0]
    if num == 0:
        raise InputError("the master contact surface has no facets")
    mid = target.coords.mean(axis=1)
    k = min(candidates, num)
    _, near = scipy.spatial.cKDTree(mid).query(points, k=k)
    near = near.reshape(n, k)
    best = np.full(n, np.inf)
    facet = np.zeros(n, dtype=np.int64)
    bary = np.zeros((n, target.coords.shape[1]))
    inside = np.zeros(n, dtype=bool)
    for j in range(k):
        f = near[:, j]
        b, ins = _closest_on_simplex(points, target.coords[f])
        closest = np.einsum("nk,nkd->nd", b, target.coords[f])
        dist = np.linalg.norm(points - closest, axis=1)
        # prefer a facet whose orthogonal projection holds the point at the same distance (a shared vertex)
        better = (dist < best * (1.0 - 1e-12)) | ((dist <= best * (1.0 + 1e-12)) & ins & ~inside)
        best[better], facet[better], bary[better], inside[better] = dist[better], f[better], b[better], ins[better]
    # a closest point on the surface's rim (a vertex or edge of one facet only, or ...) off its facet's
    # orthogonal range: the point does not face the surface
    counts = np.bincount(target.blocks.ravel())
    rim_vertex = counts[target.blocks[facet]] < (2 if target.coords.shape[1] == 2 else 3)
    on_rim = np.any((bary > 1.0 - _INSIDE) & rim_vertex, axis=1)
    found = inside | ~on_rim
    nu = -target.normals[facet]
    closest = np.einsum("nk,nkd->nd", bary, target.coords[facet])
    gap = np.sum((closest - points) * nu, axis=1)
    return Projection(facet, bary, nu, gap, found)


class ContactQuadrature(NamedTuple):
    """The contact quadrature: per point q its weight w_q, gap g_q, direction ν_q and the row of B (``B``: rows
    q, columns the scalar DOFs of the vector P1 space), with the slave points themselves; for nodal gaps the
    rows are slave nodes (``nodes``)."""

    points: np.ndarray
    weights: np.ndarray
    gap: np.ndarray
    nu: np.ndarray
    B: sp.csr_matrix
    nodes: np.ndarray | None = None  #: the slave node (DOF block) of each row (``nodal_gaps``), None for points
    #: the relative displacement u_s(x_q) − u_m(π(x_q)) at each row, one row per component (row d q + c):
    #: B = diag(ν_q)ᵀ of it; the tangential slip of friction is its part orthogonal to ν
    relative: sp.csr_matrix | None = None
    #: for points: those on slave facets that do not wholly face the master surface (``weight_functions``)
    partial: np.ndarray | None = None


def _cuts(slave: Surface, master: Surface) -> list[np.ndarray]:
    """Per slave segment the parameters t ∈ (0, 1) of the master vertices' projections onto it (2D)."""
    verts = master.node_coordinates()
    tree = scipy.spatial.cKDTree(verts)
    out = []
    for a, b in slave.coords:
        d = b - a
        length = float(np.linalg.norm(d))
        near = tree.query_ball_point(0.5 * (a + b), r=2.0 * length)
        t = (verts[near] - a) @ d / length**2 if near else np.zeros(0)
        out.append(np.unique(t[(t > 1e-12) & (t < 1.0 - 1e-12)]))
    return out


def _pieces(slave: Surface, master: Surface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slave triangles cut by the master triangles projected onto their planes (``fem.clipping``): the
    convex pieces in the slave's affine coordinates (P, M, 2), the slave facet of each (P,) and the master facet
    it lies in (−1: none).  A slave triangle
    meets the master triangles whose midpoints lie within the sum of the two circumscribing radii (about the
    midpoints) of its midpoint's closest point on the master surface."""
    mid_s, mid_m = slave.coords.mean(axis=1), master.coords.mean(axis=1)
    r_s = np.linalg.norm(slave.coords - mid_s[:, None], axis=2).max(axis=1)
    r_m = float(np.linalg.norm(master.coords - mid_m[:, None], axis=2).max())
    proj = project(mid_s, master)
    foot = np.einsum("nk,nkd->nd", proj.bary, master.coords[proj.facet])
    near = scipy.spatial.cKDTree(mid_m).query_ball_point(foot, r=(r_s + r_m) * (1.0 + 1e-9))
    k = max(1, max(len(c) for c in near))
    cand = np.full((len(near), k), -1)
    for i, c in enumerate(near):
        cand[i, : len(c)] = c
    x0 = slave.coords[:, 0]
    edges = slave.coords[:, 1:] - x0[:, None]  # (S, 2, 3)
    gram = np.einsum("sid,sjd->sij", edges, edges)
    rel = master.coords[np.maximum(cand, 0)] - x0[:, None, None]  # (S, K, 3, 3)
    rhs = np.einsum("sid,skvd->skvi", edges, rel)
    xi = np.einsum("sij,skvj->skvi", np.linalg.inv(gram), rhs)  # the orthogonal projection onto the slave plane
    xi[cand < 0] = np.nan
    poly, _, owner, slot = clipping.intersections(xi)
    return poly, owner, np.where(slot >= 0, cand[owner, np.maximum(slot, 0)], -1)


def _slave_points(
    slave: Surface, master: Surface, degree: int, vertices: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Quadrature points on the slave facets: (facet index, barycentric coordinates, weights, the master facet
    each point was clipped against (3D; −1: none) or None); ``vertices``: the facets' vertices with the lumped
    weights |F|/k instead."""
    tdim = slave.coords.shape[1]
    if vertices:
        nf = slave.coords.shape[0]
        return (
            np.repeat(np.arange(nf), tdim),
            np.tile(np.eye(tdim), (nf, 1)),
            np.repeat(slave.measures / tdim, tdim),
            None,
        )
    cell = basix.CellType.interval if tdim == 2 else basix.CellType.triangle
    ref, ref_w = basix.make_quadrature(cell, degree)
    if tdim == 2:  # segment-to-segment: each slave segment cut at the master vertices
        facets, bary, weights = [], [], []
        for i, cuts in enumerate(_cuts(slave, master)):
            edges = np.concatenate([[0.0], cuts, [1.0]])
            for t0, t1 in zip(edges[:-1], edges[1:]):
                t = t0 + (t1 - t0) * ref[:, 0]
                facets.append(np.full(t.size, i))
                bary.append(np.stack([1.0 - t, t], axis=1))
                weights.append((t1 - t0) * ref_w * slave.measures[i])
        return np.concatenate(facets), np.concatenate(bary), np.concatenate(weights), None
    pieces, owner, target = _pieces(slave, master)
    piece, xi, weights = clipping.fan_rule(pieces, degree)
    facets = owner[piece]
    bary = np.concatenate([1.0 - xi.sum(axis=1, keepdims=True), xi], axis=1)
    return facets, bary, 2.0 * weights * slave.measures[facets], target[piece]  # reference triangle area ½


def contact_quadrature(
    slave: Surface,
    master: Surface,
    num_dofs: int,
    bs: int,
    degree: int,
    *,
    nodal: bool = True,
    rule: str = "segments",
    basis: str = "standard",
) -> ContactQuadrature:
    """The contact quadrature of a slave and a master surface (module docstring); points that do not face
    the master surface are left out.  ``num_dofs``: the scalar DOFs of the vector P1 space of block size ``bs``.

    ``nodal``: the mortar-weighted nodal gaps (``nodal_gaps``) instead of the Gauss points themselves, weighted
    with the ``basis`` of the pressure (``weight_functions``: ``"standard"`` or ``"dual"``).
    ``rule``: ``"segments"`` (the module docstring) or ``"vertices"``: the one-pass node-to-segment rule (the
    slave vertices with lumped weights), which fails the patch test on non-matching meshes (kept to show it)."""
    if rule not in ("segments", "vertices"):
        raise InputError(f"the contact quadrature rule must be 'segments' or 'vertices', got {rule!r}")
    if basis not in PRESSURE_BASES:
        raise InputError(f"the pressure basis must be one of {PRESSURE_BASES}, got {basis!r}")
    if basis == "dual" and rule == "vertices":
        raise InputError("the dual pressure basis needs the segment-to-segment rule (rule='segments')")
    if slave.coords.shape[0] == 0:
        raise InputError("the slave contact surface has no facets")
    facet, bary, weights, hint = _slave_points(slave, master, degree, vertices=rule == "vertices")
    points = np.einsum("nk,nkd->nd", bary, slave.coords[facet])
    proj = project(points, master, hint=hint)
    keep = proj.found
    partial = np.isin(facet, facet[~keep])  # the points of the slave facets that do not wholly face the master
    facet, bary, weights, points = facet[keep], bary[keep], weights[keep], points[keep]
    nu, gap, mfacet, mbary = proj.nu[keep], proj.gap[keep], proj.facet[keep], proj.bary[keep]
    n, k = points.shape[0], bary.shape[1]
    rows, cols, vals, comps = [], [], [], []
    for blocks, values, sign in ((slave.blocks[facet], bary, 1.0), (master.blocks[mfacet], mbary, -1.0)):
        for j in range(k):
            for c in range(bs):
                rows.append(np.arange(n))
                cols.append(bs * blocks[:, j] + c)
                vals.append(sign * values[:, j])
                comps.append(np.full(n, c))
    rows, cols, vals, comps = (np.concatenate(a) for a in (rows, cols, vals, comps))
    B = sp.csr_matrix((vals * nu[rows, comps], (rows, cols)), shape=(n, num_dofs))
    relative = sp.csr_matrix((vals, (bs * rows + comps, cols)), shape=(bs * n, num_dofs))
    Q = ContactQuadrature(points, weights, gap, nu, B, relative=relative, partial=partial[keep])
    if not nodal:
        return Q
    phi = weight_functions(bary, partial[keep], basis)
    P = sp.csr_matrix(
        (phi.ravel(), (slave.blocks[facet].ravel(), np.repeat(np.arange(n), k))), shape=(num_dofs // bs, n)
    )
    return nodal_gaps(Q, P)


def weight_functions(bary: np.ndarray, partial: np.ndarray, basis: str) -> np.ndarray:
    """The values φ_p(x) of the slave vertices' weight functions at points of barycentric coordinates ``bary``
    (n, k) on their slave facets: the nodal gaps are s̃_p = ∫ φ_p s ds / ∫ φ_p ds and the pressure the penalty
    applies is Σ_p λ_p φ_p.

    ``"standard"``: φ_p = N_p, the P1 hat functions.  ``"dual"``: the biorthogonal basis ψ_p = (k + 1) N_p − 1 on each
    facet of k vertices (3N_p − 1 on a segment, 4N_p − 1 on a triangle), ∫_F ψ_p N_q ds = δ_pq ∫_F N_p ds, so that
    s̃_p is the nodal value of the gap's local (biorthogonal) projection onto P1, exact for a gap linear on the
    facets, and the slave's nodal contact forces are λ_p ∫ N_p ds (no coupling through a mass matrix); the points
    of facets that do not wholly face the master (``partial``, where biorthogonality is lost) keep N_p.  Both
    bases sum to 1 on every facet: a uniform s gives s̃ = s and a uniform pressure (the patch test)."""
    if basis == "standard":
        return bary
    k = bary.shape[1]
    return np.where(partial[:, None], bary, (k + 1) * bary - 1.0)


def nodal_gaps(Q: ContactQuadrature, P: sp.csr_matrix) -> ContactQuadrature:
    """The mortar-weighted nodal gaps of the quadrature Q: one row per slave node p (P[p, q] = φ_p(x_q), the weight
    functions of ``weight_functions``),

        w_p = Σ_q w_q φ_p(x_q),   s̃_p(u) = (1/w_p) Σ_q w_q φ_p(x_q) s_q(u),

    with the penalty (1/δ) Σ_p w_p (s̃_p)⁺ s̃_p(v): as many constraints as slave nodes (a Gauss-point penalty
    over-constrains the contact and its pressure oscillates), the same s̃ = s for a uniform s (patch test),
    and the active set a set of slave nodes.  Nodes whose points all miss the master surface are left out."""
    PW = P @ sp.diags(Q.weights)
    weights = np.asarray(PW.sum(axis=1)).ravel()
    nodes = np.flatnonzero(weights > 0.0)
    scale = sp.diags(1.0 / weights[nodes])
    rows = scale @ PW[nodes]
    nu = rows @ Q.nu
    nu /= np.linalg.norm(nu, axis=1)[:, None]
    bs = Q.nu.shape[1]
    relative = None if Q.relative is None else (sp.kron(rows, sp.identity(bs)) @ Q.relative).tocsr()
    return ContactQuadrature(rows @ Q.points, weights[nodes], rows @ Q.gap, nu, (rows @ Q.B).tocsr(), nodes, relative)
