"""Parameters of the mixed CEM-GMsFEM (Algorithm 4): ``MixedCEMOptions`` and the Stage I targets behind them.

``DEFAULT_MIN_GAP`` and ``DEFAULT_MAX_NBASIS`` set the Stage I rule (more modes where Λ is small); ``SMALL_GAP``
is the threshold of the warning about slowly decaying bases; each with the measurements that placed it
(``benchmarks/mixed_ms_localization.py`` measures the decay rates).
"""

from dataclasses import dataclass

import numpy as np

from fenics_contact.errors import InputError
from fenics_contact.multiscale.cem.options import DEFAULT_S_FACTOR

__all__ = ["DEFAULT_MAX_NBASIS", "DEFAULT_MIN_GAP", "SMALL_GAP", "MixedCEMOptions"]

#: Λ·c below this triggers a warning (with a fixed l): at h = 1/64, H = 1/16, m = 5 the paper's cases give
#: e_σ ≤ 1e-3 with Λ·c ≥ 0.07 (ν = 0.35: 0.57; ν = 0.49: 0.07, 0.31) and 9e-3…2e-1 with Λ·c ≤ 0.03 (ν = 0.499)
#: (``benchmarks/reproduce_mixed_ms_tables.py``, Tables 5.5–5.7 with ``--min-gap 0``).
SMALL_GAP = 0.05

#: Default Stage I target for Λ, the first eigenvalue left out on each coarse cell (κ̃ with c).
#: The Stage II bases decay like exp(−ρ·distance/H).  Global bases of a central cell, h = 1/64,
#: H = 1/16, c = 3 (benchmarks/mixed_ms_localization.py): ρ = 2.2 for ν = 0.3 (l = 3, Λ = 1.5) and
#: 1.8 for ν = 0.49 (l = 3, Λ = 0.10), but 0.60 for ν = 0.499 (l = 3, Λ = 0.011): near-div-free
#: modes have Λ ∝ μ/(λ+2μ).  Adding modes until Λ ≥ 0.1 gives ρ = 1.9 for ν = 0.499 (11–21 modes)
#: and, capped at 32 modes (Λ = 0.019), also for ν = 0.4999.  For ν ≤ 0.49 the paper's l = 3
#: already meets the target.
DEFAULT_MIN_GAP = 0.1

#: Default cap on the Stage I modes per coarse cell when ``min_gap`` adds modes (32 reach the decay of
#: ν = 0.3 even at ν = 0.4999, see ``DEFAULT_MIN_GAP``).
DEFAULT_MAX_NBASIS = 32


@dataclass(frozen=True, slots=True)
class MixedCEMOptions:
    """Mixed CEM parameters: m oversampling layers, l eigenfunctions per coarse cell (None: all).

    ``nbasis`` is the least number of Stage I modes per coarse cell (the paper's l = 3).  With
    ``min_gap`` a cell keeps further modes, up to ``max_nbasis``, until the first eigenvalue left out
    is ≥ ``min_gap`` (the decay of the bases with the layers is governed by it, see
    ``DEFAULT_MIN_GAP``); ``min_gap=None`` keeps exactly ``nbasis`` (the paper's fixed l).
    """

    layers: int = 4
    nbasis: int | None = 3
    min_gap: float | None = DEFAULT_MIN_GAP
    max_nbasis: int = DEFAULT_MAX_NBASIS
    weight: str = "lambda+2mu"  #: κ̃ = c(λ+2μ)H⁻² (the paper has c = 1) or "2mu": κ̃ = c·2μ H⁻²
    #: c, as for the primal CEM (multiscale.CEMOptions.s_factor). Model 2, h = 1/32, H = 1/8, m = 3:
    #: e_σ = 4.2e-3 (c = 1), 2.3e-3 (c = 3), 2.6e-3 (c = 10).
    s_factor: float = DEFAULT_S_FACTOR
    #: Localized source correctors: the Ω₁ response to f is computed on the oversampled
    #: patches and the coarse problem solves for the remainder, so that the error falls with m for any
    #: load.  False: the paper's Algorithm 4 (f seen only through U_aux: an O(H Λ^{-1/2}) floor).
    source_correction: bool = True
    #: Stage I eigensolver: "auto" (dense LAPACK for small coarse cells, else "krylovschur"), "lapack"
    #: (all pairs, dense) or "krylovschur" (SLEPc shift-and-invert for the pairs kept, inertia-checked).
    eigensolver: str = "auto"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.s_factor) and self.s_factor > 0):
            raise InputError(f"s_factor must be finite and > 0, got {self.s_factor!r}")
        if self.weight not in ("lambda+2mu", "2mu"):
            raise InputError(f"weight must be 'lambda+2mu' or '2mu', got {self.weight!r}")
        if int(self.layers) != self.layers or self.layers < 0:
            raise InputError(f"the number of oversampling layers must be an integer >= 0, got {self.layers!r}")
        if self.nbasis is not None and (int(self.nbasis) != self.nbasis or self.nbasis < 1):
            raise InputError(f"nbasis must be an integer >= 1 (or None for all modes), got {self.nbasis!r}")
        if self.min_gap is not None and not (np.isfinite(self.min_gap) and self.min_gap > 0):
            raise InputError(f"min_gap must be finite and > 0 (or None for a fixed nbasis), got {self.min_gap!r}")
        if int(self.max_nbasis) != self.max_nbasis or self.max_nbasis < 1:
            raise InputError(f"max_nbasis must be an integer >= 1, got {self.max_nbasis!r}")
        if self.nbasis is not None and self.max_nbasis < self.nbasis:
            raise InputError(f"max_nbasis ({self.max_nbasis}) must be >= nbasis ({self.nbasis})")
        if self.eigensolver not in ("auto", "lapack", "krylovschur"):
            raise InputError(f"eigensolver must be 'auto', 'lapack' or 'krylovschur', got {self.eigensolver!r}")
        if not isinstance(self.source_correction, (bool, np.bool_)):
            raise InputError(f"source_correction must be True or False, got {self.source_correction!r}")
