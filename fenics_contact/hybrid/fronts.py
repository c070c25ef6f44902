"""The fronts of the contact Newton's active set: Γ_C's unknowns ordered along the boundary, and the fronts
resolved locally.

A front is the end of a contiguous active segment of a chain of Γ_C unknowns (``contact_chains``: the
unknowns ordered along each piece of Γ_C from their coordinates alone); on a contact surface (3D) it is the
edge between active and inactive unknowns of their neighbour graph (``contact_chains`` then returns patches:
the unknowns of each piece with that graph).  Where a near-rigid body rests on
Γ_C (a channel 10⁶ times stiffer than its surroundings) the plain semismooth Newton frees one node per
step, and in the mixed method fronts in the bulk creep one Gauss–Lobatto point per step.  ``LocalFronts``
(``InterfaceNewtonOptions.front_window``, default 8) solves the contact equations exactly on a window
around every front of the next active set, the forces elsewhere held (a nonlinear elimination).  It only
proposes the next set of the contact Newton (``hybrid.contact_newton``): a set is accepted only when the
solve on it reproduces it.
"""

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix, issparse
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from fenics_contact.hybrid.contact_equations import solve_on

__all__ = ["contact_chains", "contact_patches", "LocalFronts"]


#: surface neighbours: unknowns closer than this many times the larger of their nearest-neighbour distances
SURFACE_NEIGHBOURS = 1.5


def contact_patches(points: np.ndarray) -> list[tuple[np.ndarray, csr_matrix]]:
    """The contact unknowns of a contact surface (3D): one (indices, neighbour graph) pair per connected piece.

    Two unknowns are neighbours when they are closer than ``SURFACE_NEIGHBOURS`` times the larger of their
    nearest-neighbour distances (on a grid face: the grid edges and the diagonals of its squares).
    """
    n = points.shape[0]
    if n < 3:
        return []
    tree = cKDTree(points)
    nearest = tree.query(points, k=2)[0][:, 1]
    pairs = tree.query_pairs(SURFACE_NEIGHBOURS * float(nearest.max()), output_type="ndarray")
    d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    pairs = pairs[d <= SURFACE_NEIGHBOURS * np.maximum(nearest[pairs[:, 0]], nearest[pairs[:, 1]])]
    adj = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    adj = (adj + adj.T).tocsr()
    count, label = connected_components(adj, directed=False)
    patches = []
    for c in range(count):
        nodes = np.flatnonzero(label == c)
        if nodes.size >= 3:
            patches.append((nodes, adj[nodes][:, nodes].tocsr()))
    return patches


def contact_chains(points: np.ndarray, *, cut: float = 4.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """The contact unknowns ordered along Γ_C: one (indices, arc-length positions) pair per piece of Γ_C; for
    points in 3D (a contact surface) the ``contact_patches`` instead.

    The pieces are the paths of the Euclidean minimum spanning tree of ``points`` once its edges longer than
    ``cut`` × the median edge are removed (separate components of Γ_C); a piece that is not a path (a
    node with three tree neighbours: points too far from a curve) is left out, and its fronts are then
    not resolved locally (the plain step's set stands there).  Coincident points (a vertex copied at a corner) follow
    each other.
    """
    if points.ndim == 2 and points.shape[1] == 3:
        return contact_patches(points)
    if points.shape[0] < 3:
        return []
    dist = cdist(points, points)
    if dist.max() == 0.0:
        return []
    # coincident points (copies of a vertex) are one node of the tree, expanded again in the chain
    _, group = connected_components(dist <= 1e-12 * dist.max(), directed=False)
    first = np.unique(group, return_index=True)[1]
    members = [np.flatnonzero(group == g) for g in range(first.size)]
    points = points[first]
    n = points.shape[0]
    dist = dist[np.ix_(first, first)]
    if n < 3:
        return []
    tree = minimum_spanning_tree(dist).tocoo()
    keep = tree.data <= cut * np.median(tree.data)
    adj = coo_matrix((tree.data[keep], (tree.row[keep], tree.col[keep])), shape=(n, n)).tocsr()
    adj = (adj + adj.T).tocsr()
    count, label = connected_components(adj, directed=False)
    degree = np.diff(adj.indptr)
    chains = []
    for c in range(count):
        nodes = np.flatnonzero(label == c)
        if nodes.size < 3 or degree[nodes].max() > 2:
            continue
        order, prev = [int(nodes[degree[nodes] == 1][0])], -1
        while True:
            nbrs = [k for k in adj.indices[adj.indptr[order[-1]] : adj.indptr[order[-1] + 1]] if k != prev]
            if not nbrs:
                break
            prev = order[-1]
            order.append(int(nbrs[0]))
        order = np.array(order)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points[order], axis=0), axis=1))])
        chains.append(
            (
                np.concatenate([members[k] for k in order]),
                np.concatenate([np.full(members[k].size, a) for k, a in zip(order, arc)]),
            )
        )
    return chains


