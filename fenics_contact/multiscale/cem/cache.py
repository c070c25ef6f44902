"""The offline data of the primal CEM (Algorithm 3) on disk: the cache key, the npz layout, the offline stage.

The aux functions, the bases, N, N_f and the Gram matrices ZᵀKZ, ZᵀMZ of Z = [Ψ, N, N_f] are cached (npz, one
entry per patch: written without a second copy) under a key hashing everything they depend on (``offline_key``);
a file whose stored key or checksum does not match is rebuilt, never used (``multiscale.cache.OfflineCache``).
``offline_stage`` builds or loads them.
"""

import hashlib
import json
import logging
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fenics_contact import __version__
from fenics_contact.errors import InputError
from fenics_contact.multiscale.cache import OfflineCache, hash_array
from fenics_contact.multiscale.cem.bases import MultiscaleSpace, build_multiscale_space, split_blocks
from fenics_contact.multiscale.cem.coarse import gram_matrices
from fenics_contact.multiscale.cem.operators import FineOperators
from fenics_contact.multiscale.cem.options import WHOLE_DOMAIN, CEMOptions
from fenics_contact.multiscale.cem.spectral import AuxiliarySpace, restrict
from fenics_contact.multiscale.coarse import CoarseGrid

__all__ = ["CACHE_FORMAT", "PrimalOfflineCache", "offline_key", "offline_stage"]

log = logging.getLogger(__name__)

#: Format of the cached arrays: bumped whenever their layout or meaning changes (4: the Gram matrices stored; 5: one
#: Robin corrector per patch problem, the masses of a γ vertex shared by cells of one group summed).
CACHE_FORMAT = 5


def offline_key(ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, h: float) -> str:
    """sha256 of everything the offline data depend on: mesh, coarse grid, E, ν, α, load, options, version."""
    hasher = hashlib.sha256()
    meta = {
        "format": CACHE_FORMAT,
        "version": __version__,
        "h": repr(float(h)),
        "H": repr(float(grid.H)),
        "options": {
            "layers": options.layers,
            "nbasis": options.modes(ops.bs),
            "threshold": options.threshold,
            "eigensolver": options.eigensolver,
            "eig_tol": options.eig_tol,
            "target": options.target,
            "s_factor": options.s_factor,
            "source_correction": options.source_correction,
        },
    }
    if options.patch_group != 1:  # one patch per cell: the keys of the default unchanged
        meta["options"]["patch_group"] = options.patch_group
    if ops.bs != 2:  # the dimension (the cell_nodes shape holds it too; 2D keys unchanged)
        meta["dim"] = int(ops.bs)
    hasher.update(json.dumps(meta, sort_keys=True).encode())
    for name in sorted(ops.key_data):
        if name == "load" and not options.source_correction:
            continue
        hasher.update(name.encode())
        hash_array(hasher, ops.key_data[name])
    return hasher.hexdigest()


def _pack(space: MultiscaleSpace) -> dict:
    """Arrays to store: the aux space (small, concatenated) and one entry per patch block (no copies)."""
    aux = space.aux
    out = {
        "aux_offsets": aux.offsets,
        "aux_dof_offsets": np.concatenate([[0], np.cumsum([d.size for d in aux.dofs])]).astype(np.int64),
        "aux_dofs": np.concatenate(aux.dofs).astype(np.int64),
        "aux_values": np.concatenate(aux.eigenvalues),
        "aux_gaps": aux.gaps,
        "aux_vectors": np.concatenate([Phi.ravel() for Phi in aux.vectors]),
        "meta": np.array([space.layers, space.n, space.n_gamma, len(space.blocks)]),
    }
    for k, (cells, p) in enumerate(zip(space.groups, space.blocks)):
        out[f"block{k}_cells"] = np.asarray(cells, dtype=np.int64)
        out[f"block{k}_dofs"] = p.dofs
        out[f"block{k}_values"] = p.values
        out[f"block{k}_gamma"] = p.columns[p.columns >= space.size] - space.size
    if space.Nf is not None:
        out["Nf"] = space.Nf
    if space.patch_group != 1:  # 0: WHOLE_DOMAIN
        out["patch_group"] = np.array([0 if space.patch_group == WHOLE_DOMAIN else space.patch_group])
    if space.grams is not None:
        out["gram_K"], out["gram_M"] = space.grams
    return out


