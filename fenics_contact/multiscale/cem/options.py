"""Parameters of the primal CEM-GMsFEM (Algorithm 3): ``CEMOptions`` and the warnings about risky choices.

``FEW_LAYERS`` and ``NEARLY_INCOMPRESSIBLE`` are the thresholds of the warnings (m too small for the bases to
decay; ν so close to ½ that they localize slowly), each with the measurements that placed it.
"""

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from fenics_contact.errors import InputError
from fenics_contact.fem.eigen import EIGEN_METHODS

__all__ = [
    "ALL_MODES",
    "RIGID_MOTIONS",
    "DEFAULT_S_FACTOR",
    "WHOLE_DOMAIN",
    "EIGENSOLVERS",
    "FEW_LAYERS",
    "NEARLY_INCOMPRESSIBLE",
    "CEMOptions",
    "warn_if_few_layers",
]

log = logging.getLogger(__name__)

#: ``nbasis`` value that keeps every local eigenfunction (V_aux = the broken fine space).
ALL_MODES = None

#: ``nbasis`` value (the default) that keeps as many modes as a floating coarse cell has rigid motions: 3 in the
#: plane, 6 in 3D (``CEMOptions.modes``).  Fewer cut through the zero eigenvalues (Λ = 0): on the 3D channel model
#: at h = 1/16, H = 1/4, m = 2 (``benchmarks/multiscale_primal_3d.py --h 16 --H 4 --layers 1 2 --nbasis 3 6``)
#: the energy error is 1.9e-2 with l = 3 and 1.0e-3 with l = 6.
RIGID_MOTIONS = "rigid"
#: the rigid motions of a coarse cell by dimension (translations and rotations)
_RIGID_MODES = {2: 3, 3: 6}

#: ``CEMOptions.patch_group`` value that solves every patch problem on all of Ω₁ (one factorization: the bases
#: are then the global ones, no localization error, dense over Ω₁)
WHOLE_DOMAIN = "all"

#: default c in κ̃ = c (λ + 2μ) H⁻² (see CEMOptions)
DEFAULT_S_FACTOR = 3.0

#: ``CEMOptions.eigensolver`` values: "auto" chooses between the two methods of ``fem.eigen``
EIGENSOLVERS = ("auto", *EIGEN_METHODS)

#: Algorithm 3 warns when ν in Ω₁ exceeds this.  As ν → ½ the smallest local eigenvalue left out, Λ,
#: falls like μ/(λ+2μ) and the bases localize slowly: model 3 at E 1e6, h = 1/64, H = 1/16, l = 3, m = 4
#: (``benchmarks/multiscale_primal.py --parts j``): energy error 3.3e-3 (ν = 0.35, Λ·c = 0.78), 3.2e-3
#: (0.4, 0.59), 2.9e-2 (0.45, 0.34), 0.30 (0.48, 0.15), 0.51 (0.49, 0.08), 0.82 (0.499, 0.01).  More modes
#: help only partly: with l_k raised until Λ ≥ 0.3 (Algorithm 4's rule tried on Algorithm 3) the error at
#: m = 4 is 0.29 at ν = 0.48, 0.22 at 0.49 and 0.10 at 0.499 (18 modes per cell, 5× the coarse space), far
#: from the 3e-3 of ν ≤ 0.4: the slow decay comes from λ/μ in a(·,·) itself, not only from Λ.  A small Λ alone
#: is no reason to warn: inclusions inside a coarse cell give one too (model 2 at h = 1/32, H = 1/8, ν = 0.35:
#: Λ·c = 0.34), which the CEM bases are built for.
NEARLY_INCOMPRESSIBLE = 0.42

#: fewer oversampling layers than this cut the bases short: warned about (``warn_if_few_layers``)
FEW_LAYERS = 2


def warn_if_few_layers(layers: int, method: str, comm) -> None:
    """Warn (rank 0) when m < ``FEW_LAYERS``: the bases are cut off at one coarse cell (m = 0) or two, and the
    error stays O(1) whatever the number of modes (measured below)."""
    if layers < FEW_LAYERS and comm.rank == 0:
        log.warning(
            "%s with m = %d oversampling layer(s): the multiscale bases are cut off where they have not decayed, "
            "and the Ω₁ error stays large (model 1, h = 1/32, H = 1/8: primal-ms e_u 0.72, 0.36, 5.1e-3, 3.9e-4 "
            "and mixed-ms e_σ 3.1, 0.44, 2.0e-2, 2.5e-3 for m = 0, 1, 2, 3). Use m >= 2 (default %d); check against "
            "the fine solution with --reference.",
            method,
            layers,
            CEMOptions().layers,
        )