class LocalFronts:
    """Local resolution of the fronts of the contact Newton's active set (a nonlinear elimination).

    After a step has solved the set 𝒜 for (s, μ), the semismooth step's next set is {s > 0}.  Where a stiff
    body rests on Γ_C (a channel 10⁶ times stiffer than its surroundings on the penalty) that set frees or
    takes one node per step, and in the mixed method fronts in the bulk creep one Gauss–Lobatto point per
    step.  Here every front of the next set (the end of a contiguous active segment of a ``contact_chains``
    chain) gets a window of the ``width`` unknowns on either side of it (overlapping windows merged), and on
    each window R the penalized contact equations are solved exactly with the forces elsewhere held at the
    step's μ:

        s_R = r_R − M_RR μ_R,  μ_R = D_R s_R⁺,  r_R = s_L,R − M_R,R̄ μ_R̄,

    by the same semismooth Newton (full steps from the next set's rows; at most 2|R| + 10 iterations, and a
    window whose iteration does not settle keeps the plain set).  The next set takes the windows' active
    sets.  Each local iteration is one dense solve of at most |R| unknowns (2w for an isolated front),
    against the n_c of a step.  The trial set is only the start of the next step: a set is accepted only when
    the step solved on it reproduces it, so the fixed point is the plain Newton's.  (Nonlinear elimination,
    Lanzkron, Rose & Wilkes 1996; Cai & Keyes 2002: the unknowns that hold a Newton method back are
    eliminated by local nonlinear solves.)
    """

    def __init__(self, chains, M: np.ndarray, D: np.ndarray, width: int) -> None:
        self.chains = [np.asarray(idx) for idx, second in chains if not issparse(second)]
        self.patches = [(np.asarray(idx), graph) for idx, graph in chains if issparse(graph)]
        self.M, self.D, self.width = M, D, int(width)

    def _patch_windows(self, active: np.ndarray) -> list[np.ndarray]:
        """On a surface patch: the unknowns within ``width`` − 1 graph steps of a front (an unknown with a
        neighbour of the other state), split into connected windows."""
        out = []
        for idx, graph in self.patches:
            a = active[idx].astype(np.int8)
            coo = graph.tocoo()
            front = np.unique(coo.row[a[coo.row] != a[coo.col]])
            if front.size == 0:
                continue
            mark = np.zeros(idx.size, dtype=bool)
            mark[front] = True
            for _ in range(self.width - 1):  # grow by one ring of neighbours
                mark |= (graph @ mark.astype(np.float64)) > 0
            sub = np.flatnonzero(mark)
            count, label = connected_components(graph[sub][:, sub], directed=False)
            out += [idx[sub[label == c]] for c in range(count)]
        return out

    def windows(self, active: np.ndarray) -> list[np.ndarray]:
        """The merged windows (rows of the contact unknowns) around the fronts of ``active``."""
        out, w = self._patch_windows(active), self.width
        for idx in self.chains:
            a = active[idx]
            mark = np.zeros(idx.size, dtype=bool)
            for e in np.flatnonzero(a[:-1] != a[1:]):  # a front between positions e and e + 1
                mark[max(0, e - w + 1) : e + w + 1] = True
            edges = np.flatnonzero(np.diff(np.concatenate([[0], mark.astype(np.int8), [0]])))
            out += [idx[a0:a1] for a0, a1 in zip(edges[::2], edges[1::2])]
        return out

    def _solve(self, R: np.ndarray, r: np.ndarray, start: np.ndarray) -> tuple[np.ndarray | None, int]:
        """The active set of the window's equations (None: no settled set), and the iterations taken."""
        MRR, DR = self.M[np.ix_(R, R)], self.D[R]
        act, seen = start.copy(), set()
        for it in range(2 * R.size + 10):
            seen.add(np.packbits(act).tobytes())
            new = solve_on(r, MRR, DR, np.flatnonzero(act))[0] > 0.0
            if np.array_equal(new, act):
                return new, it + 1
            if np.packbits(new).tobytes() in seen:  # a cycle (possible for a non-symmetric M)
                return None, it + 1
            act = new
        return None, 2 * R.size + 10

    def trial(self, predicted: np.ndarray, s_load: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, tuple]:
        """The next set: ``predicted`` with every front window's own solution; and (windows, iterations,
        largest window)."""
        trial = predicted.copy()
        iterations, largest = 0, 0
        wins = self.windows(predicted)
        for R in wins:
            r = s_load[R] - self.M[R] @ mu + self.M[np.ix_(R, R)] @ mu[R]
            found, it = self._solve(R, r, predicted[R])
            iterations += it
            largest = max(largest, R.size)
            if found is not None:
                trial[R] = found
        return trial, (len(wins), iterations, largest)
