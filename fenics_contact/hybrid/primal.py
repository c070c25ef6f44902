"""Algorithm 1: the primal iterative contact-resolving hybrid method (the docs' theory page).

    Ω₁ (linear):    a₁(u₁, v) + α∫_γ u₁·v = (f, v)_Ω₁ + ∫_γ g₁₂·v
    Ω₂ (nonlinear): a₂(u₂, v) + (1/δ)∫_ΓC (u₂c)⁺ v_c + α∫_γ u₂·v = (f, v)_Ω₂ + ∫_γ g₂₁·v
    update at every γ node p:  g₁₂ ← 2α u₂(p) − g₂₁(p),  g₂₁ ← 2α u₁(p) − g₁₂(p)

With vertex quadrature on γ its fixed point is the monolithic penalized
solution (Theorem 3.1).  The iteration stops on the transmission residual of
the pair (``hybrid.certificate``); ``accel="newton"`` solves the fixed point by
the interface Newton method (``hybrid.interface_newton``) instead of iterating.

Ω₁'s linear solver is chosen by ``fem.amg.LinearSolverOptions`` (``solver``): MUMPS Cholesky, factorized once, or
for a large 3D Ω₁ CG + smoothed-aggregation AMG with the rigid-body near-nullspace, set up once and reused by
every iteration and load step.  With AMG the interface Newton is Newton–GMRES, matrix-free
(``hybrid.krylov_newton``): the dense interface response of the condensed strategy would cost n_γ Ω₁ solves.
"""

import dataclasses
import logging
import time
from dataclasses import dataclass

import dolfinx.fem.petsc
import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.fem.amg import AMGSolver, LinearSolverOptions
from fenics_contact.fem.contact import ContactProfile, NewtonHistory, NewtonOptions
from fenics_contact.fem.primal import PrimalSubproblem, penalty_for, warn_if_locking
from fenics_contact.hybrid.certificate import Certificate, primal_certificate, relative
from fenics_contact.hybrid.condensation import InterfaceProblem
from fenics_contact.hybrid.friction import ComponentPart, FrictionalCondensation
from fenics_contact.hybrid.inputs import check_reference_displacement, check_solve_inputs
from fenics_contact.hybrid.iteration import (
    HybridStep,
    InterfaceNewtonOptions,
    IterationHistory,
    IterationOptions,
    IterationResult,
    iterate,
)
from fenics_contact.hybrid.krylov_newton import KrylovInterface
from fenics_contact.hybrid.options import interface_options
from fenics_contact.hybrid.response import FineResponse, PrimalPart
from fenics_contact.hybrid.transmission import InterfaceSpace, part_rollers, robin_coefficient, split_mesh
from fenics_contact.problem.friction import friction_of
from fenics_contact.problem.problem import ContactProblem

__all__ = [
    "PrimalHybridStep",
    "HybridResult",
    "solve_primal_hybrid",
    "solve_or_verify",
    "DEFAULT_ALPHA",
    "DEFAULT_ALPHA_MS",
    "OMEGA1_AUTO_AMG_DOFS",
    "omega1_solver",
]

#: Default transmission coefficient α_p = E_p (h/L_ref)^(-1/2)/L_ref = E_p/√(h L_ref), a stiffness per length
#: (L_ref the body's size, 1 on the unit square; chosen from benchmarks/primal_hybrid_study.py).
DEFAULT_ALPHA = "E*h^-1/2"
#: Default α of Algorithm 3 (multiscale Ω₁): h^(-1/2) times the smallest E_p on γ.  The multiscale Ω₁'s
#: interface response is a Robin map only up to its approximation error ε, and the glued problem sees
#: that error multiplied by α: α_p = E_p h^(-1/2) (≈ 6e6 in the stiff channels of model 3 at contrast
#: 1e6) made it indefinite (h = 1/32, m = 3) or 20–200× less accurate (m = 4).
DEFAULT_ALPHA_MS = "Emin*h^-1/2"
#: Ω₁ unknowns from which ``solver="auto"`` takes AMG in Ω₁ (3D).  Higher than the monolithic solve's
#: ``fem.amg.AUTO_AMG_DOFS``: with MUMPS, Algorithm 1 pays one factorization and the dense interface responses
#: once and one application of T per load step, with AMG 23–36 Ω₁ solves per load step at h = 1/16 and 1/24
#: (benchmarks/primal_hybrid_3d.py; docs/performance.md), so AMG pays only where MUMPS' memory runs out (its
#: fitted memory passes 10 GB near 330,000 DOFs, benchmarks/solvers_3d.py --fit)
OMEGA1_AUTO_AMG_DOFS = 300_000

