"""Algorithm 4: mixed CEM-GMsFEM in Ω₁, mixed FEM with penalty contact in Ω₂ (the docs' theory page).

    Ω₁ (multiscale, linear): (r, w) ∈ X_ms × U_aux, with the Robin correctors (Q g₁₂, N g₁₂) and the
    source correctors (σ_f, u_f) (zero with ``source_correction=False``, the paper's algorithm),
        (Ar, τ) + (div τ, w) + β∫_γ (rn₁)·(τn₁) = ∫_γ g₁₂·(τn₁) − [(A(Qg₁₂ + σ_f), τ) + (div τ, Ng₁₂ + u_f)
                                                   + β∫_γ ((Qg₁₂ + σ_f)n₁)·(τn₁)]
        −(div r, v) = (f, v) + (div (Qg₁₂ + σ_f), v);     σ₁ = r + Q g₁₂ + σ_f,  u₁ = w + N g₁₂ + u_f
    Ω₂ (fine, nonlinear): as in Algorithm 2 (``fem.mixed.MixedSubproblem``, globalized semismooth Newton)
    update:  g₁₂ ← g₂₁ − 2β σ₂n₂,   g₂₁ ← g₁₂ − 2β σ₁n₁

**Boundary conditions on Ω₁**: those of the fine mixed method (``fem.mixed.boundary_stress_space``).
Every exterior facet of Ω₁ that is not Γ_D or γ (untagged: traction free; Γ_N groups) carries the essential
condition τn = 0 in every local stress space (``essential_traction_facets``); a traction σn = t is the lifting
s₀ of the fine Ω₁ subproblem (σ₁ = r + Q g₁₂ + σ_f + s₀), whose effect −(A s₀, τ) − β∫_γ(s₀n)·(τn),
−(div s₀, v) is a load, and u_D on Γ_D is the stress-side load ∫_ΓD u_D·(τn): both enter the source correctors
(so the error still falls with m) and the coarse right-hand side.  Γ_C facets on Ω₁ are refused (InputError).

The Robin data and the Ω₂ side are exactly those of ``hybrid.mixed`` (the
normal-trace space of AW on γ: values at the γ nodes, one traction per side where γ
bends, ``fem.mixed_interface.GammaBends``); the step subclasses
``MixedHybridStep`` and replaces its Ω₁ solve by the coarse solve of
``multiscale.mixed_cem.MixedMultiscaleOmega1``.  The multiscale normal trace σ₁n₁
can jump at the coarse nodes of γ (the local spaces leave σ_tt free on inner
patch boundaries); the update uses the average of the two one-sided values
there, and at a bend the two sides' values projected onto the data space there.

Ω₁ is linear, so its coarse state is an affine function of g₁₂, precomputed
offline with one coarse solve per interface value
(``multiscale.mixed_cem.InterfaceResponse``).  Online, the Ω₁ side costs a few
matrix–vector products of the size of the interface data (trace, and the
stopping rule's norms from Gram matrices in g); σ₁ and u₁ are formed on the
fine mesh only at the end (output and errors).  MPI: every rank holds the whole mesh,
the offline local problems are shared out (``offline_comm``), the online phase runs
replicated.

**Displacement errors.**  u₁ = Π w + N g is, as in the paper's algorithm, a coarse
displacement (U_aux holds l functions per coarse cell, the rigid motions on interior
cells), so e_u over Ω₁ ∪ Ω₂ levels off at the best-approximation error of u_h in
U_aux (≈ 6e−2 at h = 1/64, H = 1/16, l = 3).  Two further measures are reported:
``e_u_projected`` (the Ω₁ part as ‖π(u_h − u₁)‖) and ``e_u_post`` with the fine
displacement Σ r_j q_j + N g + u_f assembled from the Stage II displacement parts q_j (it
satisfies the discrete constitutive law with σ₁ in every local space and follows e_σ).
"""

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import MixedSolution
from fenics_contact.fem.mixed_contact import MixedContactProfile
from fenics_contact.fem.mixed_spaces import boundary_stress_space
from fenics_contact.hybrid.certificate import mixed_certificate, relative
from fenics_contact.hybrid.inputs import check_reference_mixed, check_solve_inputs, require_instance
from fenics_contact.hybrid.iteration import (
    InterfaceNewtonOptions,
    IterationHistory,
    IterationOptions,
    IterationResult,
    iterate,
)
from fenics_contact.hybrid.mixed import DEFAULT_BETA, MixedHybridStep, solve_or_verify
from fenics_contact.hybrid.primal import omega2_record
from fenics_contact.hybrid.response import MatrixResponse
from fenics_contact.multiscale.cem.options import warn_if_few_layers
from fenics_contact.multiscale.coarse import coarse_grid
from fenics_contact.multiscale.mixed_cem.omega1 import MixedMultiscaleOmega1
from fenics_contact.multiscale.mixed_cem.options import MixedCEMOptions
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary

