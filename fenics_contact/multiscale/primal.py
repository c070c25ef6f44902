"""Algorithm 3: CEM-GMsFEM in Ω₁, primal FEM with penalty contact in Ω₂ (the docs' theory page).

    Ω₁ (multiscale, linear): w ∈ V_ms,
        a₁(w, v) + α∫_γ w·v = (f, v)_Ω₁ + ∫_γ g₁₂·v − [a₁(N g₁₂, v) + α∫_γ N g₁₂·v],   u₁ = w + N g₁₂
    Ω₂ (fine, nonlinear): a₂(u₂, v) + (1/δ)∫_ΓC (u₂c)⁺ v_c + α∫_γ u₂·v = (f, v)_Ω₂ + ∫_γ g₂₁·v
    update at every γ node p:  g₁₂ ← 2α u₂(p) − g₂₁(p),  g₂₁ ← 2α u₁(p) − g₁₂(p)

Offline (``MultiscalePrimalHybridStep.__init__``): local spectral problems,
relaxed CEM bases, the Robin correction N and the factorized coarse matrix.
Online (``hybrid.iteration.iterate``): one coarse solve, one Ω₂ Newton solve and the update per
iteration. The fixed point is the CEM-GMsFEM/FEM hybrid solution, whose
difference to the fine monolithic solution is the multiscale error (it falls
with the oversampling layers m and the number of local modes).
"""

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.primal import PrimalSubproblem, penalty_for, warn_if_locking
from fenics_contact.hybrid.certificate import Certificate, primal_certificate, relative
from fenics_contact.hybrid.condensation import InterfaceProblem
from fenics_contact.hybrid.inputs import check_reference_displacement, check_solve_inputs, require_instance
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions, iterate
from fenics_contact.hybrid.options import interface_options
from fenics_contact.hybrid.primal import DEFAULT_ALPHA_MS, HybridResult, omega2_record, solve_or_verify
from fenics_contact.hybrid.response import MatrixResponse, PrimalPart
from fenics_contact.hybrid.transmission import InterfaceSpace, part_rollers, robin_coefficient, split_mesh
from fenics_contact.multiscale.cem.omega1 import Omega1Multiscale
from fenics_contact.multiscale.cem.options import CEMOptions
from fenics_contact.problem.friction import friction_of
from fenics_contact.problem.problem import ContactProblem

__all__ = ["OMEGA1_CHECK_WARN", "MultiscalePrimalHybridStep", "solve_primal_ms_hybrid"]

#: Algorithm 3 warns when its multiscale Ω₁ is this far (relative, energy norm) from the fine Ω₁ solve for the
#: run's own interface data (``Omega1Multiscale.fine_check``, which tracks the energy error of the coupled
#: solution: model 3 at h = 1/32, H = 1/8, m = 1…4: 0.27, 2.1e-2, 1.9e-3, 2.3e-4 against 0.28, 2.2e-2, 2.0e-3,
#: 2.5e-4)
OMEGA1_CHECK_WARN = 1e-2

log = logging.getLogger(__name__)