@dataclass(frozen=True, slots=True)
class CEMOptions:
    """CEM-GMsFEM parameters: m oversampling layers, l_i eigenfunctions per coarse cell.

    ``nbasis`` is a number, ``RIGID_MOTIONS`` (the default: the rigid motions of a coarse cell, 3 in the plane
    and 6 in 3D, resolved by ``modes``) or None (``ALL_MODES``: every local eigenfunction). With
    ``threshold`` set, only eigenpairs with λ ≤ threshold among the ``nbasis``
    smallest are kept (at least one per coarse cell). ``eigensolver`` is
    ``"krylovschur"`` (shift-and-invert about ``target``), ``"lapack"`` (dense,
    all pairs) or ``"auto"`` (Krylov–Schur unless the local problem is too small
    for a Krylov subspace or most of its pairs are wanted).

    ``s_factor`` c scales the weight of the CEM inner product, κ̃ = c (λ + 2μ) H⁻²
    (the paper has c = 1; the CEM literature's κ Σ_j|∇χ_j|² with a bilinear
    partition of unity gives c between 2 and 4). Default 3, chosen from the sweep
    c ∈ {1, 2, 3, 10, 30, 100} recorded in benchmarks/results/multiscale_primal.md:
    at h = 1/64, H = 1/16, l = 3, m = 5 the energy error of model 1 is 1.0e-2 with
    c = 1 and 1.2e-4 with c = 3.

    ``source_correction`` (default on) corrects the Ω₁ load on the
    patches as the Robin data are (N_f); off, the coarse problem sees the load
    directly, as in the paper, and the error stalls once the load acts in Ω₁.

    ``patch_group`` g shares one patch factorization among a group of coarse cells: the cells are grouped
    (g × g blocks of a Cartesian coarse grid, g × g × g in 3D; on a general partition greedy groups of at most
    g^d cells within g − 1 adjacency steps of the group's first cell; ``WHOLE_DOMAIN`` one group of all
    of Ω₁) and the bases and correctors of a group's cells are all solved on ONE patch, the union of their
    m-layer oversamplings K_{k,m}.  The patch operator does not depend on the target cell, so one LDLᵀ serves
    the group.  Each group patch contains every K_{k,m} of its cells, so each basis is localized at least as
    well as with its own patch (the CEM decay estimate), at the price of wider supports: the patch grows from
    (2m+1)^d to (g+2m)^d coarse cells, the stored bases and the coarse matrix's bandwidth grow with it, and
    a factorization costs more while g^d fewer are made.  g = 1 (the default) is one patch per cell;
    ``WHOLE_DOMAIN`` gives the fine Robin solution of Ω₁ (no localization) with bases dense over Ω₁.
    """

    layers: int = 4
    nbasis: int | str | None = RIGID_MOTIONS
    threshold: float | None = None
    eigensolver: str = "auto"
    eig_tol: float = 1.0e-12
    target: float = -1.0
    s_factor: float = DEFAULT_S_FACTOR
    source_correction: bool = True
    patch_group: int | str = 1

    def __post_init__(self) -> None:
        if not (np.isfinite(self.s_factor) and self.s_factor > 0):
            raise InputError(f"s_factor must be finite and > 0, got {self.s_factor!r}")
        if int(self.layers) != self.layers or self.layers < 0:
            raise InputError(f"the number of oversampling layers must be an integer >= 0, got {self.layers!r}")
        if self.nbasis is not None and self.nbasis != RIGID_MOTIONS:
            if isinstance(self.nbasis, (str, bool)) or int(self.nbasis) != self.nbasis or self.nbasis < 1:
                raise InputError(
                    f"nbasis must be an integer >= 1 ({RIGID_MOTIONS!r}: the rigid motions, 3 in 2D and 6 in 3D; None: "
                    f"all modes), got {self.nbasis!r}"
                )
            object.__setattr__(self, "nbasis", int(self.nbasis))  # 3.0 → 3 (an index below)
        if self.threshold is not None and not (np.isfinite(self.threshold) and self.threshold > 0):
            raise InputError(f"the eigenvalue threshold must be finite and > 0, got {self.threshold!r}")
        if self.eigensolver not in EIGENSOLVERS:
            raise InputError(f"unknown eigensolver {self.eigensolver!r}; choose one of {EIGENSOLVERS}")
        if not (0 < self.eig_tol < 1e-2):
            raise InputError(f"eig_tol must lie in (0, 1e-2), got {self.eig_tol}")
        if not self.target < 0:
            raise InputError(f"the shift-and-invert target must be < 0 (A is only semi-definite), got {self.target}")
        if not isinstance(self.source_correction, bool):
            raise InputError(f"source_correction must be True or False, got {self.source_correction!r}")
        if self.patch_group != WHOLE_DOMAIN:
            g = self.patch_group
            whole = isinstance(g, (int, np.integer)) or (isinstance(g, float) and g.is_integer())
            if isinstance(g, bool) or not whole or g < 1:
                raise InputError(
                    f"patch_group must be an integer >= 1 (coarse cells per group and direction) or "
                    f"{WHOLE_DOMAIN!r} (one patch, all of Ω₁), got {g!r}"
                )
            object.__setattr__(self, "patch_group", int(g))

    def modes(self, dim: int) -> int | None:
        """l, the modes kept per coarse cell in dimension ``dim`` (``RIGID_MOTIONS``: 3 in 2D, 6 in 3D)."""
        if self.nbasis == RIGID_MOTIONS:
            if dim not in _RIGID_MODES:
                raise InputError(f"the CEM spaces are built in 2D and 3D, got dimension {dim}")
            return _RIGID_MODES[dim]
        return self.nbasis

    def for_dimension(self, dim: int) -> "CEMOptions":
        """These options with ``nbasis`` resolved for dimension ``dim`` (a number or None)."""
        return dataclasses.replace(self, nbasis=self.modes(dim))
