"""The offline data of the mixed CEM (Algorithm 4) on disk: ``OfflineData``, the cache key, the npz layout.

One npz file per configuration, keyed by a hash of everything the data depend on (``mixed_offline_key``),
checked by a stored checksum, written atomically and patch by patch without a second copy
(``multiscale.cache.OfflineCache``); the patch functions are stored in float32 (they only rebuild the fine
output fields, relative rounding 6·10⁻⁸), U_aux and the coarse matrices in float64.
"""

import hashlib
import json
from dataclasses import fields
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from fenics_contact import __version__
from fenics_contact.multiscale.cache import OfflineCache, hash_array
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.bases import CoarseCellDofs, PatchFunctions
from fenics_contact.multiscale.mixed_cem.coarse import COARSE_ARRAYS, SYMMETRIC_ARRAYS, CoarseOperators
from fenics_contact.multiscale.mixed_cem.operators import CellOperators
from fenics_contact.multiscale.mixed_cem.options import MixedCEMOptions
from fenics_contact.multiscale.mixed_cem.spectral import StageI

__all__ = ["MIXED_CACHE_FORMAT", "MixedOfflineCache", "OfflineData", "mixed_offline_key"]

#: Format of the cached mixed offline arrays: bumped whenever their layout or meaning changes.
MIXED_CACHE_FORMAT = 4


class OfflineData(NamedTuple):
    """What the online phase and the output need: U_aux, the patch functions and the coarse matrices."""

    aux: StageI
    basis: list  #: PatchFunctions ψ_j^i per coarse cell i
    corr: list  #: PatchFunctions of the data correctors per coarse cell (None: no γ facet, no load)
    co: CoarseOperators


#: Stored precision of the patch functions (AW coefficients, displacements) in the cache: they serve
#: only the fine output fields (relative rounding 6e-8); U_aux and the coarse matrices are float64.
_FUNCTION_DTYPE = np.float32


def mixed_offline_key(
    sub,
    ops: CellOperators,
    grid: CoarseGrid,
    options: MixedCEMOptions,
    *,
    H: float,
    traction_free: np.ndarray | None = None,
) -> str:
    """sha256 of everything the mixed offline data depend on.

    Mesh geometry and cells of Ω₁, facet tags, λ, μ, f, β, H, the coarse cells and their patches,
    every ``MixedCEMOptions`` field, the cache format and the package version, and (catching
    what these miss, e.g. a changed form) the cell operators assembled from them.
    """
    hasher = hashlib.sha256()
    meta = {
        "format": MIXED_CACHE_FORMAT,
        "version": __version__,
        "H": repr(float(H)),
        "beta": repr(float(sub.beta)),
        "num_coarse": int(grid.size),
        "options": {name: getattr(options, name) for name in sorted(f.name for f in fields(options))},
    }
    hasher.update(json.dumps(meta, sort_keys=True).encode())
    msh, ft, fld = sub.mesh, sub.facet_tags, sub.fields
    patches = [np.sort(np.asarray(grid.patch(k, options.layers), dtype=np.int64)) for k in range(grid.size)]
    arrays = {
        "x": msh.geometry.x,
        "cells": msh.geometry.dofmaps[0],
        "facet_indices": ft.indices,
        "facet_values": ft.values,
        "lambda": fld.lmbda.x.array,
        "mu": fld.mu.x.array,
        "f": fld.f.x.array,
        "gamma_points": sub.gamma_points,
        "coarse_cells": np.concatenate([np.sort(np.asarray(c, dtype=np.int64)) for c in grid.cells]),
        "coarse_sizes": np.array([len(c) for c in grid.cells], dtype=np.int64),
        "patches": np.concatenate(patches),
        "patch_sizes": np.array([p.size for p in patches], dtype=np.int64),
        "traction_free_edges": np.flatnonzero(traction_free) if traction_free is not None else np.zeros(0, np.int64),
    }
    for name in ("K", "R", "B", "M", "S", "G", "dg_rows", "u_rows", "gamma_cells", "P_cols", "P_blocks"):
        arrays[f"ops_{name}"] = getattr(ops, name)
    for name in ("F", "s0"):  # boundary data: tractions (lifting) and u_D
        if getattr(ops, name) is not None:
            arrays[f"ops_{name}"] = getattr(ops, name)
    for name in ("C", "E"):
        X = sp.csr_matrix(getattr(ops, name))
        arrays[f"ops_{name}_data"], arrays[f"ops_{name}_indices"] = X.data, X.indices
        arrays[f"ops_{name}_indptr"], arrays[f"ops_{name}_shape"] = X.indptr, np.array(X.shape)
    for name in sorted(arrays):
        hasher.update(name.encode())
        hash_array(hasher, arrays[name])
    return hasher.hexdigest()


def _concat(parts: list, dtype) -> np.ndarray:
    return np.concatenate([np.asarray(p, dtype=dtype).ravel() for p in parts]) if parts else np.zeros(0, dtype)