log = logging.getLogger(__name__)


def omega1_solver(solver: LinearSolverOptions | str) -> LinearSolverOptions:
    """Ω₁'s linear solver options: a kind given by name (``"auto"``) takes AMG from ``OMEGA1_AUTO_AMG_DOFS``."""
    if isinstance(solver, str):
        return LinearSolverOptions(kind=solver, auto_dofs=OMEGA1_AUTO_AMG_DOFS)
    return LinearSolverOptions.of(solver)


def solve_or_verify(sub: PrimalSubproblem, warm: bool) -> NewtonHistory:
    """Solve Ω₂; with ``warm`` (its state is a candidate solution, e.g. from the interface Newton) first
    check the residual with the semismooth Newton's own acceptance test and solve only if it fails."""
    if warm:
        res, load = sub.residual_norm()
        if res <= sub.newton.rtol * load + sub.newton.atol:
            if sub.friction is not None:
                sub._factorize()  # (its Jacobian at this state: the interface Newton's corrections read it)
            return NewtonHistory(residuals=[res])
    return sub.solve()


def omega2_record(history: NewtonHistory) -> dict:
    """Newton steps, final active-set size and factorizations of an Ω₂ solve (for the iteration record)."""
    return {
        "newton": history.steps,
        "active": history.active_sizes[-1] if history.active_sizes else None,
        "refactor": history.factorizations,
    }


