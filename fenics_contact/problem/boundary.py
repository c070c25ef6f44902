"""Boundary conditions of a contact problem, the same for every method.

* ``Gamma_D``: clamped, u = 0, or a prescribed displacement u = u_D.
* ``Gamma_N*`` groups (``tags.is_neumann_name``): a given traction σn = t, one per group.
* ``Gamma_C``: frictionless contact with the obstacle (``problem.obstacles``).
* every other exterior facet: traction free, σn = 0.

The primal methods impose u_D strongly and the tractions as loads ∫ t·v ds;
the mixed methods impose σn = t (and σn = 0) essentially in the stress space
and u_D as the natural term ∫_ΓD u_D·τn ds.  Fields are numpy callables
x (3, N) -> (2, N), or a constant 2-vector.

``BoundaryConditions`` travels with the problem (``ContactProblem.boundary``) and
through ``problem.fields.material_fields`` into every subproblem;
``check_boundary_groups`` matches it against a mesh's facet groups.
"""

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, is_neumann_name, neumann_tag

__all__ = [
    "VectorField",
    "BoundaryConditions",
    "constant_vector",
    "check_boundary_groups",
    "neumann_groups",
    "boundary_data_on",
]

#: A vector field: points x of shape (3, N) -> values of shape (2, N).
VectorField = Callable[[np.ndarray], np.ndarray]


def constant_vector(value: npt.ArrayLike) -> VectorField:
    """x ↦ value (a constant 2-vector, or a 3-vector for a 3D problem), as a vector field."""
    v = np.asarray(value, dtype=np.float64).ravel()
    if v.size not in (2, 3) or not np.all(np.isfinite(v)):
        raise InputError(f"a constant vector field needs two (three in 3D) finite numbers, got {value!r}")
    return lambda x: np.repeat(v[:, None], np.shape(x)[1], axis=1)


def _as_field(value, what: str) -> VectorField:
    if callable(value):
        return value
    try:
        return constant_vector(value)
    except (TypeError, ValueError) as err:
        raise InputError(
            f"{what} must be a callable x -> (gdim, N) or a constant vector (2 or 3 components), got {value!r}"
        ) from err


@dataclass(frozen=True, slots=True)
class BoundaryConditions:
    """u = ``displacement`` on Γ_D (None: clamped), σn = ``tractions[name]`` on each Γ_N group, u_i = 0 on the
    ``rollers`` planes x_i = c (tangential traction free), σn = 0 elsewhere.

    ``tractions`` maps group names (``Gamma_N``, ``Gamma_N_top``, ...) to a field or
    a constant 2-vector; it is stored as a tuple of (name, field) pairs, sorted by name.
    """

    displacement: VectorField | None = None
    tractions: Mapping[str, VectorField] | tuple = field(default_factory=tuple)
    #: symmetry planes (axis i, value c): u_i = 0 on the exterior facets in the plane x_i = c (rollers;
    #: the primal monolithic solve takes them)
    rollers: tuple[tuple[int, float], ...] = ()

    def __post_init__(self) -> None:
        rollers = []
        for item in self.rollers:
            try:
                axis, value = item
            except (TypeError, ValueError):
                raise InputError(
                    f"a roller is a pair (axis, value) for the plane x_axis = value, got {item!r}"
                ) from None
            if isinstance(axis, bool) or axis not in (0, 1, 2) or not np.isfinite(value):
                raise InputError(f"a roller plane needs an axis 0, 1 or 2 and a finite value, got {item!r}")
            rollers.append((int(axis), float(value)))
        object.__setattr__(self, "rollers", tuple(rollers))
        if self.displacement is not None:
            object.__setattr__(self, "displacement", _as_field(self.displacement, "the Gamma_D displacement"))
        items = self.tractions.items() if isinstance(self.tractions, Mapping) else self.tractions
        pairs = []
        for name, value in items:
            if not isinstance(name, str) or not is_neumann_name(name):
                raise InputError(
                    f"traction group {name!r}: a traction boundary is a facet group named 'Gamma_N' "
                    "or 'Gamma_N_<label>'"
                )
            pairs.append((name, _as_field(value, f"the traction on {name!r}")))
        names = [n for n, _ in pairs]
        if len(set(names)) != len(names):
            raise InputError(f"traction groups given twice: {sorted(names)}")
        object.__setattr__(self, "tractions", tuple(sorted(pairs, key=lambda p: p[0])))

    @property
    def clamped(self) -> bool:
        """True when Γ_D is clamped (u = 0)."""
        return self.displacement is None

    @property
    def is_default(self) -> bool:
        """Clamped Γ_D, no traction groups and no rollers."""
        return self.displacement is None and not self.tractions and not self.rollers

    def traction_tags(self) -> list[tuple[int, str, VectorField]]:
        """(facet tag, group name, traction) for every traction group."""
        return [(neumann_tag(name), name, t) for name, t in self.tractions]