def _pack_offline(data: OfflineData):
    """(name, array) pairs in sorted name order, one patch at a time (no second copy of the functions)."""
    aux, co = data.aux, data.co
    yield "aux_gaps", np.asarray(aux.gaps, dtype=np.float64)
    yield "aux_modes", _concat(aux.modes, np.float64)
    yield "aux_offsets", np.asarray(aux.offsets, dtype=np.int64)
    yield "aux_residuals", np.asarray(aux.residuals, dtype=np.float64)
    yield "aux_values", _concat(aux.values, np.float64)
    for name in sorted(COARSE_ARRAYS):
        X = getattr(co, name)
        yield f"co_{name}", X[np.triu_indices(X.shape[0])] if name in SYMMETRIC_ARRAYS else X
    yield "co_sizes", np.array([co.n_ms, co.n_aux, co.n_g], dtype=np.int64)
    for kind, funcs in (("b", data.basis), ("c", data.corr)):
        for i, f in enumerate(funcs):
            if f is None:
                continue
            yield f"fn_{kind}_{i:07d}_coarse", np.asarray(f.coarse, dtype=np.int64)
            yield f"fn_{kind}_{i:07d}_index", np.asarray(f.index, dtype=np.int64)
            yield f"fn_{kind}_{i:07d}_sigma", _concat(f.sigma, _FUNCTION_DTYPE)
            yield f"fn_{kind}_{i:07d}_u", _concat(f.u, _FUNCTION_DTYPE)


def _split(flat: np.ndarray, sizes: np.ndarray, what: str) -> list:
    if int(np.sum(sizes)) != flat.size:
        raise ValueError(f"cached {what} have {flat.size} entries, expected {int(np.sum(sizes))}")
    return np.split(flat, np.cumsum(sizes)[:-1]) if sizes.size else []


def _unpack_functions(arrays: dict, prefix: str, dofs: CoarseCellDofs, n_index: int) -> PatchFunctions:
    coarse, index = arrays.pop(f"{prefix}_coarse"), arrays.pop(f"{prefix}_index")
    if coarse.size == 0 or coarse.min() < 0 or coarse.max() >= len(dofs.cells) or np.any(np.diff(coarse) <= 0):
        raise ValueError(f"cached {prefix}: invalid coarse cells")
    if index.size == 0 or index.min() < 0 or index.max() >= n_index:
        raise ValueError(f"cached {prefix}: invalid function indices")
    k = index.size
    na = np.array([dofs.aw[K].size for K in coarse])
    nu = np.array([6 * dofs.cells[K].size for K in coarse])
    sig = _split(arrays.pop(f"{prefix}_sigma"), na * k, f"{prefix} stresses")
    dis = _split(arrays.pop(f"{prefix}_u"), nu * k, f"{prefix} displacements")
    return PatchFunctions(
        coarse,
        index,
        [s.astype(np.float64).reshape(-1, k) for s in sig],
        [d.astype(np.float64).reshape(-1, k) for d in dis],
    )


def _unpack_offline(arrays: dict, ops: CellOperators, grid: CoarseGrid) -> OfflineData:
    offsets = arrays["aux_offsets"]
    if offsets.shape != (grid.size + 1,) or offsets[0] != 0 or np.any(np.diff(offsets) < 0):
        raise ValueError("cached U_aux does not match the coarse grid")
    nk = np.diff(offsets)
    ncell = np.array([len(c) for c in grid.cells], dtype=np.int64)
    values = _split(arrays["aux_values"], nk, "eigenvalues")
    modes = [m.reshape(nc, 6, k) for m, nc, k in zip(_split(arrays["aux_modes"], 6 * ncell * nk, "modes"), ncell, nk)]
    aux = StageI(values, modes, offsets, arrays["aux_residuals"], arrays["aux_gaps"])
    n_ms, n_aux, n_g = (int(s) for s in arrays["co_sizes"])
    if n_ms != aux.size or n_aux != aux.size or n_g != ops.num_gamma_values:
        raise ValueError("cached coarse operators do not match U_aux or the interface")
    dofs = CoarseCellDofs.of(ops, grid)
    basis = [_unpack_functions(arrays, f"fn_b_{i:07d}", dofs, n_ms) for i in range(grid.size)]
    corr = [
        _unpack_functions(arrays, f"fn_c_{i:07d}", dofs, n_g + 1) if f"fn_c_{i:07d}_index" in arrays else None
        for i in range(grid.size)
    ]
    n_d = n_g + 1
    n = n_ms + n_d
    mats = {name: arrays[f"co_{name}"] for name in COARSE_ARRAYS}
    for name, size in (("Gt", n), ("Gk", n), ("Mu", n_aux + n_d)):
        tri = mats[name]
        if tri.shape != (size * (size + 1) // 2,):
            raise ValueError(f"cached coarse matrix {name} has {tri.size} entries, expected a triangle of {size}")
        X = np.zeros((size, size))
        X[np.triu_indices(size)] = tri
        mats[name] = X + np.triu(X, 1).T
    shapes = {
        "Gt": (n, n),
        "Gk": (n, n),
        "Bm": (n_aux, n),
        "BN": (n, n_d),
        "Cphi": (n, n_g),
        "Ephi": (n_g, n),
        "Mu": (n_aux + n_d, n_aux + n_d),
        "PiG": (n_aux,),
        "Fphi": (n,),
    }
    for name, shape in shapes.items():
        if mats[name].shape != shape:
            raise ValueError(f"cached coarse matrix {name} has shape {mats[name].shape}, expected {shape}")
    return OfflineData(aux, basis, corr, CoarseOperators(n_ms, n_aux, n_g, **mats))


class MixedOfflineCache(OfflineCache):
    """npz files ``mixed_cem_<key>.npz``: ``cache.OfflineCache`` holding ``OfflineData``, written patch by patch."""

    prefix = "mixed_cem"

    @staticmethod
    def pack(obj: OfflineData):
        return _pack_offline(obj)

    @staticmethod
    def unpack(arrays: dict[str, np.ndarray], *context) -> OfflineData:
        return _unpack_offline(arrays, *context)
