"""Argument checks shared by the ``solve_*_hybrid`` functions: misuse is an InputError / MeshTagError.

Called first in every solve (before any collective work), so a wrong type, a
mesh without tags, a load that vanishes on the mesh or a reference solution on
another mesh gives a clear package error instead of an AttributeError deep
inside, a "non-finite values" ConvergenceError, or a silently wrong e_u.
"""

from dolfinx import fem

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import MixedSolution
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.validation import require_tag_counts

__all__ = ["check_solve_inputs", "check_reference_displacement", "require_instance"]


def require_instance(value, cls, what: str, hint: str = "") -> None:
    """InputError unless ``value`` is a ``cls``."""
    if not isinstance(value, cls):
        raise InputError(f"{what} must be a {cls.__name__}{hint}, got {type(value).__name__}")


def check_solve_inputs(
    problem: ContactProblem,
    *,
    options: IterationOptions,
    newton: NewtonOptions,
    require_load: bool = True,
) -> None:
    """Types of the common arguments, the tags of the problem's mesh, and a load that does not vanish on it."""
    require_instance(
        problem,
        ContactProblem,
        "the problem",
        " (problem.models.model_1/2/3(...).on(mesh), or ContactProblem(..., mesh=mesh))",
    )
    require_instance(problem.cm, ContactMesh, "the mesh", " (from geometry.unit_square or geometry.read_mesh)")
    require_instance(options, IterationOptions, "options", " (hybrid.iteration.IterationOptions)")
    require_instance(newton, NewtonOptions, "newton", " (fem.contact.NewtonOptions)")
    require_tag_counts(problem.cm)
    if require_load:
        problem.check_loaded()


def _require_problem_mesh(V: fem.FunctionSpace, cm: ContactMesh) -> None:
    if V.mesh is not cm.mesh:
        raise InputError(
            "the reference solution lives on another mesh "
            f"({V.mesh.topology.index_map(V.mesh.topology.dim).size_global} cells) than the problem "
            f"({cm.mesh.topology.index_map(cm.mesh.topology.dim).size_global} cells): solve the monolithic "
            "problem on cm.mesh"
        )


def check_reference_mixed(reference, cm: ContactMesh) -> None:
    """A mixed reference must be a MixedSolution on the problem's own mesh."""
    require_instance(reference, MixedSolution, "the reference", " (from fem.mixed.solve_mixed_monolithic)")
    _require_problem_mesh(reference.u.function_space, cm)


def check_reference_displacement(reference, cm: ContactMesh) -> None:
    """A reference displacement must be a vector P1 function on the problem's own mesh."""
    require_instance(
        reference, fem.Function, "the reference", " (the displacement of solve_primal_monolithic: pass its .u)"
    )
    V = reference.function_space
    _require_problem_mesh(V, cm)
    element = V.ufl_element()
    gdim = cm.mesh.geometry.dim
    if tuple(V.value_shape) != (gdim,) or element.degree != 1 or element.discontinuous:
        raise InputError(
            f"the reference must be a continuous P1 vector function (value shape ({gdim},)), got "
            f"degree {element.degree}, value shape {tuple(V.value_shape)}"
        )
