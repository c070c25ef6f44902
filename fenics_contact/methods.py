"""The methods by name: what can be run on a ``ContactProblem``, with which options, built by one factory.

=====================  ==========  =============================================================
name                   algorithm   what it solves
=====================  ==========  =============================================================
``primal-monolithic``  —           penalized primal P1 contact on the whole mesh (semismooth Newton)
``mixed-monolithic``   —           penalized mixed Arnold–Winther contact on the whole mesh
``primal``             1           primal P1 in Ω₁ and Ω₂, Robin transmission on γ
``mixed``              2           mixed Arnold–Winther in Ω₁ and Ω₂
``primal-ms``          3           primal CEM-GMsFEM in Ω₁, primal P1 in Ω₂
``mixed-ms``           4           mixed CEM-GMsFEM in Ω₁, mixed Arnold–Winther in Ω₂
=====================  ==========  =============================================================

Every method is one entry of ``METHODS``; the command line, case files and load steps look
methods up here. A method's options and their defaults are the keyword-only parameters of its
solve function (written once there, with the named constants ``DEFAULT_ALPHA``, ``DEFAULT_BETA``…);
``Method.options`` also takes them flat, as the command line and case files give them
(``tol``, ``accel``, ``max_iterations`` for the iteration; ``layers``, ``nbasis``, ``min_gap``,
``max_nbasis`` for the multiscale space), and refuses an option the method does not use.

    result = solve(problem, "primal", tol=1e-8)          # Algorithm 1 with its defaults otherwise
    step = METHODS["primal-ms"].build(problem, layers=4)  # the offline phase, kept for many solves
"""

import dataclasses
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import monolithic_subproblem, solve_mixed_monolithic
from fenics_contact.fem.mixed_subproblem import MixedSubproblem
from fenics_contact.fem.primal import PrimalSubproblem, penalty_for, solve_primal_monolithic, warn_if_locking
from fenics_contact.fem.two_body import solve_two_body
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid
from fenics_contact.hybrid.options import InterfaceNewtonOptions, IterationOptions, default_accel
from fenics_contact.hybrid.primal import PrimalHybridStep, solve_primal_hybrid
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions, solve_two_body_hybrid
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep, solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.multiscale.pair import PairMultiscaleOptions, solve_two_body_ms_hybrid
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep, solve_primal_ms_hybrid
from fenics_contact.problem.friction import friction_of
from fenics_contact.problem.pair import TwoBodyProblem
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.validation import require_method_dimension

__all__ = ["METHODS", "Method", "MonolithicSolver", "get_method", "solve"]

#: keyword parameters of the solve functions that are not options of the method
_NOT_OPTIONS = ("reference", "initial_data", "step", "offline_comm", "prefix", "verify", "split_interface")
#: flat option names and the nested options they set: name -> (parameter of the solve, field of its type)
_ITERATION_FIELDS = tuple(f.name for f in dataclasses.fields(IterationOptions) if f.name != "newton")
_INTERFACE_NEWTON_FIELDS = tuple(f.name for f in dataclasses.fields(InterfaceNewtonOptions))


class MonolithicSolver:
    """A monolithic penalized problem kept for many solves (load steps): its subproblem is the contact side."""

    def __init__(self, sub: PrimalSubproblem | MixedSubproblem) -> None:
        self.contact = sub

    def solve(self):
        """One semismooth Newton solve (warm-started from the last solution)."""
        return self.contact.solve()


def _primal_monolithic_solver(
    problem: ContactProblem,
    *,
    delta: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    solver: LinearSolverOptions | str = "auto",
) -> MonolithicSolver:
    fields = problem.fields
    warn_if_locking(fields.nu, problem.comm)
    cm = problem.cm
    return MonolithicSolver(
        PrimalSubproblem(
            cm.mesh,
            cm.facet_tags,
            fields,
            delta=penalty_for(problem, delta),
            alpha=None,
            prefix="fc_steps_primal_",
            newton=newton,
            friction=friction_of(problem.law),
            solver=solver,
        )
    )


def _mixed_monolithic_solver(
    problem: ContactProblem,
    *,
    epsilon: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    split_interface: bool = False,
) -> MonolithicSolver:
    """``split_interface``: on X̃_h (σ_tt split at the γ vertices), the exact fixed point of Algorithm 2."""
    return MonolithicSolver(
        monolithic_subproblem(
            problem, epsilon=epsilon, newton=newton, split_interface=split_interface, prefix="fc_steps_mixed_"
        )
    )


