"""Global numbering of the (reduced) Arnold–Winther space and the map T from the full local numbering.

On each rank the *full* local numbering is 3v + j for the local vertices v (owned, then ghosts),
3n_v + 4e + k for the local edges, 3n_v + 4n_e + 3c + j for the owned cells.  The reduced space numbers
its degrees of freedom globally: each rank owns those of its owned vertices, edges and cells — the kept
full ones in local order, then the constrained vertices' null-space coefficients, then the
split-interface coefficients — and learns the numbers of its ghosts from their owners (DOLFINx scatters
over the topology's index maps).  In serial the numbering is the raw one above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.fem.arnold_winther.constraints import EssentialConstraints
from fenics_contact.fem.arnold_winther.topology import TriangleEntities
from fenics_contact.fem.distributed import offsets as block_offsets
from fenics_contact.fem.distributed import owner_of, scatter_to_ghosts

__all__ = ["DofNumbering", "number_dofs"]


@dataclass(frozen=True, slots=True)
class DofNumbering:
    """The reduced numbering: local reduced index i (owned block, then ``ghosts``) has global number
    ``global_indices[i]``; full local coefficients are d = T c (+ X c on the split side)."""

    num_owned: int  #: DOFs this rank owns
    ghosts: np.ndarray  #: global numbers of the ghost DOFs, sorted
    ghost_owners: np.ndarray  #: rank owning each ghost
    offsets: np.ndarray  #: start of every rank's block and the global size
    global_indices: np.ndarray  #: local reduced -> global
    T_local: sp.csr_matrix | None  #: full local -> reduced local (None: identity)
    X_local: sp.csr_matrix | None  #: the split-interface functions (None without a split)


def number_dofs(entities: TriangleEntities, constraints: EssentialConstraints, comm: MPI.Comm) -> DofNumbering:
    """Global numbering of the reduced space; T (full local -> reduced local) and the split part X."""
    top = entities.mesh.topology
    im0, im1 = top.index_map(0), top.index_map(1)
    nv_own, ne_own, nc = im0.size_local, im1.size_local, entities.num_cells
    nv, ne = entities.num_vertices, entities.num_edges
    null_spaces, split_bases = constraints.null, constraints.split_bases
    constrained = np.zeros(nv, dtype=bool)
    constrained[list(null_spaces)] = True
    k_null = np.zeros(nv, dtype=np.int64)
    for v, null in null_spaces.items():
        k_null[v] = null.shape[0]
    k_split = np.zeros(nv, dtype=np.int64)
    for v, z in split_bases.items():
        k_split[v] = z.shape[0]
    # owned reduced DOFs: kept full DOFs (local full order), null-space coefficients, split coefficients
    red_v = np.full((nv, 3), -1, dtype=np.int64)
    red_e = np.full((ne, 4), -1, dtype=np.int64)
    red_x = np.full((nv, 3), -1, dtype=np.int64)
    free_v = np.flatnonzero(~constrained[:nv_own])
    keep_e = constraints.keep_edge[:ne_own]
    n_kept_v, n_kept_e = 3 * free_v.size, int(keep_e.sum())
    cons_v = np.flatnonzero(constrained[:nv_own])
    split_v = np.flatnonzero(k_split[:nv_own] > 0)
    n_own = n_kept_v + n_kept_e + 3 * nc + int(k_null[cons_v].sum()) + int(k_split[split_v].sum())
    offs = block_offsets(comm, n_own)
    off = int(offs[comm.rank])
    red_v[free_v] = off + np.arange(n_kept_v).reshape(-1, 3)
    pos = off + n_kept_v
    red_e[:ne_own][keep_e] = pos + np.arange(n_kept_e)
    pos += n_kept_e
    red_c = pos + np.arange(3 * nc).reshape(nc, 3)
    pos += 3 * nc
    for v in cons_v:
        red_v[v, : k_null[v]] = pos + np.arange(k_null[v])
        pos += k_null[v]
    for v in split_v:
        red_x[v, : k_split[v]] = pos + np.arange(k_split[v])
        pos += k_split[v]
    assert pos == off + n_own
    if comm.size > 1:
        red_v = scatter_to_ghosts(im0, red_v[:nv_own])
        red_e = scatter_to_ghosts(im1, red_e[:ne_own])
        if comm.allreduce(bool(split_bases), op=MPI.LOR):
            red_x = scatter_to_ghosts(im0, red_x[:nv_own])
    # local reduced numbering: owned block, then the ghosts (sorted by global number)
    used = np.concatenate([red_v.ravel(), red_e.ravel(), red_x.ravel()])
    used = np.unique(used[(used >= 0) & ((used < off) | (used >= off + n_own))])
    global_indices = np.concatenate([off + np.arange(n_own), used])  # local reduced -> global

    def to_local(g: np.ndarray) -> np.ndarray:
        out = np.where(g >= 0, g - off, -1)
        ghost = (g >= 0) & ((g < off) | (g >= off + n_own))
        out[ghost] = n_own + np.searchsorted(used, g[ghost])
        return out

    lv, le, lc, lx = to_local(red_v), to_local(red_e), to_local(red_c), to_local(red_x)
    n_loc = n_own + used.size
    n_full = entities.num_dofs_full
    # T: full local -> reduced local
    r_idx, c_idx, vals = [], [], []
    free = np.flatnonzero(~constrained)
    r_idx.append((3 * free[:, None] + np.arange(3)).ravel())
    c_idx.append(lv[free].ravel())
    vals.append(np.ones(3 * free.size))
    for v, null in null_spaces.items():  # σ(v) = Σ_q c_q z_q
        for q, z in enumerate(null):
            nz = np.flatnonzero(z)
            r_idx.append(3 * v + nz)
            c_idx.append(np.full(nz.size, lv[v, q]))
            vals.append(z[nz])
    ei, ek = np.nonzero(constraints.keep_edge)
    r_idx.append(3 * nv + 4 * ei + ek)
    c_idx.append(le[ei, ek])
    vals.append(np.ones(ei.size))
    r_idx.append(3 * nv + 4 * ne + np.arange(3 * nc))
    c_idx.append(lc.ravel())
    vals.append(np.ones(3 * nc))
    r, c, w = np.concatenate(r_idx), np.concatenate(c_idx), np.concatenate(vals)
    if np.any(c < 0):
        raise RuntimeError("an Arnold–Winther degree of freedom has no global number")
    identity = n_loc == n_full and r.size == n_loc and np.array_equal(r, c) and np.all(w == 1.0)
    T_local = None if identity else sp.csr_matrix((w, (r, c)), shape=(n_full, n_loc))
    X_local = None
    if split_bases:
        r_idx, c_idx, vals = [], [], []
        for v, zs in split_bases.items():
            for q, z in enumerate(zs):
                nz = np.flatnonzero(z)
                r_idx.append(3 * v + nz)
                c_idx.append(np.full(nz.size, lx[v, q]))
                vals.append(z[nz])
        X_local = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(r_idx), np.concatenate(c_idx))), shape=(n_full, n_loc)
        )
    return DofNumbering(n_own, used, owner_of(used, offs), offs, global_indices, T_local, X_local)
