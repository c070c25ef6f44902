"""Algorithm 2: the mixed iterative contact-resolving hybrid method (the docs' theory page).

    Ω₁ (linear):    (Aσ₁, τ) + (div τ, u₁) + β∫_γ (σ₁n₁)·(τn₁) = ∫_γ g₁₂·(τn₁),   (div σ₁, v) = −(f, v)
    Ω₂ (nonlinear): (Aσ₂, τ) + (div τ, u₂) + β∫_γ (σ₂n₂)·(τn₂) + (1/ε)∫_ΓC (σ₂c)⁺τ_c = ∫_γ g₂₁·(τn₂),
                    (div σ₂, v) = −(f, v)
    update:         g₁₂ ← g₂₁ − 2β σ₂n₂,   g₂₁ ← g₁₂ − 2β σ₁n₁   (old values on the right)

Both subdomains use Arnold–Winther stresses × DG P1 displacements
(``fem.mixed.MixedSubproblem``); Ω₁ is factorized once, Ω₂ runs the globalized
semismooth Newton warm-started from its last solution and refactorizes only
when its active set changes.  The loop is ``hybrid.iteration.iterate`` (plain update as in the
paper, Anderson acceleration, or the interface Newton method of ``hybrid.interface_newton``), stopped by the
transmission residual of ``hybrid.certificate``.

**Space of the Robin data and quadrature on γ.**  The normal trace σn of an AW
stress on a straight edge is a cubic vector polynomial, and it is continuous where
γ is straight (AW has vertex degrees of freedom).  Where γ bends at a vertex v
the normal jumps, and so does σn; the two one-sided values are (σ(v)n_a, σ(v)n_b)
of one symmetric tensor σ(v), a 3-dimensional space.  On γ the traces of X_h(Ω₁)
and X_h(Ω₂) therefore both fill Λ_h = vector P3 on each γ edge, continuous at the
straight vertices, with one value per side at a bend restricted to those tractions
(``fem.mixed_interface.GammaBends``).  The data g₁₂, g₂₁ live in Λ_h, stored as
their values (x, y) at the P3 Lagrange nodes of γ (vertices + 2 points per edge)
and, at a bend, as 3 coefficients in an orthonormal basis of the two sides' values.
Then:

* the update is exact: σ_i n_i ∈ Λ_h is evaluated at the nodes from the DG P3
  representation (no projection);
* every γ integral (β∫σn·τn and ∫g·τn, both degree 6) uses the same 4-point
  Gauss rule per edge and is exact;
* Λ_h is exactly the trace space, so the fixed point below has one λ (a larger
  space, e.g. two free values per side at a bend, leaves the data of the
  iteration undetermined there and the interface Newton's system singular).

At a fixed point, adding the two updates gives σ₁n₁ + σ₂n₂ = 0 in Λ_h, i.e.
pointwise, and λ := g₁₂ − βσ₁n₁ = g₂₁ − βσ₂n₂ is a single displacement trace on
γ with (Aσ_i, τ) + (div τ, u_i) − ∫_γ λ·τn_i + … = 0 on each side; summing over
τ with continuous normal trace eliminates λ.  So the fixed point is exactly the
monolithic mixed solution on X̃_h = {σ ∈ X_h(Ω₁) × X_h(Ω₂) : σn continuous on γ}.
X̃_h is X_h plus one function per straight γ vertex: AW glues all three stress
components at a vertex, X̃_h only the traction σn, so σ_tt may differ on the two
sides of a straight γ vertex (at a bend the tractions on both edges fix all of
σ(v), so X̃_h glues it there as X_h does).  No transmission condition can restore
that (σ_tt is not a trace quantity), so this is the closest fixed point a
non-overlapping Robin iteration with AW subdomain spaces can have.
``fem.mixed.solve_mixed_monolithic(split_interface=True)`` computes it directly; the
iterate converges to it to round-off (1e−10 at tolerance 1e−10).  Its distance
from the standard AW solution (``split_interface=False``, the paper's
reference) is a discretization effect, concentrated where the load bands'
corner (x = 15/16, y = ½) meets γ: measured with H = 1/16, model 1 / model 2,

    h = 1/32: e_σ 9.1e−4 / 1.1e−3,  e_u 1.7e−5 / 1.6e−5
    h = 1/64: e_σ 1.4e−4 / 1.9e−4,  e_u 1.5e−6 / 1.5e−6
    h = 1/128: e_σ 3.5e−5 / 4.7e−5, e_u 1.8e−7 / 1.8e−7

(O(h²); ``benchmarks/reproduce_mixed_tables.py``, ``tests/hybrid/test_mixed_hybrid.py``).
It is the floor of e_σ, e_u against the AW reference.  On a γ that bends at most of
its vertices (the zigzag of a band of width 0.15 along Γ_C, model 2,
``tests/hybrid/test_mixed_bent_interface.py``) the iterate is the X̃_h solution to
1e−12 and its distance from the AW solution is

    h = 1/16: e_σ 5.0e−5, e_u 5.5e−7;   h = 1/24: e_σ 2.6e−5, e_u 1.9e−7.

**Friction.**  A friction law (``problem.law``) acts on Γ_C ⊂ Ω₂ only (``fem.mixed_friction``: the law on the
tangential traction), so Ω₁ and the update are unchanged and the fixed point above carries over: at every load
step of a path (``fenics_contact.slide``) it is the monolithic frictional solution on X̃_h (measured 2e−11 at
contrast 1e6, ``benchmarks/results/friction_mixed.md``).  The interface Newton then runs its ``"interface"``
strategy, Newton on g = T(g) with Ω₂'s frictional Jacobian (``hybrid.options.interface_options``).

**MPI.**  Under ``mpiexec`` both subproblems are distributed (``fem.mixed``); the
Robin data g₁₂, g₂₁ are the values at the canonical γ nodes (Ω₁'s order, which Ω₂
adopts), each rank holding one block of them (``MixedSubproblem.interface_range``),
so the update and Anderson's inner products are global.  The interface Newton takes
its affine pieces from the distributed subproblems (``hybrid.response.MixedPart``: block back-solves with
their factorizations, the trace and contact rows gathered) and solves its dense interface problem on every
rank.  The iterations, Newton steps and solution are those of the serial run
(``tests/fem/test_mpi_mixed.py``).
"""

