"""Mixed (Arnold–Winther × DG P1) penalized contact: the monolithic solve and its defaults.

Find (σ_h, u_h) ∈ X_h × U_h with

    (Aσ_h, τ) + (div τ, u_h) + (1/ε) ∫_ΓC (σ_hc)⁺ τ_c ds [+ β∫_γ (σ_h n)·(τn) ds] = [∫_γ g·(τn) ds]
    (div σ_h, v) = −(f, v)

X_h: lowest-order Arnold–Winther stresses with σ_t = t·σn = 0 on Γ_C built in
(essential); U_h: discontinuous vector P1.  u = 0 on Γ_D is natural.  The subproblem on one mesh is
``mixed_subproblem.MixedSubproblem`` (spaces ``mixed_spaces``, operators ``mixed_assembly``, γ
``mixed_interface``, Γ_C and the penalty ``mixed_contact``, factorization ``mixed_linear``, globalized
semismooth Newton ``mixed_newton``); this module solves it on the whole mesh.

**Penalty.**  The natural boundary term says u_c = −(σ_c)⁺/ε on Γ_C: where the
body presses on the obstacle (σ_c ≤ 0) u_c = 0 exactly; where it separates, a
small tensile stress σ_c = ε|u_c| remains.  So the mixed penalty never lets
the body penetrate; its error is the tensile stress left in the gap.  The
default ε = 1e−3·h·E_c (E_c the smallest Young's modulus on Γ_C: ``default_epsilon``) mirrors the
primal default δ = 1e−3·h/E_c: the tensile stress relative to the stress
scale is ε|u_c|/σ ≈ ε/E_c = 1e−3·h, far below the stress discretization error
(≥ h^{3/2} with the contact singularity).  ``MixedContactProfile.max_tensile``
reports what is left.  The monolithic solve ends with a check of the residual assembled from the UFL
forms (``mixed_residual``).

**Interface split.**  ``split_interface=True`` enlarges X_h by doubling σ_tt at
the vertices of γ (Ω₁ and Ω₂ keep their own tangential-tangential
stress there; the normal traction σn stays continuous).  That space X̃_h is
exactly the space of the converged iterate of Algorithm 2 (see
``hybrid.mixed``), so this monolithic solve is its exact fixed point.

**Friction.**  With a friction law (``problem.law``) σn·t is free on Γ_C and the law acts on the tangential
traction (``fem.mixed_friction``); ``fenics_contact.slide`` runs load paths.

**MPI.**  Everything runs on a distributed mesh (``mpiexec -n N``): the AW space
numbers its DOFs globally (``fem.arnold_winther``), the operators are distributed
PETSc matrices, MUMPS factorizes the saddle-point matrix in parallel.  The Γ_C node
data are small and replicated, so every rank takes the same Newton decisions (active
set, cycle detection, line-search step) from the same numbers; every scalar of the
iteration (energy, residual, step) is a global reduction.  With N ranks the Newton
steps, active sets and solution are those of the serial run (to round-off; tested
for N = 2, 3 in ``tests/fem/test_mpi_mixed.py``).
"""

import logging
import time
from dataclasses import dataclass

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed_contact import MixedContactProfile
from fenics_contact.fem.mixed_newton import MixedNewtonHistory
from fenics_contact.fem.mixed_spaces import boundary_stress_space, check_triangles
from fenics_contact.fem.mixed_subproblem import MixedSubproblem
from fenics_contact.problem.friction import friction_of
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = [
    "MixedSolution",
    "contact_modulus",
    "default_epsilon",
    "epsilon_hint",
    "epsilon_for",
    "monolithic_subproblem",
    "solve_mixed_monolithic",
]

log = logging.getLogger(__name__)


def default_epsilon(h: float, E_contact: float, factor: float = 1.0e-3, length: float = 1.0) -> float:
    """ε = factor·(h/L_ref)·E_c/L_ref (a stress per length, as 1/ε multiplies σ_c in a traction–displacement law),
    with E_c the *smallest* E on Γ_C (``contact_modulus(..., smallest=True)``) and L_ref = ``length`` the body's
    size (``ContactProblem.length``; 1 on the unit square, where ε = factor·h·E_c).

    Where the body separates, the wall holds it with a tensile spring of stiffness ε (σ_c = −ε u_c):
    against a material of modulus E the tensile stress left is ≈ ε L_ref/E relative, factor·h/L_ref for the
    softest material on Γ_C.  With the largest E instead, a soft part of a heterogeneous Γ_C stayed glued to the
    wall: model 3 at contrast 10⁶ (stiff channels reaching Γ_C), h = 1/32, gave a contact force 20 % below
    the primal one and a tensile σ_c of 0.22; a bar pulled off the wall with one stiff stripe kept 27 % of
    its load on the wall."""
    if not (h > 0 and E_contact > 0 and factor > 0 and length > 0):
        raise InputError(f"default_epsilon needs h, E_c, factor, L_ref > 0; got {h}, {E_contact}, {factor}, {length}")
    return factor * (h / length) * E_contact / length


def epsilon_hint(epsilon: float, default: float) -> str:
    """What a failed mixed solve adds to its message when ε < 1e-3·``default``: the penalty weights w/ε then
    dwarf the stress block, so the saddle-point solves lose digits in proportion (empty otherwise)."""
    if not epsilon < 1e-3 * default:
        return ""
    return (
        f"; ε = {epsilon:g} is {default / epsilon:.0e} times below the default 1e-3·(h/L)·E_min/L = {default:.3g} "
        "on Gamma_C, which makes the contact block ill-conditioned: use a larger --epsilon"
    )


