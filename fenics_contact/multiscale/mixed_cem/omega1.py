"""The Ω₁ side of Algorithm 4: ``MixedMultiscaleOmega1`` (offline stages, cache, online coarse solve, fields)."""

import logging
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.multiscale.cem.operators import require_serial
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.bases import CoarseCellDofs
from fenics_contact.multiscale.mixed_cem.cache import MixedOfflineCache, OfflineData, mixed_offline_key
from fenics_contact.multiscale.mixed_cem.coarse import coarse_operators, reaching
from fenics_contact.multiscale.mixed_cem.local_space import Topology
from fenics_contact.multiscale.mixed_cem.operators import cell_operators, scale_to_cell_sizes
from fenics_contact.multiscale.mixed_cem.options import DEFAULT_MIN_GAP, SMALL_GAP, MixedCEMOptions
from fenics_contact.multiscale.mixed_cem.response import InterfaceResponse
from fenics_contact.multiscale.mixed_cem.skeleton import held_cells, stage_two
from fenics_contact.multiscale.mixed_cem.spectral import stage_one

__all__ = ["MixedMultiscaleOmega1"]

log = logging.getLogger(__name__)


class MixedMultiscaleOmega1:
    """Ω₁ of Algorithm 4: offline stages on an Ω₁ ``MixedSubproblem`` and the online coarse solve.

    ``solve(g)`` returns the coarse state (r, w) for Robin data g (values at the γ
    nodes); σ₁ = Ψ r + Q g and u₁ = Π w + N g are never formed online: norms and
    traces use the dense coarse operators (``stress_state``, ``trace``, ...).

    With ``cache_dir`` the offline data (U_aux, the patch functions, the coarse
    matrices) are read from / written to ``cache_dir/mixed_cem_<key>.npz``
    (``mixed_offline_key``); ``cache_status`` is 'disabled', 'loaded', 'built' (no file yet) or
    'rebuilt (invalid: <why>)', as for the primal CEM.  A valid file is used even in a read-only directory;
    when the data must be built and the directory cannot be written, an InputError
    is raised before the (expensive) build.  A failure of the final write itself
    only logs a warning: the built data are kept.
    """

    def __init__(
        self,
        sub,
        grid: CoarseGrid,
        options: MixedCEMOptions,
        *,
        H: float,
        cache_dir: str | Path | None = None,
        comm: MPI.Comm = MPI.COMM_SELF,
        traction_free_facets: np.ndarray | None = None,
    ) -> None:
        require_serial(sub.mesh.comm)
        self.options = options
        self.grid = grid
        self.comm = comm
        self.times: dict[str, float] = {}  #: wall seconds of the offline parts
        self.cpu_times: dict[str, float] = {}  #: CPU seconds of this process in the same parts
        t, c = time.perf_counter(), time.process_time()
        self.ops = cell_operators(sub, H, options.weight, options.s_factor)
        scale_to_cell_sizes(self.ops, grid, H)
        self.topo = Topology(sub.mesh, self.ops.num_aw, traction_free_facets)
        self.times["assembly"] = time.perf_counter() - t
        self.cpu_times["assembly"] = time.process_time() - c
        self.cache_status = "disabled"
        self.cache_path: Path | None = None
        #: the coarse cells whose patch-function pieces this rank holds (None: all).  Under MPI without a cache
        #: the pieces are not gathered: the coarse operators and the fine fields are formed where they lie.
        self._held: np.ndarray | None = None
        data = None
        if cache_dir is not None:
            t, c = time.perf_counter(), time.process_time()
            cache = MixedOfflineCache(cache_dir)
            key = mixed_offline_key(sub, self.ops, grid, options, H=H, traction_free=self.topo.tf_edge)
            self.cache_path = cache.path(key)
            data, self.cache_status = cache.load(key, self.ops, grid)
            statuses = comm.allgather(self.cache_status)  # every rank builds, or none
            if any(st != "loaded" for st in statuses) and data is not None:
                data, self.cache_status = None, next(st for st in statuses if st != "loaded")
            if data is not None:
                self._setup_online(data)
                self.times["load"] = time.perf_counter() - t
                self.cpu_times["load"] = time.process_time() - c
                log.info("mixed CEM offline data loaded from %s", self.cache_path)
            else:
                if self.cache_status != "missing":
                    log.warning(
                        "mixed CEM offline cache %s rejected (%s); rebuilding", self.cache_path, self.cache_status
                    )
                problem = None
                if comm.rank == 0:
                    try:
                        cache.check_writable()
                    except InputError as err:
                        problem = str(err)
                problem = comm.bcast(problem, root=0)
                if problem is not None:
                    raise InputError(problem)
                self.cache_status = "built" if self.cache_status == "missing" else f"rebuilt ({self.cache_status})"
        if data is None:
            t, c = time.perf_counter(), time.process_time()
            aux = stage_one(
                self.ops,
                self.topo,
                grid,
                options.nbasis,
                options.min_gap,
                options.max_nbasis,
                options.eigensolver,
                comm=comm,
            )
            self.times["eigen"] = time.perf_counter() - t
            self.cpu_times["eigen"] = time.process_time() - c
            t, c = time.perf_counter(), time.process_time()
            self.dofs = CoarseCellDofs.of(self.ops, grid)
            distributed = comm.size > 1 and cache_dir is None  # (the cache file needs every function on rank 0)
            basis, corr = stage_two(
                self.ops,
                self.topo,
                grid,
                aux,
                options.layers,
                options.source_correction,
                dofs=self.dofs,
                comm=comm,
                distributed=distributed,
            )
            if distributed and comm.allreduce(any(a is None for f in basis for a in f.sigma), op=MPI.LOR):
                self._held = held_cells(basis)
            self.times["basis"] = time.perf_counter() - t
            self.cpu_times["basis"] = time.process_time() - c
            t, c = time.perf_counter(), time.process_time()
            data = OfflineData(
                aux,
                basis,
                corr,
                coarse_operators(self.ops, grid, aux, basis, corr, dofs=self.dofs, comm=comm, cells=self._held),
            )
            self._setup_online(data)
            self.times["coarse"] = time.perf_counter() - t
            self.cpu_times["coarse"] = time.process_time() - c
            if cache_dir is not None:
                t, c = time.perf_counter(), time.process_time()
                if comm.rank == 0:
                    try:
                        cache.save(key, data)
                        log.info("mixed CEM offline data written to %s", self.cache_path)
                    except OSError as err:
                        log.warning("could not write the mixed CEM offline cache %s (%s)", self.cache_path, err)
                comm.Barrier()
                self.times["save"] = time.perf_counter() - t
                self.cpu_times["save"] = time.process_time() - c
        co = self.co
        lo, hi = self.nbasis_range
        log.info(
            "mixed CEM Ω₁ (m=%d, l=%d..%d per cell): dim X_ms %d, dim U_aux %d, max Stage I residual %.1e, Λ %.2e, "
            "cache %s, times %s",
            options.layers,
            lo,
            hi,
            co.n_ms,
            co.n_aux,
            float(self.aux.residuals.max()),
            self.spectral_gap,
            self.cache_status,
            {k: round(v, 2) for k, v in self.times.items()},
        )
        if not options.source_correction and self.ops.F is not None:
            log.warning(
                "mixed CEM without source correctors: the Ω₁ boundary data (a prescribed displacement on Gamma_D or "
                "the traction lifting) act on the stresses, which X_ms sees only through Ψᵀ F, an error no number of "
                "layers removes (e_σ = 0.13 with all modes and patches covering Ω₁, h = 1/16, H = 1/4); keep "
                "source_correction=True (the default)"
            )
        if options.min_gap is not None and self.spectral_gap < options.min_gap:
            log.warning(
                "mixed CEM: the Stage I target Λ ≥ %g was not reached with at most max_nbasis = %d modes per cell "
                "(Λ = %.2e, ν → ½ in Ω₁): the basis functions may decay more slowly with the oversampling layers "
                "(for ν = 0.4999, h = 1/64, H = 1/16, 32 modes still gave the decay of ν = 0.3). Check the error "
                "with one layer more, raise max_nbasis, or use Algorithm 2.",
                options.min_gap,
                options.max_nbasis,
                self.spectral_gap,
            )
        elif options.min_gap is None and self.spectral_gap * options.s_factor < SMALL_GAP:
            log.warning(
                "mixed CEM: the smallest left-out Stage I eigenvalue is Λ = %.2e (Λ·c < %g): the basis functions "
                "decay slowly with the oversampling layers (expected for ν → ½ in Ω₁ with a fixed l); at m = 5 "
                "errors of 1e-2 and more were measured in such cases. Set min_gap (e.g. %g) to add modes where "
                "Λ is small, add layers, or use Algorithm 2.",
                self.spectral_gap,
                SMALL_GAP,
                DEFAULT_MIN_GAP,
            )

    @property
    def nbasis_range(self) -> tuple[int, int]:
        """(least, most) Stage I modes kept on a coarse cell."""
        counts = np.diff(self.aux.offsets)
        return int(counts.min()), int(counts.max())

    @property
    def spectral_gap(self) -> float:
        """Λ = min over coarse cells of the first Stage I eigenvalue left out (inf when all are kept)."""
        return float(np.min(self.aux.gaps, initial=np.inf))

    def _setup_online(self, data: OfflineData) -> None:
        """Keep the offline data; factorize the coarse matrix [[ΨᵀÃΨ, (ΠᵀBΨ)ᵀ], [ΠᵀBΨ, 0]] (dense LU: with the
        S-orthonormal modes Π it is dimensionless, the same matrix in any units of E, so it needs no scaling)."""
        self.aux, self.basis, self.corr, self.co = data
        if getattr(self, "dofs", None) is None:
            self.dofs = CoarseCellDofs.of(self.ops, self.grid)
        self._reach_b = reaching(self.basis, self.grid.size)
        self._reach_c = reaching(self.corr, self.grid.size)
        co = self.co
        ms = slice(0, co.n_ms)
        qd = slice(co.n_ms, co.n_ms + co.n_d)
        A = np.block([[co.Gt[ms, ms], co.Bm[:, ms].T], [co.Bm[:, ms], np.zeros((co.n_aux, co.n_aux))]])
        self._lu = sla.lu_factor(A)
        # right-hand sides for the data d = [g; 1]: τ rows F1 d, v rows Πᵀ G − F2 d
        load = np.zeros((co.n_ms, 1)) if co.Fphi is None else co.Fphi[ms, None]  # Ψᵀ F: boundary data
        self._F1 = np.hstack([co.Cphi[ms], load]) - co.Gt[ms, qd] - co.BN[ms]
        self._F2 = co.Bm[:, qd]
        self._E_r, self._E_g = co.Ephi[:, ms], co.Ephi[:, qd].copy()
        if self.ops.s0 is not None:  # σ₁n₁ of the traction lifting s₀ (σ₁ = Ψ r + Q g + σ_f + s₀)
            self._E_g[:, co.n_g] += self.ops.E @ self.ops.s0.ravel()
        self.response = InterfaceResponse.of(co, self._lu, self._F1, self._F2, self._E_r, self._E_g)

    @staticmethod
    def data(g: np.ndarray) -> np.ndarray:
        """The data vector d = [g; 1] (γ values, then the load's weight)."""
        return np.append(np.asarray(g, dtype=float), 1.0)

    def solve_lu(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coarse (r, w) for Robin data g by the coarse LU (``solve`` uses the precomputed response)."""
        n, d = self.co.n_ms, self.data(g)
        x = sla.lu_solve(self._lu, np.concatenate([self._F1 @ d, self.co.PiG - self._F2 @ d]))
        return x[:n], x[n:]

    @property
    def num_coarse_dofs(self) -> int:
        """dim X_ms + dim U_aux."""
        return self.co.n_ms + self.co.n_aux

    def solve(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coarse (r, w) for Robin data g: r = R g + r₀, w = W g + w₀ (``InterfaceResponse``)."""
        rs = self.response
        return rs.R @ g + rs.r0, rs.W @ g + rs.w0

    def trace(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """σ₁n₁ at the γ nodes."""
        return self._E_r @ r + self._E_g @ self.data(g)

    def stress_norm2(self, r: np.ndarray, g: np.ndarray) -> float:
        """‖Ψ r + Q g + σ_f‖²_A."""
        x = np.concatenate([r, self.data(g)])
        return float(x @ self.co.Gk @ x)

    def l2_norm2(self, w: np.ndarray, g: np.ndarray) -> float:
        """‖Π w + N g + u_f‖²_L²."""
        x = np.concatenate([w, self.data(g)])
        return float(x @ self.co.Mu @ x)

    # -- fine reconstruction (output, errors, tests) ----------------------------------
    def _combine(self, K: int, r: np.ndarray | None, d: np.ndarray, part: str) -> np.ndarray:
        """Σ over the functions reaching K of their ``part`` ('sigma' or 'u') on K times their coefficient."""
        out = None
        terms = ([] if r is None else [(f, p, r) for f, p in self._reach_b[K]]) + [
            (q, p, d) for q, p in self._reach_c[K]
        ]
        for f, p, coef in terms:
            x = getattr(f, part)[p] @ coef[f.index]
            out = x if out is None else out + x
        return out

    @property
    def distributed(self) -> bool:
        """Whether the patch functions are spread over the ranks of ``comm`` (each coarse cell's pieces on one):
        then ``fine_stress`` and the other fine fields are collective over ``comm``."""
        return self._held is not None

    def _here(self) -> np.ndarray:
        """The coarse cells whose fine fields this rank forms (``_held``; all without MPI or with a cache)."""
        return np.arange(self.grid.size) if self._held is None else self._held

    def _summed(self, out: np.ndarray) -> np.ndarray:
        """A fine field formed on the held coarse cells, completed by the other ranks' (each cell from one rank)."""
        if self._held is not None:
            self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out

    def fine_stress(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """σ₁ = Ψ r + Q g + σ_f, cell-major (n_cells, 30): without the traction lifting ``lifting`` (collective
        over ``comm`` when the patch functions are distributed)."""
        out = np.zeros((self.ops.num_cells, 30))
        d = self.data(g)
        for K in self._here():
            out[self.dofs.cells[K]] = self.dofs.dg(self.ops, K, self._combine(K, r, d, "sigma"))
        return self._summed(out)

    def fine_displacement(self, w: np.ndarray, g: np.ndarray) -> np.ndarray:
        """u₁ = Π w + N g + u_f, cell-major (n_cells, 6)."""
        out = np.zeros((self.ops.num_cells, 6))
        d = self.data(g)
        for K in self._here():
            cells = self.dofs.cells[K]
            out[cells] = self.aux.modes[K] @ w[self.aux.offsets[K] : self.aux.offsets[K + 1]]
            if self._reach_c[K]:
                out[cells] += self._combine(K, None, d, "u").reshape(-1, 6)
        return self._summed(out)

    def fine_displacement_post(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """Post-processed fine displacement Σ r_j q_j + N g + u_f (cell-major (n_cells, 6)).

        q_j is the displacement part of the Stage II problem of ψ_j (Ãψ_j + Bᵀq_j = 0), so
        σ₁ = Ψ r + Q g + σ_f and this u satisfy the discrete constitutive law (Aσ₁, τ) + (div τ, u) +
        β∫_γ(σ₁n₁)·(τn₁) = ∫_{γ}g·(τn₁) for τ in every local space; unlike u₁ = Π w + N g + u_f
        (coarse, in U_aux) it resolves the fine scales.
        """
        out = np.zeros((self.ops.num_cells, 6))
        d = self.data(g)
        for K in self._here():
            out[self.dofs.cells[K]] = self._combine(K, r, d, "u").reshape(-1, 6)
        return self._summed(out)

    @property
    def lifting(self) -> np.ndarray | None:
        """The traction lifting s₀ (n_cells, 30), cell-major: the stress is ``fine_stress`` + s₀ (None: no
        tractions)."""
        return self.ops.s0

    def a_norm2(self, sigma: np.ndarray) -> float:
        """(Aσ, σ) of a cell-major stress."""
        return float(np.einsum("ca,cab,cb->", sigma, self.ops.K, sigma))

    def m_norm2(self, u: np.ndarray) -> float:
        """‖u‖²_L² of a cell-major displacement."""
        return float(np.einsum("ca,cab,cb->", u, self.ops.M, u))

    def project(self, u: np.ndarray) -> np.ndarray:
        """π u = Π Πᵀ S u (cell-major)."""
        out = np.zeros_like(u)
        for k in range(self.grid.size):
            cells = np.sort(self.grid.cells[k].astype(np.int64))
            p = self.aux.modes[k]
            Su = np.einsum("cab,cb->ca", self.ops.S[cells], u[cells])
            out[cells] = p @ np.einsum("cak,ca->k", p, Su)
        return out