class PrimalHybridStep:
    """The transmission map T of Algorithm 1 on a tagged mesh."""

    def __init__(
        self,
        problem: ContactProblem,
        *,
        alpha: float | str = DEFAULT_ALPHA,
        delta: float | None = None,
        newton: NewtonOptions = NewtonOptions(),
        reference: fem.Function | None = None,
        solver: LinearSolverOptions | str = "auto",
    ) -> None:
        """``solver``: Ω₁'s linear solver (``fem.amg.LinearSolverOptions`` or its kind; Ω₂, the contact strip,
        keeps MUMPS for its Newton Jacobians)."""
        cm = problem.cm
        self.comm = cm.comm
        self.parts = split_mesh(cm)
        gdim = cm.mesh.geometry.dim
        self.interface = InterfaceSpace(cm, self.parts, shape=(gdim,))
        parent_fields = problem.fields
        warn_if_locking(parent_fields.nu, cm.comm)
        self.alpha = robin_coefficient(alpha, parent_fields.E, self.interface, cm.h, problem.length)
        self.delta = delta = penalty_for(problem, delta)
        self.sub = []
        for i, part in enumerate(self.parts):
            alpha_fn = fem.Function(self.interface.spaces[i], name="alpha")
            self.interface.to_part(self.alpha, i, alpha_fn)
            fields = problem.fields_on(part.mesh)
            if problem.boundary.rollers:  # each part takes the roller planes on its own outer boundary
                own = part_rollers(part, problem.boundary.rollers)
                fields = fields._replace(boundary=dataclasses.replace(problem.boundary, rollers=own))
            self.sub.append(
                PrimalSubproblem(
                    part.mesh,
                    part.facet_tags,
                    fields,
                    delta=delta if i == 1 else None,
                    alpha=alpha_fn,
                    prefix=f"fc_primal_omega{i + 1}_",
                    newton=newton,
                    V=self.interface.spaces[i],
                    friction=friction_of(problem.law) if i == 1 else None,
                    solver=omega1_solver(solver) if i == 0 else "direct",
                )
            )
        self._prev = [np.zeros_like(s.u.x.array) for s in self.sub]
        self._products: list | None = None  #: per subdomain [K u, M u, work, work] of the last state (``_measure``)
        self._diff = [fem.Function(s.V) for s in self.sub]
        self._change = np.inf
        self._certificate = Certificate(np.inf, np.inf)
        self._record: dict = {}
        self._newton = None
        self._omega1_data: np.ndarray | None = None  #: the data g₁₂ of Ω₁'s last ``PrimalPart.solve_for`` (global)
        self._robin = None  #: (Ω₁'s PrimalPart, R on its owned γ rows, its Γ_D rows): ``_omega1_stiffness_product``
        self._krylov: KrylovInterface | None = None
        self.reference = None
        if reference is not None:
            self.reference = [fem.Function(s.V) for s in self.sub]
            for i, ref in enumerate(self.reference):
                self.interface.transfers[i].to_sub(reference, ref)
            self._ref_norm2 = sum(s.l2_norm2(r) for s, r in zip(self.sub, self.reference))

    @property
    def contact(self) -> PrimalSubproblem:
        """The subproblem holding Γ_C (Ω₂)."""
        return self.sub[1]

    @property
    def omega1_iterative(self) -> bool:
        """Ω₁ is solved by CG + AMG (the interface Newton is then Newton–GMRES, ``hybrid.krylov_newton``)."""
        return isinstance(self.sub[0].solver, AMGSolver)

    def initial_data(self) -> np.ndarray:
        return np.zeros(2 * self.interface.size)

    def prepare(self) -> None:
        """Offline work: factorize the linear Ω₁ operator once (with AMG: its set-up, once)."""
        self.sub[0].factorize()

    def apply(self, g: np.ndarray, *, omega2_warm: bool = False) -> np.ndarray:
        n = self.interface.size
        g12, g21 = g[:n], g[n:]
        for i, data in enumerate((g12, g21)):
            self.interface.to_part(data, i, self.sub[i].g)
        newton = [self._solve_omega1(g12, omega2_warm), solve_or_verify(self.sub[1], omega2_warm)]
        u1 = self.interface.from_part(self.sub[0].u, 0)
        u2 = self.interface.from_part(self.sub[1].u, 1)
        self._measure(kept=omega2_warm)
        self._certificate = primal_certificate(u1, u2, g12, g21, self.alpha, self.interface.weights, self.comm)
        self._record = omega2_record(newton[1])
        return np.concatenate([2.0 * self.alpha * u2 - g21, 2.0 * self.alpha * u1 - g12])

    def _solve_omega1(self, g12: np.ndarray, condensed: bool) -> NewtonHistory | None:
        """Solve Ω₁ for the data g₁₂ (its Robin data set).  In the condensed interface Newton's application of T
        (``condensed``, the Ω₁ response held) the linear Ω₁ is one back-solve of the kept body load plus the data
        (``PrimalPart.solve_for``: no assembly of its residual), otherwise its own solve."""
        omega1 = getattr(self._newton, "omega1", None)
        self._omega1_data = None
        state = self._krylov.take_omega1_state(g12) if self._krylov is not None else None
        if state is not None:  # the Newton–GMRES's (``hybrid.krylov_newton``: solved there, or a combination of solves)
            self._krylov.omega1.set_state(state)
            return None
        if condensed and isinstance(omega1, FineResponse) and omega1.part.sub is self.sub[0]:
            self._omega1_data = self.interface.gather(g12)
            omega1.part.solve_for(self._omega1_data)
            return None
        return self.sub[0].solve()

    def _omega1_stiffness_product(self, Ku) -> bool:
        """Ku ← K u₁ for the Ω₁ state ``PrimalPart.solve_for`` set, from the equations it solved, J u₁ = b + C g:
        J is K plus the Robin term's diagonal R = α w on the γ unknowns (vertex quadrature) on the free rows, so
        K u₁ = b + C g − R u₁ there, without a product with K (the solve's residual, like the product's rounding,
        is ε|K||u₁| row by row); 0 on the Γ_D rows, which the relative change sees only through u₁ and its change,
        both 0 there.  Returns False (Ku untouched) unless Ω₁'s state came from ``solve_for`` and u_D vanishes."""
        part = getattr(getattr(self._newton, "omega1", None), "part", None)
        if self._omega1_data is None or part is None:
            return False
        if self._robin is None or self._robin[0] is not part:  # (once per part: R on its γ rows, the Γ_D rows)
            weights = self.interface.gather(self.alpha * self.interface.weights)
            mask = self.sub[0].u.x.petsc_vec.duplicate()
            mask.set(1.0)
            dolfinx.fem.petsc.set_bc(mask, self.sub[0].bcs)  # (0 on the Γ_D rows)
            fixed = mask.getArray(readonly=True) == 0.0
            mask.destroy()
            self._robin = (part, weights[part.trace_index], fixed)
        _, robin, fixed = self._robin
        u = self.sub[0].u.x.array[: part.nown]
        if self.comm.allreduce(bool(np.any(u[fixed])), op=MPI.LOR):
            return False
        out = part.solved_rhs()
        out[part.trace_at] -= robin * u[part.trace_at]
        out[fixed] = 0.0
        Ku.getArray()[:] = out
        return True

    def certificate(self) -> Certificate:
        return self._certificate

    def reset(self) -> None:
        """Start the next solve cold: zero subdomain states, Ω₂ factorization dropped (offline data kept)."""
        self.sub[1].reset()
        self.sub[0].u.x.array[:] = 0.0
        for prev in self._prev:
            prev[:] = 0.0
        self._drop_products()

    def data_weights(self) -> np.ndarray:
        """w_p/α_p per data value: Robin data g ~ α u + t, so this balances stiff and soft γ nodes in Anderson."""
        w = self.interface.weights / self.alpha
        return np.concatenate([w, w])

    def krylov_interface(self) -> KrylovInterface:
        """The matrix-free interface equation of Newton–GMRES (built once: Ω₁'s set-up, the γ and Γ_C maps)."""
        if self._krylov is None:
            self.prepare()
            iface = self.interface
            omega1 = PrimalPart(self.sub[0], iface, 0, contact=False)
            omega2 = PrimalPart(self.sub[1], iface, 1, contact=True, factorize=False)
            self._krylov = KrylovInterface(omega1, omega2, iface.gather(2.0 * self.alpha), -1.0)
        return self._krylov

    def interface_problem(self, options: InterfaceNewtonOptions):
        """The affine pieces for ``hybrid.interface_newton`` (built once: fine Ω₁ response, Ω₂ with J₀)."""
        friction = self.sub[1].friction
        options = interface_options(options, friction, frictional_condensation=True)
        if self._newton is None or self._newton.options.strategy != options.strategy:
            self.prepare()
            iface = self.interface
            omega1 = FineResponse(PrimalPart(self.sub[0], iface, 0, contact=False), chunk=options.chunk)
            condensed = options.strategy == "condensed"
            if friction is not None and condensed:  # all components of the Γ_C displacements (hybrid.friction)
                omega2 = ComponentPart(self.sub[1], iface, 1)
            else:
                omega2 = PrimalPart(self.sub[1], iface, 1, contact=True, factorize=condensed)
            self._newton = InterfaceProblem(
                omega1, omega2, iface.gather(2.0 * self.alpha), -1.0, iface.gather, iface.local, options
            )
            if isinstance(omega2, ComponentPart):
                self._newton.condensed = FrictionalCondensation(self._newton)
        return self._newton

    def _measure(self, *, kept: bool = False) -> None:
        """The relative change of the pair since the last application of T.  ``kept`` (the condensed Newton's
        load steps): the products with the stiffness and mass matrices of the last state are kept, and those of
        the change are their differences, K(u − u_prev) = K u − K u_prev: two products per subdomain instead of
        four (the same numbers to round-off relative to the state's, the change's relative accuracy ε/change);
        Ω₁'s K u₁ from the equations its back-solve solved (``_omega1_stiffness_product``): one product there, and
        Ω₁'s K is not assembled (``PrimalSubproblem._K``, on first use) along a load path from a zero state."""
        de = du = ne = nu = 0.0
        fast = kept and self._products is not None
        if kept and not fast:
            self._products = [[s.u.x.petsc_vec.duplicate() for _ in range(4)] for s in self.sub]
        for i, (s, prev, diff) in enumerate(zip(self.sub, self._prev, self._diff)):
            diff.x.array[:] = s.u.x.array - prev
            if fast:
                Ku, Mu, Kprev, Mprev = self._products[i]
                # (Ω₁'s K u₁ from its equations: the mass product only)
                s.norm_products(s.u, None if i == 0 and self._omega1_stiffness_product(Ku) else Ku, Mu)
                x, d = s.u.x.petsc_vec, diff.x.petsc_vec
                ne, nu = ne + Ku.dot(x), nu + Mu.dot(x)
                Kprev.aypx(-1.0, Ku)  # K u − K u_prev
                Mprev.aypx(-1.0, Mu)
                de, du = de + Kprev.dot(d), du + Mprev.dot(d)
                self._products[i] = [Kprev, Mprev, Ku, Mu]  # (the next call's work and kept products)
            elif kept:  # the products of the state, kept for the next call, give its quadratic forms
                Ku, Mu = self._products[i][2:]
                s.norm_products(s.u, None if i == 0 and self._omega1_stiffness_product(Ku) else Ku, Mu)
                x = s.u.x.petsc_vec
                ne_i, nu_i = Ku.dot(x), Mu.dot(x)
                ne, nu = ne + ne_i, nu + nu_i
                if self.comm.allreduce(bool(np.any(prev)), op=MPI.LOR):
                    de += s.energy_norm2(diff)
                    du += s.l2_norm2(diff)
                else:  # from zero (a curve's first step): the change is the state itself
                    de, du = de + ne_i, du + nu_i
            else:
                de += s.energy_norm2(diff)
                du += s.l2_norm2(diff)
                ne += s.energy_norm2(s.u)
                nu += s.l2_norm2(s.u)
            prev[:] = s.u.x.array
        if not kept:
            self._drop_products()
        # (a quadratic form of a round-off-sized difference can come out a little below zero)
        self._change = max(np.sqrt(max(de, 0.0) / ne), np.sqrt(max(du, 0.0) / nu)) if ne > 0 and nu > 0 else np.inf

    def _drop_products(self) -> None:
        """Forget the products kept by ``_measure`` (the state changed otherwise)."""
        for vec in [v for vecs in self._products or () for v in vecs]:
            vec.destroy()
        self._products = None

    def relative_change(self) -> float:
        return self._change

    def record(self) -> dict:
        return dict(self._record)

    def error_l2(self) -> float:
        """‖u_h − uⁿ‖_L² / ‖u_h‖_L² over both subdomains (needs the reference)."""
        err = 0.0
        for s, ref, diff in zip(self.sub, self.reference, self._diff):
            diff.x.array[:] = s.u.x.array - ref.x.array
            err += s.l2_norm2(diff)
        return float(np.sqrt(relative(err, self._ref_norm2)))

    def error_energy(self) -> float:
        """‖u_h − uⁿ‖_a / ‖u_h‖_a over both subdomains (needs the reference)."""
        err = ref = 0.0
        for s, r, diff in zip(self.sub, self.reference, self._diff):
            diff.x.array[:] = s.u.x.array - r.x.array
            err += s.energy_norm2(diff)
            ref += s.energy_norm2(r)
        return float(np.sqrt(relative(err, ref)))

    def glued(self, V: fem.FunctionSpace) -> fem.Function:
        """u on the parent mesh: u₁ on Ω₁, u₂ on Ω₂ (u₂ on γ)."""
        u = fem.Function(V, name="u")
        for i, s in enumerate(self.sub):
            self.interface.transfers[i].to_parent(s.u, u)
        return u