import logging
import time
from dataclasses import dataclass

import basix.ufl
import numpy as np
from dolfinx import fem

from fenics_contact.errors import InputError
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import MixedSolution, epsilon_for
from fenics_contact.fem.mixed_contact import MixedContactProfile
from fenics_contact.fem.mixed_newton import MixedNewtonHistory
from fenics_contact.fem.mixed_spaces import check_triangles
from fenics_contact.fem.mixed_subproblem import MixedSubproblem
from fenics_contact.hybrid.certificate import Certificate, mixed_certificate, relative
from fenics_contact.hybrid.condensation import InterfaceProblem
from fenics_contact.hybrid.inputs import check_reference_mixed, check_solve_inputs
from fenics_contact.hybrid.iteration import (
    InterfaceNewtonOptions,
    IterationHistory,
    IterationOptions,
    IterationResult,
    iterate,
)
from fenics_contact.hybrid.options import interface_options
from fenics_contact.hybrid.primal import omega2_record
from fenics_contact.hybrid.response import FineResponse, MixedPart
from fenics_contact.hybrid.transmission import split_mesh, sub_to_parent_dofs
from fenics_contact.problem.friction import friction_of
from fenics_contact.problem.problem import ContactProblem

__all__ = [
    "DEFAULT_BETA",
    "MixedHybridResult",
    "MixedHybridStep",
    "solve_mixed_hybrid",
    "solve_or_verify",
    "transmission_coefficient",
]

log = logging.getLogger(__name__)

#: Default transmission coefficient β = √(h L_ref)/E_c of Algorithms 2 and 4 (the paper's faster choice √h, with
#: E = L_ref = 1; E_c the smallest Young's modulus on Γ_C and L_ref the body's size make β a compliance, a length
#: per stress, as the primal α = E/√(h L_ref) is a stiffness per length).
DEFAULT_BETA = "sqrt-h"


def solve_or_verify(sub: MixedSubproblem, data: np.ndarray, warm: bool) -> MixedNewtonHistory:
    """Solve Ω₂ with Robin data; with ``warm`` (its state is a candidate solution, e.g. from the interface
    Newton) first check the residual with the Newton solver's own acceptance test and solve only if it fails."""
    if warm:
        res, scale = sub.residual(data)
        if res <= sub.newton.rtol * scale + sub.newton.atol:
            return MixedNewtonHistory(residuals=[res])
    return sub.solve(data)