class MultiscalePrimalHybridStep:
    """The transmission map T of Algorithm 3 (``hybrid.iteration.HybridStep`` protocol)."""

    def __init__(
        self,
        problem: ContactProblem,
        *,
        alpha: float | str = DEFAULT_ALPHA_MS,
        delta: float | None = None,
        cem: CEMOptions = CEMOptions(),
        newton: NewtonOptions = NewtonOptions(),
        reference: fem.Function | None = None,
        cache_dir: str | Path | None = None,
    ) -> None:
        cm = problem.cm
        if cm.H is None and cm.comm.allreduce(int(np.any(np.asarray(cm.coarse_cell) >= 0)), op=MPI.MAX) == 0:
            raise InputError(
                "Algorithm 3 needs a coarse grid: build the mesh with geometry.unit_square(n, n_coarse) or "
                "meshes3d.unit_cube(n, H=…), or give read_mesh H or a mesh with a coarse partition"
            )
        start = time.perf_counter()
        self.comm = cm.comm
        self.parts = split_mesh(cm)
        # the Ω₁ CEM space takes clamped and traction-free sides, Γ_N tractions (a load functional,
        # source-corrected like f: cem.omega1_load) and a prescribed u_D (its lifting: cem.assemble_fine_operators)
        gdim = cm.mesh.geometry.dim
        self.interface = InterfaceSpace(cm, self.parts, shape=(gdim,))
        parent_fields = problem.fields
        warn_if_locking(parent_fields.nu, cm.comm)
        self.alpha = robin_coefficient(alpha, parent_fields.E, self.interface, cm.h, problem.length)
        self.delta = delta = penalty_for(problem, delta)
        self.cem = cem = cem.for_dimension(gdim)  # l resolved (RIGID_MOTIONS: 3 in 2D, 6 in 3D)
        p2 = self.parts[1]
        fields2 = problem.fields_on(p2.mesh)
        rollers = problem.boundary.rollers
        if rollers:  # each part takes the roller planes on its own outer boundary (Ω₁: cem.roller_dofs)
            own = [part_rollers(part, rollers) for part in self.parts]  # (refuses a plane through γ)
            lost = [plane for plane in rollers if plane not in own[0] + own[1]]
            if lost:
                raise InputError(f"no exterior facet lies in the roller plane(s) x_axis = value {lost}")
            fields2 = fields2._replace(boundary=dataclasses.replace(problem.boundary, rollers=own[1]))
        self.omega1 = Omega1Multiscale(problem, self.parts, self.interface, self.alpha, cem=cem, cache_dir=cache_dir)
        alpha2 = fem.Function(self.interface.spaces[1], name="alpha")
        self.interface.to_part(self.alpha, 1, alpha2)
        self.omega2 = PrimalSubproblem(
            p2.mesh,
            p2.facet_tags,
            fields2,
            delta=delta,
            alpha=alpha2,
            prefix="fc_primal_ms_omega2_",
            newton=newton,
            V=self.interface.spaces[1],
            friction=friction_of(problem.law),
        )
        self.u1 = fem.Function(self.interface.spaces[0], name="u1")  # filled by glued()
        # u₁ in the interface coordinates t = (g₁₂, 1) of Omega1Multiscale: its trace and norms are small dense
        # products (online nothing of fine-mesh size in Ω₁, no coarse solve: the coarse field only on request)
        self._t = np.zeros(self.omega1.solver.space.n_gamma + 1)
        self._prev = [self._t.copy(), np.zeros_like(self.omega2.u.x.array)]
        self._diff2 = fem.Function(self.omega2.V)
        self._products: list | None = None  #: Ω₂'s [K u, M u, work, work] of the last state (``_measure``)
        self._change = np.inf
        self._certificate = Certificate(np.inf, np.inf)
        self._record: dict = {}
        self._newton = None
        self.reference = None
        if reference is not None:
            r1 = self.omega1.from_parent(reference)
            r2 = fem.Function(self.interface.spaces[1])
            self.interface.transfers[1].to_sub(reference, r2)
            self.reference = (r1, r2)
            self._ref_l2 = self.omega1.l2_norm2(r1) + self.omega2.l2_norm2(r2)
            self._ref_energy = self.omega1.energy_norm2(r1) + self.omega2.energy_norm2(r2)
        self.offline_times = dict(self.omega1.times)
        self.offline_times["setup"] = time.perf_counter() - start - sum(self.omega1.times.values())
        self.time_offline_s = time.perf_counter() - start

    @property
    def contact(self) -> PrimalSubproblem:
        """The subproblem holding Γ_C (Ω₂)."""
        return self.omega2

    def prepare(self) -> None:
        """Offline work: done on construction (bases, correctors, the coarse factorization)."""

    # -- HybridStep protocol --------------------------------------------------------------
    def initial_data(self) -> np.ndarray:
        return np.zeros(2 * self.interface.size)

    def apply(self, g: np.ndarray, *, omega2_warm: bool = False) -> np.ndarray:
        n = self.interface.size
        g12, g21 = g[:n], g[n:]
        self._t = self.omega1.interface_coordinates(g12)
        self.interface.to_part(g21, 1, self.omega2.g)
        newton = solve_or_verify(self.omega2, omega2_warm)
        u1g = self.omega1.interface_trace(self._t)
        u2g = self.interface.from_part(self.omega2.u, 1)
        self._measure(kept=omega2_warm)
        self._certificate = primal_certificate(u1g, u2g, g12, g21, self.alpha, self.interface.weights, self.comm)
        self._record = omega2_record(newton)  # e_u: the solve's monitor, outside the online time
        return np.concatenate([2.0 * self.alpha * u2g - g21, 2.0 * self.alpha * u1g - g12])

    def relative_change(self) -> float:
        return self._change

    def certificate(self) -> Certificate:
        return self._certificate

    def reset(self) -> None:
        """Start the next solve cold: zero subdomain states, Ω₂ factorization dropped (offline data kept)."""
        self.omega2.reset()
        self._t[:] = 0.0
        for prev in self._prev:
            prev[:] = 0.0
        self._drop_products()

    def interface_problem(self, options: InterfaceNewtonOptions):
        """The affine pieces for ``hybrid.interface_newton``: Ω₁'s interface response u₁|γ = R g₁₂ + r₀ from the
        coarse solver (``Omega1Multiscale.response``: one dense coarse solve with n_γ + 1 right-hand sides,
        nothing of fine-mesh size), Ω₂ with J₀ (built once)."""
        options = interface_options(options, self.omega2.friction, frictional_condensation=False)
        if self._newton is None or self._newton.options.strategy != options.strategy:
            iface = self.interface
            R, r0 = self.omega1.response()  # rows: this rank's owned values; columns: all ranks' (rank order)
            omega1 = MatrixResponse(np.vstack(self.comm.allgather(R)), iface.gather(r0))
            omega2 = PrimalPart(self.omega2, iface, 1, contact=True, factorize=options.strategy == "condensed")
            self._newton = InterfaceProblem(
                omega1, omega2, iface.gather(2.0 * self.alpha), -1.0, iface.gather, iface.local, options
            )
        return self._newton

    def record(self) -> dict:
        return dict(self._record)

    # -- measures -------------------------------------------------------------------------
    def _measure(self, *, kept: bool = False) -> None:
        """The relative change of the pair since the last application of T.  Ω₁'s part is a small dense product in
        the interface coordinates.  ``kept`` (the condensed Newton's load steps): Ω₂'s products with the stiffness
        and mass matrices of the last state are kept, and those of the change are their differences,
        K(u − u_prev) = K u − K u_prev: two sparse products instead of four (as ``hybrid.primal``'s Algorithm 1)."""
        om1, om2 = self.omega1, self.omega2
        (de1, ne1), (dl1, nl1) = om1.interface_norms2(np.column_stack([self._t - self._prev[0], self._t]))
        self._diff2.x.array[:] = om2.u.x.array - self._prev[1]
        fast = kept and self._products is not None
        if fast:
            Ku, Mu, Kprev, Mprev = self._products
            om2.norm_products(om2.u, Ku, Mu)
            x, d = om2.u.x.petsc_vec, self._diff2.x.petsc_vec
            ne2, nl2 = Ku.dot(x), Mu.dot(x)
            Kprev.aypx(-1.0, Ku)  # K u − K u_prev
            Mprev.aypx(-1.0, Mu)
            de2, dl2 = Kprev.dot(d), Mprev.dot(d)
            self._products = [Kprev, Mprev, Ku, Mu]  # (the next call's work and kept products)
        else:
            de2, dl2 = om2.energy_norm2(self._diff2), om2.l2_norm2(self._diff2)
            ne2, nl2 = om2.energy_norm2(om2.u), om2.l2_norm2(om2.u)
            if kept:
                self._products = [om2.u.x.petsc_vec.duplicate() for _ in range(4)]
                om2.norm_products(om2.u, *self._products[2:])
            else:
                self._drop_products()
        de, dl, ne, nl = de1 + de2, dl1 + dl2, ne1 + ne2, nl1 + nl2
        self._prev[0][:] = self._t
        self._prev[1][:] = om2.u.x.array
        # (a quadratic form of a round-off-sized difference can come out a little below zero)
        self._change = max(np.sqrt(max(de, 0.0) / ne), np.sqrt(max(dl, 0.0) / nl)) if ne > 0 and nl > 0 else np.inf

    def _drop_products(self) -> None:
        """Forget the products kept by ``_measure`` (the state changed otherwise)."""
        for vec in self._products or ():
            vec.destroy()
        self._products = None

    def _errors(self) -> tuple[float, float]:
        if self.reference is None:
            raise InputError("no reference solution was given")
        r1, r2 = self.reference
        d1 = self.omega1.field(self.omega1.expand(self._t)) - r1  # the fine field (no cancellation in the error norms)
        self._diff2.x.array[:] = self.omega2.u.x.array - r2.x.array
        l2 = self.omega1.l2_norm2(d1) + self.omega2.l2_norm2(self._diff2)
        en = self.omega1.energy_norm2(d1) + self.omega2.energy_norm2(self._diff2)
        return float(np.sqrt(relative(l2, self._ref_l2))), float(np.sqrt(relative(en, self._ref_energy)))

    def error_l2(self) -> float:
        """‖u_h − uⁿ‖_L² / ‖u_h‖_L² over Ω₁ ∪ Ω₂ against the fine monolithic reference."""
        return self._errors()[0]

    def error_energy(self) -> float:
        """(Σ_i a_i(u_h − uⁿ, u_h − uⁿ))^½ / (Σ_i a_i(u_h, u_h))^½ against the fine monolithic reference."""
        return self._errors()[1]

    def glued(self, V: fem.FunctionSpace) -> fem.Function:
        """u on the parent mesh: u₁ on Ω₁, u₂ on Ω₂ (u₂ on γ)."""
        u = fem.Function(V, name="u")
        self.omega1.to_part(self.omega1.field(self.omega1.expand(self._t)), self.u1)
        self.interface.transfers[0].to_parent(self.u1, u)
        self.interface.transfers[1].to_parent(self.omega2.u, u)
        return u