def _prepared(step_class: type) -> Callable:
    def build(problem: ContactProblem, **options):
        step = step_class(problem, **options)
        step.prepare()
        return step

    build.__wrapped__ = step_class  # (inspect.signature follows it: the step's options)
    return build


@dataclass(frozen=True, slots=True)
class Method:
    """One method of the catalogue: its name, what it is, its solve function and its step factory."""

    name: str
    family: str  #: "primal" (P1 displacements) or "mixed" (Arnold–Winther stresses)
    algorithm: int | None  #: 1–4 for the hybrid methods, None for the monolithic solves
    summary: str
    solve_function: Callable
    factory: Callable  #: (problem, options) -> a solver kept for many solves (load steps)
    cem_type: type | None = None  #: the multiscale options type (``cem=``), None for fine Ω₁

    @property
    def hybrid(self) -> bool:
        """Ω₁/Ω₂ with Robin transmission on γ (Algorithms 1–4)."""
        return self.algorithm is not None

    @property
    def multiscale(self) -> bool:
        """Ω₁ is a CEM-GMsFEM space built offline (Algorithms 3 and 4)."""
        return self.cem_type is not None

    def defaults(self) -> dict[str, Any]:
        """The method's options and their defaults (the keyword-only parameters of its solve function)."""
        params = inspect.signature(self.solve_function).parameters.values()
        return {p.name: p.default for p in params if p.kind is p.KEYWORD_ONLY and p.name not in _NOT_OPTIONS}

    def flat_options(self) -> tuple[str, ...]:
        """Every option name the method takes, flat (as ``options`` accepts them)."""
        names = list(self.defaults())
        if self.hybrid:
            names += [*_ITERATION_FIELDS, *_INTERFACE_NEWTON_FIELDS]
        if self.cem_type is not None:
            names += [f.name for f in dataclasses.fields(self.cem_type)]
        return tuple(dict.fromkeys(names))

    def default_accel(self, comm: MPI.Comm = MPI.COMM_WORLD) -> str | None:
        """The update of a hybrid method when none is given (``hybrid.options.default_accel``: the interface
        Newton, serially and under MPI); None for a monolithic one."""
        return default_accel(self.factory.__wrapped__, comm) if self.hybrid else None

    def options(
        self, values: Mapping[str, Any] | None = None, /, *, comm: MPI.Comm = MPI.COMM_WORLD, **more
    ) -> dict[str, Any]:
        """Keyword arguments for the solve function from flat or nested options (InputError for an option
        the method does not use). Not given: the method's defaults, ``accel`` from ``default_accel``."""
        given = {**(values or {}), **more}
        known = self.defaults()
        out = {k: v for k, v in given.items() if k in known}
        iteration = {k: given.pop(k) for k in list(given) if k in _ITERATION_FIELDS and self.hybrid}
        interface = {k: given.pop(k) for k in list(given) if k in _INTERFACE_NEWTON_FIELDS and self.hybrid}
        cem_fields = () if self.cem_type is None else [f.name for f in dataclasses.fields(self.cem_type)]
        cem = {k: given.pop(k) for k in list(given) if k in cem_fields}
        unknown = sorted(k for k in given if k not in known)
        if unknown:
            raise InputError(
                f"{self.name}: no option(s) {unknown}; {self.name} takes {list(self.flat_options())}"
                + _elsewhere(unknown)
            )
        if self.hybrid:
            nested = out.get("options")
            if nested is not None and (iteration or interface):
                raise InputError(
                    f"{self.name}: give the iteration either as options=IterationOptions(...) or as "
                    f"{sorted({*iteration, *interface})}, not both"
                )
            if nested is None:
                if interface:
                    iteration["newton"] = InterfaceNewtonOptions(**interface)
                out["options"] = IterationOptions(**iteration)
        if cem:
            if out.get("cem") is not None:
                raise InputError(
                    f"{self.name}: give the multiscale options either as cem={self.cem_type.__name__}"
                    f"(...) or as {sorted(cem)}, not both"
                )
            out["cem"] = self.cem_type(**cem)
        if out.get("cem") is not None and not isinstance(out["cem"], self.cem_type):
            where = self.cem_type.__module__.removeprefix("fenics_contact.")
            raise InputError(f"{self.name} takes {where}.{self.cem_type.__name__}, got {type(out['cem']).__name__}")
        return out

    def solve(self, problem: ContactProblem, /, *, comm: MPI.Comm = MPI.COMM_WORLD, **values):
        """Solve ``problem`` with this method (``values``: its options, flat or nested, and the solve's own
        keyword arguments such as ``reference``)."""
        if isinstance(problem, TwoBodyProblem):
            return _solve_two_bodies(self.name, problem, values)
        _require_dimension(self.name, problem)
        extra = {k: values.pop(k) for k in list(values) if k in _NOT_OPTIONS}
        return self.solve_function(problem, **self.options(values, comm=comm), **extra)

    def build(self, problem: ContactProblem, /, *, comm: MPI.Comm = MPI.COMM_WORLD, **values):
        """The solver kept for many solves (``factory``): a prepared hybrid step, or a ``MonolithicSolver``;
        its ``contact`` is the subproblem holding Γ_C."""
        if isinstance(problem, TwoBodyProblem):
            raise InputError(
                f"{self.name}: two-body problems are solved once, by solve(problem, 'primal-monolithic') or "
                "solve(problem, 'primal') (Algorithm 1); build() keeps a one-body problem for many solves"
            )
        _require_dimension(self.name, problem)
        extra = {k: values.pop(k) for k in list(values) if k in _NOT_OPTIONS}
        options = self.options(values, comm=comm) | extra
        accepted = inspect.signature(self.factory).parameters
        refused = sorted(k for k in extra if k not in accepted)
        if refused:
            raise InputError(f"{self.name}: the solver it builds takes no {refused}")
        return self.factory(problem, **{k: v for k, v in options.items() if k in accepted})

    def iteration(
        self, values: Mapping[str, Any] | None = None, *, comm: MPI.Comm = MPI.COMM_WORLD
    ) -> IterationOptions | None:
        """The hybrid iteration's options among ``values`` (None for a monolithic method; the build's own keywords
        such as ``offline_comm`` are left to ``build``)."""
        options = {k: v for k, v in (values or {}).items() if k not in _NOT_OPTIONS}
        return self.options(options, comm=comm).get("options") if self.hybrid else None