@dataclass(slots=True)
class HybridResult(IterationResult):
    """Fields, history, DOF counts and timings of a hybrid solve."""

    u1: fem.Function
    u2: fem.Function
    u: fem.Function
    history: IterationHistory
    profile: ContactProfile
    dofs: dict
    time_offline_s: float
    time_online_s: float
    e_u: float | None
    step: HybridStep  #: the step object (PrimalHybridStep, MultiscalePrimalHybridStep, ...)
    time_interface_offline_s: float = 0.0  #: offline interface response of the Newton method (in time_offline_s)
    #: Algorithm 3: the multiscale Ω₁ against the fine Ω₁ solve for the final interface data (relative energy
    #: norm; ``Omega1Multiscale.fine_check``), None when not checked
    omega1_check: float | None = None


def solve_primal_hybrid(
    problem: ContactProblem,
    *,
    alpha: float | str = DEFAULT_ALPHA,
    delta: float | None = None,
    options: IterationOptions = IterationOptions(),
    newton: NewtonOptions = NewtonOptions(),
    reference: fem.Function | None = None,
    initial_data: np.ndarray | None = None,
    step: PrimalHybridStep | None = None,
    solver: LinearSolverOptions | str = "auto",
) -> HybridResult:
    """Algorithm 1 until the transmission residual is below ``options.tol``.

    ``delta`` defaults to ``fem.primal.default_penalty(h, E_c)``, E_c the largest E on Γ_C; ``reference`` (the
    monolithic solution) adds e_u per iteration, outside the online time;
    ``initial_data`` warm-starts the interface data; ``step`` reuses a step (and its offline
    data) from an earlier solve on the same mesh and model.  ``solver``: Ω₁'s linear solver
    (``fem.amg.LinearSolverOptions`` or its kind: ``"direct"``, ``"amg"``, ``"auto"``: AMG for a 3D Ω₁ of
    ``OMEGA1_AUTO_AMG_DOFS`` unknowns or more).
    """
    check_solve_inputs(problem, options=options, newton=newton)
    cm = problem.cm
    if reference is not None:
        check_reference_displacement(reference, cm)
    start = time.perf_counter()
    if step is None:
        step = PrimalHybridStep(problem, alpha=alpha, delta=delta, newton=newton, reference=reference, solver=solver)
    step.prepare()
    offline = time.perf_counter() - start
    monitor = (lambda: {"e_u": step.error_l2()}) if step.reference is not None else None
    history = iterate(step, options, name="primal hybrid", monitor=monitor, initial=initial_data)
    V = reference.function_space if reference is not None else None
    if V is None:
        V = fem.functionspace(cm.mesh, ("Lagrange", 1, (cm.mesh.geometry.dim,)))
    u = step.glued(V)
    dofs = {
        "omega1": step.sub[0].num_dofs,
        "omega2": step.sub[1].num_dofs,
        "interface": step.comm.allreduce(step.interface.size, op=MPI.SUM),
    }
    e_u = step.error_l2() if step.reference is not None else None
    return HybridResult(
        step.sub[0].u,
        step.sub[1].u,
        u,
        history,
        step.sub[1].contact_profile(),
        dofs,
        offline + history.time_offline_s,
        history.time_s,
        e_u,
        step,
        history.time_offline_s,
    )
