"""The Ω₁ side of Algorithm 3: ``Omega1Multiscale`` (fine operators, coarse grid, V_ms, the online solver).

Everything lives on a serial copy of Ω₁ (``multiscale.replica.SerialReplica``), the same on every rank; the
offline local problems are shared out over the ranks, and every rank solves the small dense coarse problem
itself.
"""

import logging
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.hybrid.transmission import InterfaceSpace, Part, robin_coefficient, split_mesh
from fenics_contact.multiscale.cem.cache import offline_stage
from fenics_contact.multiscale.cem.coarse import MultiscaleRobinSolver
from fenics_contact.multiscale.cem.operators import assemble_fine_operators, omega1_load
from fenics_contact.multiscale.cem.options import NEARLY_INCOMPRESSIBLE, CEMOptions, warn_if_few_layers
from fenics_contact.multiscale.coarse import grid_from_cells
from fenics_contact.multiscale.replica import SerialReplica
from fenics_contact.problem.problem import ContactProblem

__all__ = ["Omega1Multiscale", "build_omega1_multiscale"]

log = logging.getLogger(__name__)


def _allgather_values(comm: MPI.Comm, local: np.ndarray) -> np.ndarray:
    """The owned interface values of every rank, concatenated in rank order (= global interface order)."""
    local = np.ascontiguousarray(local, dtype=np.float64)
    if comm.size == 1:
        return local
    counts = np.array(comm.allgather(local.size), dtype=np.int64)
    out = np.empty(int(counts.sum()))
    comm.Allgatherv(local, [out, (counts, np.concatenate([[0], np.cumsum(counts)[:-1]]))])
    return out