#: the options of the two-body solves: monolithic (``fem.two_body``) and Algorithm 1 (``hybrid.two_body``)
_TWO_BODY_OPTIONS = {
    "primal-monolithic": ("delta", "newton", "line_search", "state"),
    "primal": ("delta", "newton", "state", *(f.name for f in dataclasses.fields(TwoBodyHybridOptions))),
    "primal-ms": ("delta", "newton", "state", "H", "cem", *(f.name for f in dataclasses.fields(TwoBodyHybridOptions))),
}


def _solve_two_bodies(name: str, problem: TwoBodyProblem, values: Mapping[str, Any]):
    """The two-body solves: ``primal-monolithic``, ``primal`` (Algorithm 1; its options flat or as
    ``options=TwoBodyHybridOptions(…)``) and ``primal-ms`` (Algorithm 3: ``H`` and ``cem=CEMOptions(…)`` besides);
    InputError for the other methods and for other options."""
    if name not in _TWO_BODY_OPTIONS:
        raise InputError(
            f"{name} cannot solve two deformable bodies: the mixed contact law prescribes the normal displacement "
            "u_c = g − (σ_c)⁺/ε on Γ_C as natural boundary data of one stress; between two bodies that displacement "
            "is shared by two stresses and needs a displacement unknown on the contact surface (a mortar mixed "
            "method), which is not built; solve a TwoBodyProblem with 'primal-monolithic', 'primal' (Algorithm 1) "
            "or 'primal-ms' (Algorithm 3)"
        )
    accepted = _TWO_BODY_OPTIONS[name] + (("options",) if name != "primal-monolithic" else ())
    refused = sorted(set(values) - set(accepted))
    if refused:
        raise InputError(f"the two-body solve {name} takes the options {', '.join(accepted)}; got {refused}")
    if name == "primal-monolithic":
        return solve_two_body(problem, **values)
    kwargs = {k: values[k] for k in ("delta", "newton", "state") if k in values}
    own = ("delta", "newton", "state", "options", "H", "cem")
    flat = {k: v for k, v in values.items() if k not in own}
    options = values.get("options") or TwoBodyHybridOptions()
    if flat:
        options = dataclasses.replace(options, **flat)
    if name == "primal-ms":
        if "H" not in values:
            raise InputError("primal-ms for two bodies needs H, the coarse cell size of both bulks")
        multiscale = PairMultiscaleOptions(values["H"], values.get("cem") or CEMOptions())
        return solve_two_body_ms_hybrid(problem, multiscale, options=options, **kwargs)
    return solve_two_body_hybrid(problem, options=options, **kwargs)