__all__ = ["MixedMsResult", "MixedMultiscaleHybridStep", "solve_mixed_ms_hybrid"]

log = logging.getLogger(__name__)


def essential_traction_facets(msh, facet_tags) -> np.ndarray:
    """Facets of Ω₁ where the stress space imposes τn = 0: every exterior facet that is not Γ_D or γ (the untagged,
    traction-free sides and the Γ_N groups; as ``fem.mixed.boundary_stress_space``).  Γ_C on Ω₁ is refused: the local
    spaces impose τn = 0 or nothing, not τn·t = 0 alone."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    if facet_tags.find(Boundary.GAMMA_C).size:
        raise InputError(
            "Algorithm 4 needs Γ_C inside Ω₂ (the fine strip): Ω₁ has Gamma_C facets; move γ so that the "
            "contact boundary lies in Ω₂, or use Algorithm 2"
        )
    exterior = dmesh.exterior_facet_indices(msh.topology)
    natural = np.concatenate([facet_tags.find(Boundary.GAMMA_D), facet_tags.find(Boundary.INTERFACE)])
    return np.setdiff1d(exterior, natural).astype(np.int64)


def _require_replicated_mesh(cm: ContactMesh, offline_comm: MPI.Comm) -> None:
    """The Arnold–Winther spaces are serial: every rank holds the whole mesh (``cm`` on COMM_SELF)."""
    if cm.comm.size > 1:
        raise InputError(
            f"Algorithm 4 needs the whole mesh on every rank (the Arnold–Winther space is serial); got a mesh "
            f"distributed over {cm.comm.size} ranks. Build it on MPI.COMM_SELF on each rank (e.g. "
            "geometry.unit_square(n, n_coarse, comm=MPI.COMM_SELF)) and pass offline_comm=MPI.COMM_WORLD: the "
            "offline local problems are then shared out over the ranks."
        )


class MixedMultiscaleHybridStep(MixedHybridStep):
    """The transmission map T of Algorithm 4 (``hybrid.iteration.HybridStep`` protocol)."""

    omega1_operators = False  # Ω₁ is solved in the multiscale space: no fine Ω₁ matrices

    def __init__(
        self,
        problem: ContactProblem,
        *,
        beta: float | str = DEFAULT_BETA,
        epsilon: float | None = None,
        cem: MixedCEMOptions = MixedCEMOptions(),
        newton: NewtonOptions = NewtonOptions(),
        cache_dir: str | Path | None = None,
        offline_comm: MPI.Comm = MPI.COMM_SELF,
    ) -> None:
        cm = problem.cm
        _require_replicated_mesh(cm, offline_comm)
        if cm.H is None and not np.any(np.asarray(cm.coarse_cell) >= 0):
            raise InputError(
                "Algorithm 4 needs a coarse grid: build the mesh with geometry.unit_square(n, n_coarse), "
                "give read_mesh H or a mesh with a coarse partition, or set cm.coarse_cell (e.g. "
                "problem.partition.centroid_coarse_cells on an unstructured mesh)"
            )
        start = time.perf_counter()
        self._offline_comm = offline_comm  # (before the base class builds Ω₁'s space: ``_omega1_space``)
        super().__init__(problem, beta=beta, epsilon=epsilon, newton=newton)
        setup = time.perf_counter() - start
        part = self.parts[0]
        grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
        self.cem = cem
        warn_if_few_layers(cem.layers, "mixed CEM (Algorithm 4)", offline_comm)
        # the boundary conditions of the fine mixed method on Ω₁: σn = 0 (traction free) and σn = t
        # (Γ_N, homogeneous part + the lifting s₀) essential in every local space, u_D and the lifting as loads
        self.omega1 = MixedMultiscaleOmega1(
            self.sub[0],
            grid,
            cem,
            H=grid.H,
            cache_dir=cache_dir,
            comm=offline_comm,
            traction_free_facets=essential_traction_facets(part.mesh, part.facet_tags),
        )
        # the fine Ω₁ AW prolongation (1 GB at h = 1/256) is never made here (omega1.ops reads its cell blocks);
        # drop it should anything have made it
        self.sub[0].space.release_prolongation()
        co = self.omega1.co
        if co.n_g != self.size:
            raise RuntimeError("the multiscale interface data do not match the Ω₂ interface data")
        self.g12 = np.zeros(co.n_g)
        self._prev_g12: np.ndarray | None = None  # no Ω₁ state yet: the first change is measured from zero
        self.offline_times = {"setup": setup, **self.omega1.times}
        self.time_offline_s = time.perf_counter() - start

    def _omega1_space(self, part, fields):
        """Ω₁'s AW space with its cells' nodal bases shared out over ``offline_comm`` (each rank holds the whole
        Ω₁: without this every rank computed all of them, 1–1.5 s at h = 1/128)."""
        return boundary_stress_space(part.mesh, part.facet_tags, fields.boundary, basis_comm=self._offline_comm)

    # -- reference and errors ------------------------------------------------------------
    def set_reference(self, reference: MixedSolution) -> None:
        """σ_h, u_h on Ω₁ as cell-major DG values (``omega1.ops``), on Ω₂ as in Algorithm 2."""
        ops = self.omega1.ops
        d1, u1 = self._part_reference(0, reference, dg=True)
        self._sref1 = d1[ops.dg_rows]
        self._uref1 = u1[ops.u_rows]
        c2, u2 = self._part_reference(1, reference)
        self.reference = [None, (c2, u2)]  # Ω₁ has no fine AW problem here (omega1_operators = False)
        s2 = self.sub[1]
        self._ref_norm2 = (
            self.omega1.a_norm2(self._sref1) + s2.stress_norm2(c2),
            self.omega1.m_norm2(self._uref1) + s2.l2_norm2(u2),
        )

    def fine_omega1(self) -> tuple[np.ndarray, np.ndarray]:
        """σ₁ (n_cells, 30) and u₁ (n_cells, 6) of the current iterate, cell-major (``multiscale.mixed_cem``).

        Kept for the current g₁₂ (collective when the patch functions are distributed over ranks, so that the
        errors of a rank holding a reference then need no other rank: ``fine_fields``)."""
        return self._fine(
            "fields", lambda r, w: (self.omega1.fine_stress(r, self.g12), self.omega1.fine_displacement(w, self.g12))
        )

    def fine_displacement_post(self) -> np.ndarray:
        """The post-processed fine Ω₁ displacement of the current iterate (kept like ``fine_omega1``)."""
        return self._fine("post", lambda r, w: self.omega1.fine_displacement_post(r, self.g12))

    def _fine(self, what: str, make):
        kept = self.__dict__.setdefault("_fine_kept", {})
        key = self.g12.tobytes()
        if what not in kept or kept[what][0] != key:
            kept[what] = (key, make(*self.omega1.solve(self.g12)))
        return kept[what][1]

    def fine_fields(self, errors: bool) -> None:
        """Collective over the offline ranks when the patch functions are distributed: form (and keep) the
        fine Ω₁ fields every rank needs, and those the errors need if any rank holds a reference (``errors``)."""
        om = self.omega1
        if om.distributed and om.comm.allreduce(bool(errors), op=MPI.LOR):
            self.fine_omega1()
            self.fine_displacement_post()

    def errors(self) -> tuple[float, float]:
        """(e_σ, e_u) against the fine monolithic reference over Ω₁ ∪ Ω₂."""
        if self.reference is None:
            raise InputError("no reference solution was given")
        s1, u1 = self.fine_omega1()
        s2 = self.sub[1]
        c2, v2 = self.reference[1]
        es = self.omega1.a_norm2(s1 - self._sref1) + s2.stress_norm2(s2.c - c2)
        eu = self.omega1.m_norm2(u1 - self._uref1) + s2.l2_norm2(s2.u - v2)
        return float(np.sqrt(relative(es, self._ref_norm2[0]))), float(np.sqrt(relative(eu, self._ref_norm2[1])))

    def projected_displacement_error(self) -> float:
        """‖π(u_h − u₁)‖_Ω₁ ⊕ ‖u_h − u₂‖_Ω₂ relative to ‖u_h‖: e_u with the Ω₁ part seen through π.

        u₁ = Π w + N g lives in the coarse space U_aux (+ the correction), so e_u over Ω₁ is
        bounded below by the best approximation of u_h in U_aux (a few percent with l = 3); the
        projected error measures the coarse displacement the method actually computes.
        """
        if self.reference is None:
            raise InputError("no reference solution was given")
        _, u1 = self.fine_omega1()
        s2 = self.sub[1]
        eu = self.omega1.m_norm2(self.omega1.project(u1 - self._uref1)) + s2.l2_norm2(s2.u - self.reference[1][1])
        return float(np.sqrt(relative(eu, self._ref_norm2[1])))

    def postprocessed_displacement_error(self) -> float:
        """e_u with the post-processed fine Ω₁ displacement Σ r_j q_j + N g (``fine_displacement_post``)."""
        if self.reference is None:
            raise InputError("no reference solution was given")
        u1 = self.fine_displacement_post()
        s2 = self.sub[1]
        eu = self.omega1.m_norm2(u1 - self._uref1) + s2.l2_norm2(s2.u - self.reference[1][1])
        return float(np.sqrt(relative(eu, self._ref_norm2[1])))

    # -- HybridStep protocol -------------------------------------------------------------
    def prepare(self) -> None:
        """Nothing to do: the coarse operator was factorized offline."""

    def apply(self, g: np.ndarray, *, omega2_warm: bool = False) -> np.ndarray:
        n = self.size
        g12, g21 = g[:n], g[n:]
        self.g12 = g12.copy()  # Ω₁ is linear: its state is the affine response to g12
        newton = solve_or_verify(self.sub[1], g21[self._perm2], omega2_warm)
        t1 = self.omega1.response.trace(g12)
        t2 = np.empty(n)
        t2[self._perm2] = self.sub[1].gamma_traction()
        self._measure()
        self._certificate = mixed_certificate(t1, t2, g12, g21, self.beta, self.gamma_mass)
        self._record = omega2_record(newton)
        return np.concatenate([g21 - 2.0 * self.beta * t2, g12 - 2.0 * self.beta * t1])

    def reset(self) -> None:
        super().reset()
        self.g12[:] = 0.0
        self._prev_g12[:] = 0.0

    def _omega1_response(self, options: InterfaceNewtonOptions):
        """Ω₁'s affine trace σ₁n₁ = T g + t₀ (``InterfaceResponse``, precomputed offline with the bases)."""
        rs = self.omega1.response
        return MatrixResponse(rs.T, rs.t0)

    def _measure(self) -> None:
        rs = self.omega1.response
        ns = rs.stress_norm2(self.g12)
        nu = rs.l2_norm2(self.g12)
        if self._prev_g12 is None:  # the state before the first step is zero (as in Algorithm 2), not σ₁(0)
            ds, du = ns, nu
        else:
            ds = rs.stress_change2(self.g12, self._prev_g12)
            du = rs.l2_change2(self.g12, self._prev_g12)
        self._prev_g12 = self.g12.copy()
        s = self.sub[1]
        c0, u0 = self._prev[1]
        ds += s.stress_norm2(s.c - c0)
        du += s.l2_norm2(s.u - u0)
        ns += s.stress_norm2(s.c)
        nu += s.l2_norm2(s.u)
        c0[:] = s.c
        u0[:] = s.u
        self._change = max(np.sqrt(ds / ns), np.sqrt(du / nu)) if ns > 0 and nu > 0 else np.inf

    # -- output ----------------------------------------------------------------------------
    def part_values(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The multiscale σ₁ (with the traction lifting), u₁ = Π w + N g on Ω₁ and the fine σ₂, u₂ on Ω₂ (sub
        numbering)."""
        ops = self.omega1.ops
        s1, u1 = self.fine_omega1()
        sig_sub = np.zeros(3 * self.sub[0].dg.dofmap.index_map.size_local)
        sig_sub[ops.dg_rows.ravel()] = s1.ravel()
        if self.omega1.lifting is not None:  # the traction lifting s₀ (σ₁ = homogeneous part + s₀)
            sig_sub[ops.dg_rows.ravel()] += self.omega1.lifting.ravel()
        u_sub = np.zeros(self.sub[0].n_u)
        u_sub[ops.u_rows.ravel()] = u1.ravel()
        return [(sig_sub, u_sub), (self.sub[1].sigma_function().x.array, self.sub[1].u)]


def l2_stress_error(sigma: fem.Function, reference: fem.Function) -> float:
    """‖σ_h − σ‖_L² / ‖σ_h‖_L² of two stresses (σ_xx, σ_xy, σ_yy) on the same mesh (σ_xy counted twice)."""
    s = fem.Function(reference.function_space)
    s.interpolate(sigma)
    d = forms_mixed.stress_tensor(s - reference)
    r = forms_mixed.stress_tensor(reference)
    comm = reference.function_space.mesh.comm
    num = comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(d, d) * ufl.dx)))
    den = comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(r, r) * ufl.dx)))
    return float(np.sqrt(relative(num, den)))


@dataclass(slots=True)
class MixedMsResult(IterationResult):
    """Fields, history, DOF counts, timings and errors of an Algorithm 4 solve."""

    sigma: fem.Function  #: DG P3 (σ_xx, σ_xy, σ_yy) on the parent mesh
    u: fem.Function  #: DG P1 on the parent mesh
    history: IterationHistory
    profile: MixedContactProfile
    dofs: dict
    time_offline_s: float
    time_online_s: float
    offline_times: dict
    e_sigma: float | None
    e_u: float | None
    e_u_projected: float | None  #: e_u with the Ω₁ part measured as ‖π(u_h − u₁)‖
    e_u_post: float | None  #: e_u with the post-processed fine Ω₁ displacement Σ r_j q_j + N g
    e_sigma_l2: float | None  #: ‖σ_h − σⁿ‖_L²/‖σ_h‖_L² (for ν → ½ the A-norm sees mostly the deviatoric part)
    beta: float
    epsilon: float
    layers: int
    nbasis: int | None
    step: MixedMultiscaleHybridStep
    time_interface_offline_s: float = 0.0  #: offline interface response of the Newton method (in time_offline_s)


def solve_mixed_ms_hybrid(
    problem: ContactProblem,
    *,
    beta: float | str = DEFAULT_BETA,
    epsilon: float | None = None,
    cem: MixedCEMOptions = MixedCEMOptions(),
    offline_comm: MPI.Comm = MPI.COMM_SELF,
    options: IterationOptions = IterationOptions(),
    newton: NewtonOptions = NewtonOptions(),
    reference: MixedSolution | None = None,
    cache_dir: str | Path | None = None,
    initial_data: np.ndarray | None = None,
    step: MixedMultiscaleHybridStep | None = None,
) -> MixedMsResult:
    """Algorithm 4 until the transmission residual is below ``options.tol``; e_σ, e_u against ``reference``
    (fine monolithic mixed), outside the online time.  ``initial_data`` warm-starts the interface data,
    ``step`` reuses a step (and its offline data) from an earlier solve.

    ``epsilon`` defaults to the reference's ε (else ``fem.mixed.default_epsilon``).  ``dofs`` counts
    the fine Ω₁ problem, dim X_ms, dim U_aux, Ω₂ and the interface data; ``time_offline_s``
    covers the subproblem set-up, Stage I, Stage II, the correction and the coarse
    factorization (``offline_times``); ``time_online_s`` the iteration.  With ``cache_dir`` the
    offline data are stored there and reused when the configuration matches
    (``multiscale.mixed_cem.MixedOfflineCache``; ``step.omega1.cache_status``).  ``nbasis`` is the least
    number of Stage I modes per coarse cell; ``min_gap`` adds modes where the first eigenvalue left
    out is below it (up to ``max_nbasis``; ``None`` keeps exactly ``nbasis``, the paper's fixed l).
    ``source_correction`` (default) adds the localized source correctors (the error then
    falls with m for loads inside Ω₁ too); ``False`` is the paper's Algorithm 4. These are the fields of
    ``cem`` (``multiscale.mixed_cem.MixedCEMOptions``).

    MPI: the Arnold–Winther spaces are serial, so every rank holds the whole mesh (``cm`` built on
    COMM_SELF) and ``offline_comm`` (e.g. COMM_WORLD) shares out the offline local problems (Stage I
    cells, Stage II patches, coarse-operator cells; each computed once, results broadcast, coarse
    matrices summed).  The online iteration then runs replicated on every rank (identical results,
    no communication; the Ω₂ solves are serial anyway).
    """
    check_solve_inputs(problem, options=options, newton=newton)
    require_instance(cem, MixedCEMOptions, "cem", " (multiscale.mixed_cem.MixedCEMOptions)")
    if reference is not None:
        check_reference_mixed(reference, problem.cm)
    if reference is not None and epsilon is None:
        epsilon = reference.epsilon
    if step is None:
        step = MixedMultiscaleHybridStep(
            problem, beta=beta, epsilon=epsilon, cem=cem, newton=newton, cache_dir=cache_dir, offline_comm=offline_comm
        )
    layers, nbasis = step.cem.layers, step.cem.nbasis
    if reference is not None:  # not part of the method: outside the timings
        step.set_reference(reference)
    history = iterate(step, options, name=f"mixed CEM hybrid (m={layers}, l={nbasis})", initial=initial_data)
    step.fine_fields(errors=step.reference is not None)  # (collective when Ω₁'s functions are distributed)
    sigma, u = step.glued()
    co = step.omega1.co
    dofs = {
        "omega1": step.sub[0].num_dofs["total"],
        "omega1_ms": co.n_ms + co.n_aux,
        "X_ms": co.n_ms,
        "U_aux": co.n_aux,
        "omega2": step.sub[1].num_dofs["total"],
        "interface": 2 * step.size,
    }
    has_ref = step.reference is not None
    e_sigma, e_u = step.errors() if has_ref else (None, None)
    e_u_pi = step.projected_displacement_error() if has_ref else None
    e_u_post = step.postprocessed_displacement_error() if has_ref else None
    e_sigma_l2 = l2_stress_error(sigma, reference.sigma) if reference is not None else None
    log.info(
        "Algorithm 4 (m=%d, l=%s): %d iterations (converged %s), dim X_ms %d + U_aux %d, offline %.2f s, "
        "online %.2f s, e_σ %s, e_u %s",
        layers,
        nbasis,
        history.iterations,
        history.converged,
        co.n_ms,
        co.n_aux,
        step.time_offline_s,
        history.time_s,
        e_sigma,
        e_u,
    )
    offline_times = dict(step.offline_times)
    if history.time_offline_s:
        offline_times["interface_response"] = history.time_offline_s
    return MixedMsResult(
        sigma,
        u,
        history,
        step.sub[1].contact_profile(),
        dofs,
        step.time_offline_s + history.time_offline_s,
        history.time_s,
        offline_times,
        e_sigma,
        e_u,
        e_u_pi,
        e_u_post,
        e_sigma_l2,
        step.beta,
        step.epsilon,
        layers,
        nbasis,
        step,
        history.time_offline_s,
    )