def contact_modulus(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, E: fem.Function, *, smallest: bool = False) -> float:
    """Largest (``smallest``: smallest) Young's modulus of the cells touching Γ_C (over all ranks)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    facets = facet_tags.find(Boundary.GAMMA_C)
    cells = np.unique(np.concatenate([f2c.links(f) for f in facets] or [[]])).astype(np.int32)
    if msh.comm.allreduce(int(cells.size), op=MPI.SUM) == 0:
        raise InputError("the mesh has no Γ_C facets")
    if smallest:
        return float(msh.comm.allreduce(float(np.min(E.x.array[cells], initial=np.inf)), op=MPI.MIN))
    return float(msh.comm.allreduce(float(np.max(E.x.array[cells], initial=-np.inf)), op=MPI.MAX))


@dataclass(slots=True)
class MixedSolution:
    """The monolithic mixed penalized solution with its Newton history and contact profile."""

    sigma: fem.Function  #: DG P3 (σ_xx, σ_xy, σ_yy)
    u: fem.Function  #: DG P1 vector
    newton: MixedNewtonHistory
    profile: MixedContactProfile
    epsilon: float
    dofs: dict
    time_s: float  #: setup + Newton
    time_newton_s: float  #: Newton only (the online part)
    problem: MixedSubproblem | None  #: None once ``free()`` has been called
    split_interface: bool

    def free(self) -> None:
        """Release the monolithic problem (its matrices and MUMPS factors); the solution, history and profile stay.

        A reference solve keeps GBs at h = 1/128 otherwise (the factors of the whole mixed problem).
        """
        if self.problem is not None:
            self.problem.destroy()
            self.problem = None


def epsilon_for(problem: ContactProblem, epsilon: float | None = None) -> float:
    """ε, or when None the default ``default_epsilon(h, E_c, length=L_ref)`` with E_c the smallest E on Γ_C and
    L_ref the body's size (``ContactProblem.length``)."""
    if epsilon is None:
        return default_epsilon(problem.h, problem.contact_modulus(smallest=True), length=problem.length)
    if (
        isinstance(epsilon, bool)
        or not isinstance(epsilon, (int, float, np.number))
        or not (np.isfinite(epsilon) and epsilon > 0)
    ):
        raise InputError(f"the mixed penalty ε must be a finite number > 0 (or None: the default), got {epsilon!r}")
    return float(epsilon)


def monolithic_subproblem(
    problem: ContactProblem,
    *,
    epsilon: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    split_interface: bool = False,
    prefix: str = "fc_mixed_mono_",
) -> MixedSubproblem:
    """The mixed subproblem of the whole mesh (contact, no Robin term) with the problem's friction law; on X̃_h with
    ``split_interface`` (``solve_mixed_monolithic``)."""
    friction = friction_of(problem.law)
    cm = problem.cm
    check_triangles(cm.mesh)
    space = None
    if split_interface:
        split = (cm.facet_tags.find(Boundary.INTERFACE), cm.cell_tags.find(Subdomain.OMEGA2))
        space = boundary_stress_space(
            cm.mesh, cm.facet_tags, problem.fields.boundary, split_interface=split, friction=friction is not None
        )
    return MixedSubproblem(
        cm.mesh,
        cm.facet_tags,
        problem.fields,
        epsilon=epsilon_for(problem, epsilon),
        beta=None,
        prefix=prefix,
        newton=newton,
        space=space,
        friction=friction,
    )


def solve_mixed_monolithic(
    problem: ContactProblem,
    *,
    epsilon: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    split_interface: bool = False,
    prefix: str = "fc_mixed_mono_",
    verify: bool = True,
) -> MixedSolution:
    """Mixed penalized contact on the whole mesh, globalized semismooth Newton (serial or MPI).

    ``epsilon`` defaults to ``default_epsilon(h, E_c)``; ``split_interface`` solves on X̃_h
    (σ_tt doubled at the γ vertices: the exact fixed point of Algorithm 2); ``verify``
    re-checks the final residual with the UFL forms.  A friction law (``problem.law``) makes σn·t on Γ_C an unknown
    of the law on the traction (``fem.mixed_friction``); the solve is one load step from the unloaded state
    (``fenics_contact.sliding`` for load paths).
    """
    start = time.perf_counter()
    usual = epsilon_for(problem)
    sub = monolithic_subproblem(problem, epsilon=epsilon, newton=newton, split_interface=split_interface, prefix=prefix)
    epsilon = sub.epsilon
    t0 = time.perf_counter()
    try:  # every numerical failure of the solve and of its check says when ε is far below its default
        history = sub.solve()
        t_newton = time.perf_counter() - t0
        if verify:
            norm, scale = sub.ufl_residual_norm()
            if norm > newton.rtol * scale + newton.atol:
                raise ConvergenceError(
                    f"mixed monolithic: the solution misses its own equations (UFL residual "
                    f"{norm:.3e} > {newton.rtol:g}·{scale:.3e}, the size of their terms): the "
                    "linear solves lost accuracy"
                )
    except ConvergenceError as err:
        raise ConvergenceError(f"{err}{epsilon_hint(epsilon, usual)}") from err
    elapsed = time.perf_counter() - start
    profile = sub.contact_profile()
    log.info(
        "monolithic mixed (ε = %.3g%s): %d Newton steps, step lengths %s, contact points %s, "
        "max tensile σ_c %.3e, %.2f s",
        epsilon,
        ", split γ" if split_interface else "",
        history.steps,
        [round(t, 3) for t in history.step_lengths],
        history.active_sizes,
        profile.max_tensile,
        elapsed,
    )
    return MixedSolution(
        sub.sigma_function(),
        sub.u_function(),
        history,
        profile,
        epsilon,
        sub.num_dofs,
        elapsed,
        t_newton,
        sub,
        split_interface,
    )