def _require_dimension(name: str, problem) -> None:
    """InputError when the method ``name`` does not solve a problem of this dimension or with rollers."""
    if isinstance(problem, ContactProblem) and problem.mesh is not None:
        require_method_dimension(name, problem.mesh.mesh, problem.boundary)


def _elsewhere(names: list[str]) -> str:
    """Which methods take the options ``names`` (for the message of a refused option)."""
    users = {name: [m.name for m in METHODS.values() if name in m.flat_options()] for name in names}
    known = [f"{name} is an option of {', '.join(methods)}" for name, methods in users.items() if methods]
    return f" ({'; '.join(known)})" if known else ""


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method(
            "primal-monolithic",
            "primal",
            None,
            "penalized primal P1 contact on the whole mesh",
            solve_primal_monolithic,
            _primal_monolithic_solver,
        ),
        Method(
            "mixed-monolithic",
            "mixed",
            None,
            "penalized mixed Arnold–Winther contact on the whole mesh",
            solve_mixed_monolithic,
            _mixed_monolithic_solver,
        ),
        Method(
            "primal",
            "primal",
            1,
            "Algorithm 1: primal P1 in Ω₁ and Ω₂",
            solve_primal_hybrid,
            _prepared(PrimalHybridStep),
        ),
        Method(
            "mixed",
            "mixed",
            2,
            "Algorithm 2: mixed Arnold–Winther in Ω₁ and Ω₂",
            solve_mixed_hybrid,
            _prepared(MixedHybridStep),
        ),
        Method(
            "primal-ms",
            "primal",
            3,
            "Algorithm 3: primal CEM-GMsFEM in Ω₁, primal P1 in Ω₂",
            solve_primal_ms_hybrid,
            _prepared(MultiscalePrimalHybridStep),
            CEMOptions,
        ),
        Method(
            "mixed-ms",
            "mixed",
            4,
            "Algorithm 4: mixed CEM-GMsFEM in Ω₁, mixed Arnold–Winther in Ω₂",
            solve_mixed_ms_hybrid,
            _prepared(MixedMultiscaleHybridStep),
            MixedCEMOptions,
        ),
    )
}
#: the hybrid methods (Algorithms 1–4), the ``fenics-contact run --method`` choices
HYBRID_METHODS = tuple(name for name, m in METHODS.items() if m.hybrid)


def get_method(name: str) -> Method:
    """The method called ``name`` (InputError naming the methods otherwise)."""
    if name not in METHODS:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def solve(problem: ContactProblem, method: str = "primal", /, **options):
    """Solve ``problem`` with the method called ``method`` (``METHODS``) and its ``options``.

    Args:
        problem: the contact problem (``ContactProblem`` on its mesh: ``problem.on(mesh)``), or two bodies in
            contact (``TwoBodyProblem``: ``"primal-monolithic"``, options ``delta``, ``newton``, ``line_search``,
            a ``TwoBodySolution``; or ``"primal"``, Algorithm 1 with a strip on each side, options those of
            ``hybrid.two_body.TwoBodyHybridOptions``, a ``TwoBodyHybridResult``; or ``"primal-ms"``, Algorithm 3
            with a CEM-GMsFEM space in each bulk, options ``H`` and ``cem`` besides Algorithm 1's, serial; all take
            ``state``, the previous load step's ``.state``: its friction anchors and warm start).
        method: ``"primal-monolithic"``, ``"mixed-monolithic"``, ``"primal"`` (Algorithm 1), ``"mixed"``
            (Algorithm 2), ``"primal-ms"`` (Algorithm 3) or ``"mixed-ms"`` (Algorithm 4).
        **options: the method's options by name, flat (``tol=1e-8``, ``layers=4``, ``delta=…``) or as their
            option objects (``options=IterationOptions(…)``, ``cem=CEMOptions(…)``), and the solve's own
            keywords (``reference=…`` for the error against a fine solution); ``METHODS[method].defaults()``
            lists them with their defaults.

    Returns:
        The method's result: a ``PrimalSolution`` or ``MixedSolution`` for the monolithic solves, a
        ``HybridResult`` or ``MixedHybridResult`` for the hybrid ones (``converged``, ``history`` with the
        certificate, ``profile`` of the contact pressure along Γ_C, the fields, ``dofs``, timings).

    Raises:
        InputError: an unknown method or option, or a problem the method cannot solve (the message says why
            and what to do).
        ConvergenceError: a Newton solve failed (the monolithic solve, or a subproblem of a hybrid one); a
            hybrid iteration that reaches its iteration cap returns with ``converged`` False.
    """
    return get_method(method).solve(problem, **options)