def solve_primal_ms_hybrid(
    problem: ContactProblem,
    *,
    alpha: float | str = DEFAULT_ALPHA_MS,
    delta: float | None = None,
    cem: CEMOptions = CEMOptions(),
    options: IterationOptions = IterationOptions(),
    newton: NewtonOptions = NewtonOptions(),
    reference: fem.Function | None = None,
    cache_dir: str | Path | None = None,
    initial_data: np.ndarray | None = None,
    step: MultiscalePrimalHybridStep | None = None,
    check: bool = True,
) -> HybridResult:
    """Algorithm 3 until the transmission residual is below ``options.tol``; e_u is measured against
    ``reference`` (fine monolithic), outside the online time.  ``initial_data`` warm-starts the interface
    data, ``step`` reuses a step (and its offline data) from an earlier solve.

    ``alpha`` defaults to ``hybrid.primal.DEFAULT_ALPHA_MS`` (h^(-1/2) times the smallest nodal E on γ: a
    nodal E amplifies the multiscale error in stiff channels through γ), ``delta`` to
    ``fem.primal.default_penalty(h, E_c)``; ``cem`` holds the CEM-GMsFEM parameters (layers m, modes l).
    ``dofs["omega1_ms"]`` is dim V_ms; ``time_offline_s`` covers assembly, eigenproblems,
    bases, N and the coarse factorization (breakdown in ``result.step.offline_times``);
    ``time_online_s`` the iteration.  With ``check`` the multiscale Ω₁ is compared with the fine Ω₁ solve for
    the final interface data (``result.omega1_check``; one sparse factorization of the fine Ω₁ operator,
    outside the online time), and a warning names a difference above ``OMEGA1_CHECK_WARN``.
    """
    check_solve_inputs(problem, options=options, newton=newton)
    require_instance(cem, CEMOptions, "cem", " (multiscale.cem.CEMOptions)")
    cm = problem.cm
    if reference is not None:
        check_reference_displacement(reference, cm)
    if step is None:
        step = MultiscalePrimalHybridStep(
            problem, alpha=alpha, delta=delta, cem=cem, newton=newton, reference=reference, cache_dir=cache_dir
        )
    layers, nbasis = step.cem.layers, step.cem.nbasis
    monitor = (lambda: {"e_u": step.error_l2()}) if step.reference is not None else None
    history = iterate(
        step, options, name=f"primal CEM hybrid (m={layers}, l={nbasis})", monitor=monitor, initial=initial_data
    )
    V = reference.function_space if reference is not None else None
    if V is None:
        V = fem.functionspace(cm.mesh, ("Lagrange", 1, (cm.mesh.geometry.dim,)))
    u = step.glued(V)
    dofs = {
        "omega1": step.omega1.num_fine_dofs,
        "omega1_ms": step.omega1.num_coarse_dofs,
        "omega2": step.omega2.num_dofs,
        "interface": step.comm.allreduce(step.interface.size, op=MPI.SUM),
    }
    e_u = step.error_l2() if step.reference is not None else None
    check = step.omega1.fine_check(history.data[: step.interface.size]) if check and history.data is not None else None
    log.info(
        "Algorithm 3: %d iterations (converged %s), dim V_ms = %d, offline %.2f s, online %.2f s, e_u %s, Ω₁ against "
        "its fine solve %s",
        history.iterations,
        history.converged,
        dofs["omega1_ms"],
        step.time_offline_s,
        history.time_s,
        e_u,
        check,
    )
    if check is not None and check > OMEGA1_CHECK_WARN and step.comm.rank == 0:
        log.warning(
            "the multiscale Ω₁ is %.2g (relative, energy norm) from its fine P1 solve for this run's interface "
            "data, with m = %d oversampling layers and %s modes per coarse cell: more layers (--layers) make "
            "it smaller (it falls about tenfold per layer where the bases decay)",
            check,
            layers,
            nbasis,
        )
    return HybridResult(
        step.u1,
        step.omega2.u,
        u,
        history,
        step.omega2.contact_profile(),
        dofs,
        step.time_offline_s + history.time_offline_s,
        history.time_s,
        e_u,
        step,
        history.time_offline_s,
        check,
    )