def _unpack(arrays: dict, ops: FineOperators, grid: CoarseGrid) -> MultiscaleSpace:
    offs, doffs = arrays["aux_offsets"], arrays["aux_dof_offsets"]
    if offs.size != grid.size + 1 or doffs.size != grid.size + 1:
        raise ValueError("cached auxiliary space does not match the coarse grid")
    dofs, values, vectors, s_phi = [], [], [], []
    pos = 0
    for k in range(grid.size):
        D = arrays["aux_dofs"][doffs[k] : doffs[k + 1]]
        lk = int(offs[k + 1] - offs[k])
        Phi = arrays["aux_vectors"][pos : pos + D.size * lk].reshape(D.size, lk)
        pos += D.size * lk
        S = restrict(ops.Sc[int(grid.colors[k])], D)
        dofs.append(D)
        values.append(arrays["aux_values"][offs[k] : offs[k + 1]])
        vectors.append(Phi)
        s_phi.append(S @ Phi)
    aux = AuxiliarySpace.from_parts(ops.size, dofs, values, vectors, s_phi, arrays["aux_gaps"])
    layers, n, ng, nblocks = (int(x) for x in arrays["meta"])
    if n != ops.size or ng != ops.gamma.size:
        raise ValueError("cached multiscale space does not match the Ω₁ operators")
    groups = [arrays[f"block{k}_cells"] for k in range(nblocks)]
    basis, blocks, correction, correction_cells = split_blocks(
        aux,
        grid.size,
        (
            (cells, arrays[f"block{k}_dofs"], arrays[f"block{k}_values"], arrays[f"block{k}_gamma"])
            for k, cells in enumerate(groups)
        ),
    )
    if any(b is None for b in basis):
        raise ValueError("cached multiscale space does not hold a basis of every coarse cell")
    times = {"eigen": 0.0, "patches": 0.0, "total": 0.0}
    nz = aux.size + ng + 1
    grams = (arrays["gram_K"], arrays["gram_M"])
    if any(G.shape != (nz, nz) for G in grams):
        raise ValueError("cached Gram matrices do not match the multiscale space")
    group = int(arrays["patch_group"][0]) if "patch_group" in arrays else 1
    return MultiscaleSpace(
        aux,
        basis,
        correction,
        arrays.get("Nf"),
        layers,
        n,
        ng,
        correction_cells,
        times,
        grams,
        patch_group=WHOLE_DOMAIN if group == 0 else group,
        blocks=blocks,
        groups=groups,
    )


class PrimalOfflineCache(OfflineCache):
    """npz files ``cem_<key>.npz`` holding the primal ``MultiscaleSpace`` (``cache.OfflineCache``)."""

    prefix = "cem"

    @staticmethod
    def pack(obj: "MultiscaleSpace") -> dict[str, np.ndarray]:
        return _pack(obj)

    @staticmethod
    def unpack(arrays: dict[str, np.ndarray], *context) -> "MultiscaleSpace":
        return _unpack(arrays, *context)


def offline_stage(
    ops: FineOperators,
    grid: CoarseGrid,
    options: CEMOptions,
    *,
    h: float,
    cache_dir: str | Path | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
) -> tuple[MultiscaleSpace, str]:
    """Build (or load from the cache) the multiscale space; returns (space, cache status).

    Under MPI every rank reads the cache file; rank 0 alone writes it.
    """
    if cache_dir is None:
        return build_multiscale_space(ops, grid, options, comm=comm), "disabled"
    cache = PrimalOfflineCache(cache_dir)
    key = offline_key(ops, grid, options, h=h)
    t0 = time.perf_counter()
    space, status = cache.load(key, ops, grid)
    # every rank must agree on the cache status before the collective build
    if comm.size > 1 and comm.allreduce(int(space is None), op=MPI.MAX):
        space, status = None, comm.bcast(status if space is None else "missing", root=0)
    if space is not None:
        space.times["load"] = time.perf_counter() - t0
        log.info("CEM offline data loaded from %s", cache.path(key))
        return space, status
    if status != "missing":
        log.warning("CEM offline cache %s rejected (%s); rebuilding", cache.path(key), status)
    error = None
    if comm.rank == 0:
        try:
            cache.check_writable()  # before the expensive build, not after it
        except InputError as err:
            error = str(err)
    error = comm.bcast(error, root=0)  # every rank raises, none waits in the collective build
    if error is not None:
        raise InputError(error)
    space = build_multiscale_space(ops, grid, options, comm=comm)
    t0 = time.perf_counter()
    space.grams = gram_matrices(ops, grid, space, comm=comm)  # stored too: a later run needs no pass over the bases
    space.equations = None  # (used by the Gram matrices only)
    space.times["gram"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if comm.rank == 0:
        try:
            cache.save(key, space)
        except OSError as err:  # the directory went away or filled up meanwhile: keep the built data
            log.warning("CEM offline data could not be saved to %s: %s", cache.path(key), err)
    comm.Barrier()
    space.times["save"] = time.perf_counter() - t0
    return space, "built" if status == "missing" else "rebuilt"