def neumann_groups(facet_tags) -> list[int]:
    """The traction-group tags present (locally) in ``facet_tags``."""
    values = np.unique(facet_tags.values)
    standard = {int(t) for t in Boundary}
    return [int(v) for v in values if int(v) not in standard]


def check_boundary_groups(
    msh, facet_tags, boundary: BoundaryConditions, *, names: Mapping[int, str] | None = None
) -> None:
    """Match the traction data with the mesh's Γ_N groups (collective); MeshTagError / InputError naming the group.

    Every traction group of ``boundary`` must exist (non-empty) on the mesh, and every
    Γ_N group of the mesh must have a traction.  ``names`` maps the mesh's tags to
    group names (for the messages); by default the names of ``boundary`` are used.
    """
    comm = msh.comm
    given = {tag: name for tag, name, _ in boundary.traction_tags()}
    present = set().union(*comm.allgather(set(neumann_groups(facet_tags))))
    for tag, name in given.items():
        if comm.allreduce(int(facet_tags.find(tag).size), op=MPI.SUM) == 0:
            raise MeshTagError(
                f"a traction is given on the group {name!r}, but the mesh has no facets in a physical group of that "
                f"name (boundary groups: Gamma_D, Gamma_C, gamma and Gamma_N*)"
            )
    missing = sorted(present - set(given))
    if missing:
        labels = [(names or {}).get(t, f"tag {t}") for t in missing]
        raise InputError(
            f"the mesh has traction group(s) {labels} but the model gives no traction for them; "
            "give one (BoundaryConditions(tractions={name: (tx, ty)})) or remove the group (untagged = traction free)"
        )
    gdim = msh.geometry.dim
    fields = [("the Gamma_D displacement", boundary.displacement)] if boundary.displacement is not None else []
    fields += [(f"the traction on {name!r}", t) for name, t in boundary.tractions]
    point = np.ascontiguousarray(msh.geometry.x[:1].T)
    for what, value in fields:
        rows = np.shape(value(point))[0] if point.shape[1] else gdim
        if comm.allreduce(int(rows != gdim), op=MPI.SUM):
            raise InputError(f"{what} has {rows} components; the mesh is {gdim}D: give {gdim} components")
    if (
        boundary.displacement is not None
        and comm.allreduce(int(facet_tags.find(Boundary.GAMMA_D).size), op=MPI.SUM) == 0
    ):
        raise MeshTagError(
            f"a displacement is prescribed on {PHYSICAL_NAMES[Boundary.GAMMA_D]!r}, but that group has no facets"
        )


def boundary_data_on(msh, facet_tags, boundary: BoundaryConditions, *, traction_free: bool = False) -> list[str]:
    """What boundary data act on this (sub)mesh besides clamping (collective): for methods that cannot take them yet.

    Lists 'a prescribed displacement on Gamma_D', 'a traction on <group>' and, with
    ``traction_free``, 'traction-free sides' (exterior facets in no group other than γ).
    """
    comm = msh.comm
    found = []
    if boundary.displacement is not None and comm.allreduce(int(facet_tags.find(Boundary.GAMMA_D).size), op=MPI.SUM):
        found.append("a prescribed displacement on Gamma_D")
    for tag, name, _ in boundary.traction_tags():
        if comm.allreduce(int(facet_tags.find(tag).size), op=MPI.SUM):
            found.append(f"a traction on {name}")
    if boundary.rollers:
        found.append("rollers (symmetry planes)")
    if traction_free:
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        exterior = dmesh.exterior_facet_indices(msh.topology)
        free = np.setdiff1d(exterior, facet_tags.indices)
        if comm.allreduce(int(free.size), op=MPI.SUM):
            found.append("traction-free sides")
    return found