def transmission_coefficient(beta: float | str, h: float, modulus: float = 1.0, length: float = 1.0) -> float:
    """β from a number (or its string: a length per stress in the data's units) or ``"sqrt-h"``: β =
    √(h/L_ref)·L_ref/E_c = √(h L_ref)/E_c, E_c = ``modulus``, L_ref = ``length`` (the body's size; 1 on the unit
    square, where β = √h/E_c): a compliance in the units of the data, the same relative answers in any unit of
    length. Raises InputError unless β > 0."""
    if not (np.isfinite(length) and length > 0):
        raise InputError(f"the reference length L_ref must be a finite number > 0, got {length!r}")
    if isinstance(beta, str):
        text = beta.strip().replace(" ", "").lower()
        if text in ("sqrt-h", "sqrt(h)", "h^1/2", "h^0.5"):
            value = float(np.sqrt(h / length)) * length / modulus
        else:
            try:
                value = float(text)
            except ValueError:
                raise InputError(f"cannot read beta={beta!r}: give a number > 0 or 'sqrt-h'") from None
    else:
        value = float(beta)
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"the transmission coefficient β must be > 0, got {beta!r}")
    return value


class MixedHybridStep:
    """The transmission map T of Algorithm 2 on a tagged mesh (implements ``hybrid.iteration.HybridStep``)."""

    #: whether the Ω₁ subproblem assembles its global matrices (Algorithm 4's Ω₁ does not need them)
    omega1_operators = True

    def __init__(
        self,
        problem: ContactProblem,
        *,
        beta: float | str = DEFAULT_BETA,
        epsilon: float | None = None,
        newton: NewtonOptions = NewtonOptions(),
        reference: MixedSolution | None = None,
    ) -> None:
        cm = problem.cm
        check_triangles(cm.mesh)
        self.comm = cm.comm
        self.beta = transmission_coefficient(beta, cm.h, problem.contact_modulus(smallest=True), problem.length)
        self.epsilon = epsilon_for(problem, epsilon)
        self.cm = cm
        self.parts = split_mesh(cm)
        # Ω₂ takes its Robin data at Ω₁'s γ nodes (canonical order, distributed in blocks over the ranks)
        self.sub = []
        for i, part in enumerate(self.parts):
            fields = problem.fields_on(part.mesh)
            self.sub.append(
                MixedSubproblem(
                    part.mesh,
                    part.facet_tags,
                    fields,
                    epsilon=self.epsilon if i == 1 else None,
                    beta=self.beta,
                    prefix=f"fc_mixed_omega{i + 1}_",
                    newton=newton,
                    operators=i == 1 or self.omega1_operators,
                    space=self._omega1_space(part, fields) if i == 0 else None,
                    interface_points=self.sub[0].gamma_points if i == 1 else None,
                    friction=friction_of(problem.law) if i == 1 else None,
                )
            )
        if self.sub[0].interface_range != self.sub[1].interface_range:
            raise RuntimeError("the interface data of Ω₁ and Ω₂ are not distributed alike")
        g0, g1 = self.sub[0].interface_range
        #: this rank's number of interface values (x, y at the canonical γ nodes) per data vector
        self.size = g1 - g0
        self.size_global = self.sub[0].interface.num_values
        self._perm2 = np.arange(self.size)  # Ω₂ uses the canonical order (kept for subclasses)
        self._prev = [(s.c.copy(), s.u.copy()) for s in self.sub]
        self._change = np.inf
        self._certificate = Certificate(np.inf, np.inf)
        self._record: dict = {}
        self._newton = None
        #: L²(γ) mass matrix of the interface data (canonical order: Ω₁'s γ nodes), for the certificate
        self.gamma_mass = self.sub[0].gamma_mass()
        self.reference = None
        if reference is not None:
            self.set_reference(reference)

    @property
    def contact(self) -> MixedSubproblem:
        """The subproblem holding Γ_C (Ω₂)."""
        return self.sub[1]

    def _omega1_space(self, part, fields) -> ArnoldWintherSpace | None:
        """Ω₁'s stress space (``fem.arnold_winther.ArnoldWintherSpace``) for the ``transmission.Part`` ``part``
        with its material ``fields``, or None for the one ``MixedSubproblem`` builds (Algorithm 4 shares out its
        set-up)."""
        return None

    # -- reference --------------------------------------------------------------------
    def set_reference(self, reference: MixedSolution) -> None:
        """Restrict the monolithic σ_h, u_h to the parts, as AW / DG P1 coefficients there."""
        self.reference = [self._part_reference(i, reference) for i in range(len(self.parts))]
        self._ref_norm2 = (
            sum(s.stress_norm2(c) for s, (c, _) in zip(self.sub, self.reference)),
            sum(s.l2_norm2(u) for s, (_, u) in zip(self.sub, self.reference)),
        )

    def _part_reference(self, i: int, reference: MixedSolution, *, dg: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """σ_h, u_h on part i: AW coefficients (``dg``: the DG P3 values minus the traction lifting) and DG P1
        values of the part (owned entries)."""
        part, s = self.parts[i], self.sub[i]
        i_sub, i_par = sub_to_parent_dofs(part, s.dg, reference.sigma.function_space)
        d = np.zeros(s.dg.dofmap.index_map.size_local * s.dg.dofmap.index_map_bs)
        d[i_sub] = reference.sigma.x.array[i_par]
        j_sub, j_par = sub_to_parent_dofs(part, s.U, reference.u.function_space)
        u = np.zeros(s.n_u)
        u[j_sub] = reference.u.x.array[j_par]
        if dg:
            return d - s.s0, u  # the traction lifting is not in the span of P
        c, miss = s.fit_stress(d)  # (fit_stress removes the lifting itself)
        if miss > 1e-8:
            raise InputError(f"the reference stress is not in the subdomain stress space (misfit {miss:.2e})")
        return c, u

    def errors(self) -> tuple[float, float]:
        """(e_σ, e_u) = (‖σ_h − σⁿ‖_A/‖σ_h‖_A, ‖u_h − uⁿ‖/‖u_h‖) against the reference."""
        es = sum(s.stress_norm2(s.c - c) for s, (c, _) in zip(self.sub, self.reference))
        eu = sum(s.l2_norm2(s.u - u) for s, (_, u) in zip(self.sub, self.reference))
        return float(np.sqrt(relative(es, self._ref_norm2[0]))), float(np.sqrt(relative(eu, self._ref_norm2[1])))

    # -- HybridStep protocol -------------------------------------------------------------
    def initial_data(self) -> np.ndarray:
        """g⁰ = 0: (g₁₂, g₂₁) stacked, values (x, y) at the canonical γ nodes."""
        return np.zeros(2 * self.size)

    def prepare(self) -> None:
        """Offline work: factorize the linear Ω₁ saddle-point operator once."""
        self.sub[0]._factorize_for(None)

    def apply(self, g: np.ndarray, *, omega2_warm: bool = False) -> np.ndarray:
        n = self.size
        g12, g21 = g[:n], g[n:]
        self.sub[0].solve(g12)
        newton = self.sub[1].solve(g21[self._perm2])
        t1 = self.sub[0].gamma_traction()  # σ₁n₁ at the canonical nodes
        t2 = np.empty(n)
        t2[self._perm2] = self.sub[1].gamma_traction()  # σ₂n₂
        self._measure()
        self._certificate = mixed_certificate(t1, t2, g12, g21, self.beta, self.gamma_mass, self.comm)
        self._record = omega2_record(newton)
        return np.concatenate([g21 - 2.0 * self.beta * t2, g12 - 2.0 * self.beta * t1])

    def certificate(self) -> Certificate:
        return self._certificate

    def reset(self) -> None:
        """Start the next solve cold: zero subdomain states, Ω₂ factorization dropped (offline data kept)."""
        self.sub[1].reset()
        for c0, u0 in self._prev:
            c0[:] = 0.0
            u0[:] = 0.0

    def _omega1_response(self, options: InterfaceNewtonOptions):
        """Ω₁'s affine trace response (fine Ω₁: back-solves with its factorization)."""
        self.prepare()
        return FineResponse(MixedPart(self.sub[0], perm=None, contact=False), chunk=options.chunk)

    def interface_problem(self, options: InterfaceNewtonOptions):
        """The affine pieces for ``hybrid.interface_newton`` (built once); with friction on Γ_C the
        ``"interface"`` strategy (Newton on F(g) = g − T(g) with Ω₂'s frictional Jacobian:
        ``options.interface_options``)."""
        options = interface_options(options, self.sub[1].friction, frictional_condensation=False)
        if self._newton is None or self._newton.options.strategy != options.strategy:
            perm = self._perm2 if self.comm.size == 1 else None  # (distributed: the canonical order)
            omega2 = MixedPart(self.sub[1], perm=perm, contact=True, factorize=options.strategy == "condensed")
            g0, g1 = self.sub[0].interface_range
            self._newton = InterfaceProblem(
                self._omega1_response(options),
                omega2,
                np.full(self.size_global, -2.0 * self.beta),
                1.0,
                self._gather,
                lambda v: np.asarray(v)[g0:g1],
                options,
            )
        return self._newton

    def _gather(self, block: np.ndarray) -> np.ndarray:
        """The interface values of all ranks (canonical order) from this rank's block (collective)."""
        return np.asarray(block) if self.comm.size == 1 else np.concatenate(self.comm.allgather(np.asarray(block)))

    def _measure(self) -> None:
        ds = du = ns = nu = 0.0
        for s, (c0, u0) in zip(self.sub, self._prev):
            ds += s.stress_norm2(s.c - c0)
            du += s.l2_norm2(s.u - u0)
            ns += s.stress_norm2(s.c)
            nu += s.l2_norm2(s.u)
            c0[:] = s.c
            u0[:] = s.u
        self._change = max(np.sqrt(ds / ns), np.sqrt(du / nu)) if ns > 0 and nu > 0 else np.inf

    def relative_change(self) -> float:
        return self._change

    def record(self) -> dict:
        return dict(self._record)

    # -- output ----------------------------------------------------------------------------
    def part_values(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per part: the DG P3 stress coefficients and the DG P1 displacement, in the part's numbering."""
        return [(s.sigma_function().x.array, s.u) for s in self.sub]

    def glued(self) -> tuple[fem.Function, fem.Function]:
        """σ (DG P3) and u (DG P1) on the parent mesh, each part's values (``part_values``) on its cells."""
        msh = self.cm.mesh
        el = basix.ufl.blocked_element(basix.ufl.element("DG", msh.basix_cell(), 3), shape=(3,))
        sigma = fem.Function(fem.functionspace(msh, el), name="sigma")
        u = fem.Function(fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 1, shape=(2,))), name="u")
        for part, s, (sv, uv) in zip(self.parts, self.sub, self.part_values()):
            i_sub, i_par = sub_to_parent_dofs(part, s.dg, sigma.function_space)
            sigma.x.array[i_par] = sv[i_sub]
            j_sub, j_par = sub_to_parent_dofs(part, s.U, u.function_space)
            u.x.array[j_par] = uv[j_sub]
        sigma.x.scatter_forward()
        u.x.scatter_forward()
        return sigma, u