class Omega1Multiscale:
    """The Ω₁ side of Algorithm 3: fine operators, coarse grid, multiscale space and the online solver.

    Everything lives on a serial copy of Ω₁ (``replica.SerialReplica``), the same on every rank;
    the offline local problems are shared out across the ranks of ``cm.comm``. Online, every rank
    solves the (small, dense) coarse problem itself: ``solve`` gathers the owned Robin data of all
    ranks (one Allgather of the γ values) and returns u₁ on every DOF of the copy;
    ``interface_values`` gives back this rank's owned γ values.
    """

    def __init__(
        self,
        problem: ContactProblem,
        parts: tuple[Part, Part],
        interface: InterfaceSpace,
        alpha: np.ndarray,
        *,
        cem: CEMOptions,
        cache_dir: str | Path | None = None,
    ) -> None:
        t0 = time.perf_counter()
        cm = problem.cm
        comm = cm.comm
        self.comm = comm
        part = parts[0]
        self.interface = interface
        tdim = part.mesh.topology.dim
        imap = part.mesh.topology.index_map(tdim)
        sub_cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        parent_cells = np.asarray(part.cell_map.sub_topology_to_topology(sub_cells, False), dtype=np.int64)
        coarse = np.asarray(cm.coarse_cell)[parent_cells]
        if cm.H is None and comm.allreduce(int(np.any(coarse >= 0)), op=MPI.MAX) == 0:
            raise InputError(
                "the mesh has no coarse grid (ContactMesh.H is None and no coarse partition): build it with "
                "geometry.unit_square(n, n_coarse), or give read_mesh H or a mesh with a coarse partition"
            )
        self.replica = SerialReplica(part.mesh, part.facet_tags, interface.spaces[0], {"coarse": coarse})
        self.mesh = self.replica.mesh
        self.facet_tags = self.replica.facet_tags
        self.V = self.replica.V
        self.fields = problem.fields_on(self.mesh)
        self.grid = grid_from_cells(
            self.mesh.geometry.dofmaps[0], self.mesh.geometry.x, self.replica.cell_data["coarse"], cm.H
        )
        # global interface value index (rank order) of every γ DOF of the copy
        self._n_local = interface.size
        self._offset = comm.exscan(self._n_local) or 0
        self._n_total = comm.allreduce(self._n_local, op=MPI.SUM)
        probe = fem.Function(interface.spaces[0])
        interface.to_part(self._offset + np.arange(1, self._n_local + 1, dtype=np.float64), 0, probe)
        index = np.rint(self.replica.gather(probe)).astype(np.int64) - 1
        self.alpha_fn = fem.Function(self.V, name="alpha")
        on = np.flatnonzero(index >= 0)
        self.alpha_fn.x.array[on] = _allgather_values(comm, alpha)[index[on]]
        self._fine_factor = None  # the fine Ω₁ operator's factorization, made by the first fine_check
        self.ops = assemble_fine_operators(
            self.V,
            self.facet_tags,
            self.fields,
            self.alpha_fn,
            self.grid,
            s_factor=cem.s_factor,
            load=omega1_load(self.V, self.facet_tags, self.fields),
            displacement=self.fields.boundary.displacement,
        )
        value_of_dof = index[self.ops.gamma]
        if (
            np.any(value_of_dof < 0)
            or np.unique(value_of_dof).size != self._n_total
            or self.ops.gamma.size != self._n_total
        ):
            raise InputError("the Ω₁ γ DOFs do not match the interface DOFs one to one")
        self.value_of_dof = value_of_dof  #: global interface index of each ops.gamma DOF
        self.gamma_of_value = np.empty(self._n_total, dtype=np.int64)  #: position in ops.gamma of each value
        self.gamma_of_value[value_of_dof] = np.arange(self.ops.gamma.size)
        self._mine = self.gamma_of_value[self._offset : self._offset + self._n_local]
        t_assembly = time.perf_counter() - t0
        self.space, self.cache_status = offline_stage(self.ops, self.grid, cem, h=cm.h, cache_dir=cache_dir, comm=comm)
        self.solver = MultiscaleRobinSolver(self.ops, self.space, self.grid, comm=comm)
        self._Zg_mine = self.solver.Zg[self._mine]  # the trace rows of this rank's values (one copy, not per step)
        t_reduce = time.perf_counter()
        T, self._GK_t, self._GM_t = self.solver.reduced()  # a step in the interface coordinates t = (g, 1)
        self._T_mine = np.ascontiguousarray(T[self._mine])
        t_reduce = time.perf_counter() - t_reduce
        self.nu_max = float(np.max(self.fields.nu.x.array, initial=0.0))  #: largest ν in Ω₁
        warn_if_few_layers(cem.layers, "primal CEM (Algorithm 3)", comm)
        if self.nu_max > NEARLY_INCOMPRESSIBLE and comm.rank == 0:
            log.warning(
                "primal CEM with ν up to %.4g in Ω₁ (Λ·c = %.2f, Λ the smallest local eigenvalue left out): the "
                "bases localize slowly as ν → ½ and the Ω₁ error at m = %d layers may be large (model 3 at E 1e6, "
                "h = 1/64, H = 1/16, m = 4: energy error 3.2e-3 at ν = 0.4, 2.9e-2 at 0.45, 0.30 at 0.48, 0.51 at "
                "0.49; P1 itself locks as ν → ½). Check against the fine solution (CLI: --reference); more layers "
                "help up to ν ≈ 0.48 (8.9e-2 "
                "at m = 5, 1.7e-2 at m = 6), not at ν = 0.499 (0.79 at m = 6); --method mixed-ms is robust in ν.",
                self.nu_max,
                self.spectral_gap * cem.s_factor,
                cem.layers,
            )
        self.times = {
            "assembly": t_assembly,
            "eigen": self.space.times.get("eigen", 0.0),
            "patches": self.space.times.get("patches", 0.0),
            "cache_load": self.space.times.get("load", 0.0),
            "cache_save": self.space.times.get("save", 0.0),
            "coarse": self.solver.time_s + self.space.times.get("gram", 0.0) + t_reduce,
        }
        #: parts of the above (not added again): the patch factorizations and solves (summed over the ranks), the
        #: Gram matrices
        self.time_parts = {
            "patch_factor": self.space.times.get("patch_factor", 0.0),
            "patch_solve": self.space.times.get("patch_solve", 0.0),
            "gram": self.space.times.get("gram", 0.0) + self.solver.time_gram,
        }

    @property
    def spectral_gap(self) -> float:
        """Λ = min over the coarse cells of the first local eigenvalue left out (inf when all are kept)."""
        return self.space.aux.spectral_gap

    @property
    def nbasis_range(self) -> tuple[int, int]:
        """(least, most) local modes kept on a coarse cell."""
        counts = np.diff(self.space.aux.offsets)
        return int(counts.min()), int(counts.max())

    @property
    def num_coarse_dofs(self) -> int:
        """dim V_ms."""
        return self.space.size

    @property
    def num_fine_dofs(self) -> int:
        """Scalar DOFs of the fine Ω₁ P1 space (Γ_D included, as PrimalSubproblem.num_dofs counts them)."""
        return self.ops.size

    def solve(self, g12: np.ndarray) -> np.ndarray:
        """u₁ on every DOF of the Ω₁ copy for Robin data g₁₂ (this rank's owned values, InterfaceSpace
        ordering; collective)."""
        return self.solver.field(self.coordinates(g12))

    def interface_values(self, u1: np.ndarray) -> np.ndarray:
        """u₁ at this rank's owned interface DOFs, in InterfaceSpace ordering."""
        return u1[self.ops.gamma[self._mine]]

    # -- online in coarse coordinates: u₁ = Z s, Z = [Ψ, N, N_f], s = (w, g, 1) ----------------------
    def coordinates(self, g12: np.ndarray) -> np.ndarray:
        """s with u₁ = Z s for Robin data g₁₂ (owned values; collective: one Allgather of the γ values).

        Costs one dense coarse solve; nothing of fine-mesh size.
        """
        g = _allgather_values(self.comm, g12)[self.value_of_dof]
        return self.solver.coordinates(g)

    def interface_coordinates(self, g12: np.ndarray) -> np.ndarray:
        """t = (g, 1), the Robin data of all ranks (``ops.gamma`` ordering) and the load's 1: u₁ = Z Q t
        (``MultiscaleRobinSolver.reduced``; collective: one Allgather of the γ values).  No solve: the coarse
        solution is an affine map of the data, applied only when a field is wanted (``expand``)."""
        return np.concatenate([_allgather_values(self.comm, g12)[self.value_of_dof], [1.0]])

    def expand(self, t: np.ndarray) -> np.ndarray:
        """s = Q t, the coordinates of u₁ = Z s, for interface coordinates t."""
        return self.solver.expand(t)

    def interface_trace(self, t: np.ndarray) -> np.ndarray:
        """u₁ at this rank's owned interface DOFs (InterfaceSpace ordering) for interface coordinates t."""
        return self._T_mine @ t

    def interface_norms2(self, t: np.ndarray) -> tuple:
        """(a₁(u₁, u₁), ‖u₁‖²_L²) of u₁ = Z Q t, t interface coordinates (or their differences); for the
        columns of a 2-D t, two arrays (one pass over each reduced Gram matrix)."""
        if t.ndim == 2:
            return np.einsum("ij,ij->j", t, self._GK_t @ t), np.einsum("ij,ij->j", t, self._GM_t @ t)
        return float(t @ (self._GK_t @ t)), float(t @ (self._GM_t @ t))

    def field(self, s: np.ndarray) -> np.ndarray:
        """u₁ = Z s on every DOF of the Ω₁ copy."""
        return self.solver.field(s)

    def trace(self, s: np.ndarray) -> np.ndarray:
        """u₁ = Z s at this rank's owned interface DOFs (InterfaceSpace ordering)."""
        return self._Zg_mine @ s

    def coordinate_norms2(self, s: np.ndarray) -> tuple:
        """(a₁(Zs, Zs), ‖Zs‖²_L²) from the Gram matrices (s may be a difference of coordinates); for the columns
        of a 2-D s, two arrays (one pass over each Gram matrix for all columns)."""
        if s.ndim == 2:
            GK, GM = self.solver.GK, self.solver.GM
            return np.einsum("ij,ij->j", s, GK @ s), np.einsum("ij,ij->j", s, GM @ s)
        return float(s @ (self.solver.GK @ s)), float(s @ (self.solver.GM @ s))

    def reference_terms(self, r1: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(ZᵀK r, ZᵀM r, a₁(r, r), ‖r‖²) of a fine Ω₁ field r, for ``error_norms2``."""
        Kr, Mr = self.ops.K @ r1, self.ops.M @ r1
        space = self.space
        n_ms, ng = space.size, space.n_gamma
        zk, zm = np.zeros(n_ms + ng + 1), np.zeros(n_ms + ng + 1)
        for parts, shift in ((space.basis, 0), (space.correction, n_ms)):
            for p in parts:
                zk[shift + p.columns] += p.values.T @ Kr[p.dofs]
                zm[shift + p.columns] += p.values.T @ Mr[p.dofs]
        if space.Nf is not None:
            zk[-1], zm[-1] = space.Nf @ Kr, space.Nf @ Mr
        return zk, zm, float(Kr @ r1), float(Mr @ r1)

    def error_norms2(self, s: np.ndarray, terms: tuple) -> tuple[float, float]:
        """(a₁(Zs − r, Zs − r), ‖Zs − r‖²) for ``terms = reference_terms(r)``."""
        zk, zm, rk, rm = terms
        ek, em = self.coordinate_norms2(s)
        return max(ek - 2.0 * (s @ zk) + rk, 0.0), max(em - 2.0 * (s @ zm) + rm, 0.0)

    def response(self) -> tuple[np.ndarray, np.ndarray]:
        """The affine interface map of Ω₁, u₁|γ = R g₁₂ + r₀.

        Rows: this rank's owned interface values (InterfaceSpace ordering); columns: the interface
        values of all ranks in rank order (serially: R is square, n_γ × n_γ, dense).
        ``interface_values(solve(g))`` equals ``R @ g_all + r0`` to round-off.
        """
        R, r0 = self.solver.response()
        return R[np.ix_(self._mine, self.gamma_of_value)], r0[self._mine]

    def from_parent(self, u: fem.Function) -> np.ndarray:
        """A parent-mesh P1 function restricted to Ω₁, as values on the copy (collective)."""
        sub = fem.Function(self.interface.spaces[0])
        self.interface.transfers[0].to_sub(u, sub)
        return self.replica.gather(sub)

    def to_part(self, u1: np.ndarray, out: fem.Function) -> None:
        """out (P1 on the distributed Ω₁ submesh) ← u₁ given on the copy."""
        self.replica.scatter(u1, out)

    def fine_check(self, g12: np.ndarray) -> float:
        """‖u₁ − u₁,h‖_A / ‖u₁,h‖_A: the multiscale Ω₁ solution for the Robin data g₁₂ against the fine P1 solution
        of the same Ω₁ problem (A = a₁ + α∫_γ, its energy), by one sparse factorization of the fine operator (on
        rank 0, broadcast; collective; the factorization is kept for the next check: a load path factorizes
        once). The accuracy of Ω₁'s multiscale space for the run's own data: the
        certificate proves the fixed point of the multiscale problem, this its distance to the fine Ω₁ one."""
        g = _allgather_values(self.comm, g12)[self.value_of_dof]
        u_ms = self.solver.field(self.solver.coordinates(g))
        error = None
        if self.comm.rank == 0:
            ops = self.ops
            fixed = np.zeros(ops.size) if ops.lifting is None else ops.lifting
            rhs = ops.F + ops.G[:, ops.gamma] @ g - ops.A @ np.where(ops.free, 0.0, fixed)
            free = np.flatnonzero(ops.free)
            if self._fine_factor is None:  # Ω₁ is linear: one factorization serves every check of the run
                upper = sp.triu(ops.A[free][:, free], format="csr")
                upper.sort_indices()
                self._fine_factor = SparseFactor.symmetric(upper)
            u = np.where(ops.free, 0.0, fixed)
            u[free] = self._fine_factor.solve(rhs[free][:, None])[:, 0]
            d = u_ms - u
            norm2 = float(u @ (ops.A @ u))
            error = float(np.sqrt(max(d @ (ops.A @ d), 0.0) / norm2)) if norm2 > 0 else 0.0
        return self.comm.bcast(error, root=0)

    def energy_norm2(self, w: np.ndarray) -> float:
        """a₁(w, w) (the same on every rank)."""
        return float(self.ops.K.dot(w).dot(w))

    def l2_norm2(self, w: np.ndarray) -> float:
        """‖w‖²_L²(Ω₁) (the same on every rank)."""
        return float(self.ops.M.dot(w).dot(w))


def build_omega1_multiscale(
    problem: ContactProblem,
    *,
    alpha: float | str = "E",
    cem: CEMOptions = CEMOptions(),
    cache_dir: str | Path | None = None,
) -> tuple[Omega1Multiscale, InterfaceSpace, np.ndarray]:
    """The Ω₁ multiscale solver on its own (for linear Robin problems and tests): (Ω₁ solver, interface, α)."""
    cm = problem.cm
    parts = split_mesh(cm)
    interface = InterfaceSpace(cm, parts, shape=(cm.mesh.geometry.dim,))
    alpha_values = robin_coefficient(alpha, problem.fields.E, interface, cm.h, problem.length)
    omega1 = Omega1Multiscale(problem, parts, interface, alpha_values, cem=cem, cache_dir=cache_dir)
    return omega1, interface, alpha_values