@dataclass(slots=True)
class MixedHybridResult(IterationResult):
    """Fields, history, DOF counts, timings and errors of an Algorithm 2 solve."""

    sigma: fem.Function  #: DG P3 (σ_xx, σ_xy, σ_yy) on the parent mesh
    u: fem.Function  #: DG P1 on the parent mesh
    sigma1: fem.Function
    sigma2: fem.Function
    u1: fem.Function
    u2: fem.Function
    history: IterationHistory
    profile: MixedContactProfile
    dofs: dict
    time_offline_s: float
    time_online_s: float
    e_sigma: float | None
    e_u: float | None
    beta: float
    epsilon: float
    step: MixedHybridStep
    time_interface_offline_s: float = 0.0  #: offline interface response of the Newton method (in time_offline_s)


def solve_mixed_hybrid(
    problem: ContactProblem,
    *,
    beta: float | str = DEFAULT_BETA,
    epsilon: float | None = None,
    options: IterationOptions = IterationOptions(),
    newton: NewtonOptions = NewtonOptions(),
    reference: MixedSolution | None = None,
    initial_data: np.ndarray | None = None,
    step: MixedHybridStep | None = None,
) -> MixedHybridResult:
    """Algorithm 2 until the transmission residual is below ``options.tol``; ``reference`` adds e_σ, e_u
    (per iteration, outside the online time, and final).

    ``epsilon`` defaults to ``fem.mixed.default_epsilon`` (pass the reference's ε when comparing).
    ``initial_data`` warm-starts the interface data; ``step`` reuses a step (and its offline data).
    """
    check_solve_inputs(problem, options=options, newton=newton)
    if reference is not None:
        check_reference_mixed(reference, problem.cm)
    start = time.perf_counter()
    if reference is not None and epsilon is None:
        epsilon = reference.epsilon
    if step is None:
        step = MixedHybridStep(problem, beta=beta, epsilon=epsilon, newton=newton)
    step.prepare()
    offline = time.perf_counter() - start
    if reference is not None:  # not part of the method: outside the timings
        step.set_reference(reference)
    monitor = None
    if step.reference is not None:
        monitor = lambda: dict(zip(("e_sigma", "e_u"), step.errors()))  # noqa: E731
    history = iterate(step, options, name="mixed hybrid", monitor=monitor, initial=initial_data)
    sigma, u = step.glued()
    s1, s2 = step.sub
    dofs = {
        "omega1": s1.num_dofs["total"],
        "omega2": s2.num_dofs["total"],
        "interface": 2 * step.size_global,
    }
    e_sigma, e_u = step.errors() if step.reference is not None else (None, None)
    return MixedHybridResult(
        sigma,
        u,
        s1.sigma_function(),
        s2.sigma_function(),
        s1.u_function(),
        s2.u_function(),
        history,
        s2.contact_profile(),
        dofs,
        offline + history.time_offline_s,
        history.time_s,
        e_sigma,
        e_u,
        step.beta,
        step.epsilon,
        step,
        history.time_offline_s,
    )
