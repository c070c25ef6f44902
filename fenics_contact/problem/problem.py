"""The contact problem a user describes: one validated ``ContactProblem``.

A problem is a body — its tagged mesh (``geometry.ContactMesh``), Young's modulus E(x) and
Poisson ratio ν(x), body force f(x), boundary conditions (Γ_D displacement, Γ_N tractions) —
and what it touches on Γ_C: a rigid obstacle (``problem.obstacles``; None: a wall flush with
Γ_C) through a contact law (``Frictionless``, or ``problem.friction.Friction``: Tresca or Coulomb).
Every solver takes a problem, and only a problem: the monolithic solves, Algorithms 1–4 and the load steps alike.

The physics can be given before the mesh (``model_1()``, or ``ContactProblem(youngs_modulus=…)``)
and put on a mesh with ``problem.on(mesh)``; a problem on a mesh is validated once, there (the
boundary groups against the mesh's facet groups, E > 0 and ν ∈ (−1, ½) on every cell), and its
cellwise material fields are built once per mesh (``fields``, ``fields_on``): the subproblems,
the CLI and the load steps share them. The dimension is the mesh's: triangles (plane strain) or
tetrahedra (3D; ``problem.meshes3d``, ``geometry.read_mesh``), loads and boundary data with as many
components.
"""

import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem import strip, validation
from fenics_contact.problem.boundary import BoundaryConditions, check_boundary_groups
from fenics_contact.problem.fields import FunctionField, MaterialFields, material_fields, tag_function, zero_load
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import ContactMesh, mesh_extent, mesh_size
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.tags import Boundary, neumann_tag
from fenics_contact.problem.validation import require_facet_groups

__all__ = [
    "ContactProblem",
    "ContactLaw",
    "Friction",
    "Frictionless",
    "ScalarField",
    "VectorField",
    "constant_field",
    "zero_load",
]

#: A scalar field: points x of shape (3, N) -> values of shape (N,).
ScalarField = Callable[[np.ndarray], np.ndarray]
#: A vector field: points x of shape (3, N) -> values of shape (gdim, N) (2 on triangles, 3 on tetrahedra).
VectorField = Callable[[np.ndarray], np.ndarray]


def constant_field(value: float) -> ScalarField:
    """x ↦ value, as a scalar field."""
    return lambda x: np.full(x.shape[1], float(value))


@dataclass(frozen=True, slots=True)
class Frictionless:
    """Frictionless unilateral contact on Γ_C: u·ν ≤ g, σ_c ≤ 0, σ_c (u·ν − g) = 0, σ_t = 0."""

    name = "frictionless"


#: The contact laws a problem can carry: frictionless, or a penalized friction law (``problem.friction``).
ContactLaw = Frictionless | Friction


def _scalar(value, what: str) -> ScalarField:
    if isinstance(value, fem.Function):
        return FunctionField(value)
    if callable(value):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
        raise InputError(f"{what} must be a callable x (3, N) -> (N,) or a finite number, got {value!r}")
    return constant_field(float(value))


def _vector(value, what: str) -> VectorField:
    if isinstance(value, fem.Function):
        return FunctionField(value)
    if callable(value):
        return value
    v = np.asarray(value, dtype=np.float64).ravel() if not isinstance(value, str) else np.array([])
    if v.size not in (2, 3) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} must be a callable x (3, N) -> (gdim, N) or a constant vector, got {value!r}")
    return lambda x: np.repeat(v[:, None], x.shape[1], axis=1)


#: the fields that describe the materials and the load: a change of any of them rebuilds the cellwise fields
_MATERIAL_FIELDS = ("youngs_modulus", "poisson_ratio", "load")


@dataclass(frozen=True, eq=False)
class ContactProblem:
    """A body in contact with a rigid obstacle: mesh, E(x), ν(x), body force f(x), boundary conditions, obstacle.

    ``youngs_modulus``, ``poisson_ratio``: numbers or callables x (3, N) -> (N,); ``load``: a constant
    vector or a callable x (3, N) -> (gdim, N) (default zero); ``boundary``: Γ_D displacement and Γ_N
    tractions (default: Γ_D clamped; every other exterior facet traction free); ``obstacle``: the rigid
    obstacle facing Γ_C (None: a wall flush with Γ_C, zero gap); ``law``: the contact law on Γ_C;
    ``mesh``: the tagged mesh (None until ``on(mesh)``). Validated on construction (InputError /
    MeshTagError naming what is wrong).
    """

    youngs_modulus: ScalarField
    poisson_ratio: ScalarField
    load: VectorField = zero_load
    boundary: BoundaryConditions = BoundaryConditions()
    obstacle: Obstacle | None = None
    law: ContactLaw = Frictionless()
    mesh: ContactMesh | None = None
    name: str = "problem"
    description: str = ""
    _fields: weakref.WeakKeyDictionary = field(default_factory=weakref.WeakKeyDictionary, init=False, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "youngs_modulus", _scalar(self.youngs_modulus, "youngs_modulus (E)"))
        set_(self, "poisson_ratio", _scalar(self.poisson_ratio, "poisson_ratio (nu)"))
        set_(self, "load", _vector(self.load, "the body force (load)"))
        if not isinstance(self.boundary, BoundaryConditions):
            raise InputError(
                f"ContactProblem.boundary must be a BoundaryConditions, got {type(self.boundary).__name__}"
            )
        if self.obstacle is not None and not isinstance(self.obstacle, Obstacle):
            raise InputError(f"ContactProblem.obstacle must be an Obstacle or None, got {type(self.obstacle).__name__}")
        if not isinstance(self.law, (Frictionless, Friction)):
            raise InputError(
                f"ContactProblem.law must be a contact law (Frictionless or Friction), got {type(self.law).__name__}"
            )
        if not isinstance(self.name, str) or not isinstance(self.description, str):
            raise InputError("ContactProblem.name and .description must be strings")
        if self.mesh is not None:
            if not isinstance(self.mesh, ContactMesh):
                raise InputError(
                    f"ContactProblem.mesh must be a ContactMesh (geometry.unit_square, read_mesh, …), "
                    f"got {type(self.mesh).__name__}"
                )
            require_facet_groups(self.mesh.mesh, self.mesh.facet_tags, ())  # facet tags (not e.g. the cell tags)
            check_boundary_groups(self.mesh.mesh, self.mesh.facet_tags, self.boundary, names=self.mesh.neumann_names)
            self.fields_on(self.mesh.mesh)  # E > 0 and ν ∈ (−1, ½) on every cell, checked once, here

    # -- building problems ---------------------------------------------------------------------
    @classmethod
    def from_meshtags(
        cls,
        mesh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        cell_tags: dmesh.MeshTags | None = None,
        *,
        contact: int | Sequence[int],
        clamped: int | Sequence[int],
        youngs_modulus,
        poisson_ratio,
        load=zero_load,
        displacement=None,
        tractions: Mapping[int, object] | None = None,
        obstacle: Obstacle | None = None,
        strip_cells: int | Sequence[int] | None = None,
        H: float | None = None,
        strip_width: float | None = None,
        name: str = "problem",
        description: str = "",
    ) -> "ContactProblem":
        """A problem on a DOLFINx mesh with its own tags (e.g. from ``dolfinx.io.gmsh.model_to_mesh``).

        ``contact``, ``clamped``: the facet tag(s) of Γ_C and Γ_D; ``tractions``: facet tag -> traction
        (σn = t there; a constant vector or a callable); ``displacement``: u on Γ_D (default 0).
        ``youngs_modulus``, ``poisson_ratio``: a number, a callable x (3, N) -> (N,), a ``dolfinx.fem.Function``
        or ``{cell tag: value}`` (needs ``cell_tags``). The strip Ω₂ along Γ_C and the interface γ are
        built (``strip.automatic_split``: of width ``strip_width``, default H, or a few contact cells
        without H; with ``H`` also the coarse cells of the multiscale methods); or give Ω₂ yourself as the
        cells of the tag(s) ``strip_cells`` (γ is then its boundary with the rest).
        """
        if not isinstance(facet_tags, dmesh.MeshTags) or facet_tags.dim != mesh.topology.dim - 1:
            raise InputError(f"facet_tags must be the facet MeshTags of the mesh (dimension {mesh.topology.dim - 1})")
        _require_entities_of(mesh, facet_tags, "facet_tags")
        if cell_tags is not None:
            _require_entities_of(mesh, cell_tags, "cell_tags")
        tractions = dict(tractions or {})
        groups = [
            (_tags(contact, "contact"), int(Boundary.GAMMA_C)),
            (_tags(clamped, "clamped"), int(Boundary.GAMMA_D)),
        ]
        names = {neumann_tag(f"Gamma_N_{int(t)}"): f"Gamma_N_{int(t)}" for t in tractions}
        groups += [((int(t),), tag) for t, tag in zip(tractions, names)]
        tags = _retagged(mesh, facet_tags, groups)
        if strip_cells is not None:
            if cell_tags is None:
                raise InputError("strip_cells names cell tags: give cell_tags")
            in_strip = np.isin(cell_tags.values, _tags(strip_cells, "strip_cells"))
            mask = np.zeros(_num_cells(mesh), dtype=bool)
            mask[cell_tags.indices[in_strip]] = True
            cell_omega, tags = strip.strip_tags(mesh, tags, mask)
            coarse = (
                strip.coarse_partition(mesh, ~mask, H)
                if H is not None
                else np.full(_num_cells(mesh), -1, dtype=np.int32)
            )
            split = strip.Split(cell_omega, tags, coarse, H)
        else:
            split = strip.automatic_split(mesh, tags, H=H, width=strip_width)
        cm = ContactMesh(
            mesh,
            split.cell_tags,
            split.facet_tags,
            mesh_size(mesh, split.facet_tags),
            split.H,
            split.coarse_cell,
            names,
            split.coarse_grid,
        )
        validation.validate_contact_mesh(cm, source="the mesh given to ContactProblem.from_meshtags")
        fields = {}
        for key, value in (("youngs_modulus", youngs_modulus), ("poisson_ratio", poisson_ratio)):
            if isinstance(value, Mapping):
                if cell_tags is None:
                    raise InputError(f"{key} by cell tag needs cell_tags")
                value = tag_function(mesh, cell_tags, value, name=key)
            fields[key] = value
        boundary = BoundaryConditions(
            displacement=displacement, tractions={names[tag]: tractions[t] for t, tag in zip(tractions, names)}
        )
        return cls(
            **fields, load=load, boundary=boundary, obstacle=obstacle, mesh=cm, name=name, description=description
        )

    # -- building new problems ----------------------------------------------------------------
    def on(self, mesh: ContactMesh) -> "ContactProblem":
        """The same physics on ``mesh`` (validated there)."""
        return self.with_(mesh=mesh)

    def with_(self, **changes) -> "ContactProblem":
        """A copy with some fields replaced. The cellwise fields are kept when the materials, the load and
        the mesh stay (a moved obstacle, new boundary data)."""
        names = {f.name for f in dataclass_fields(self) if f.init}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise InputError(f"ContactProblem has no field(s) {unknown}; its fields are {sorted(names)}")
        values = {name: changes.get(name, getattr(self, name)) for name in names}
        keep = changes.get("mesh", self.mesh) is self.mesh and not any(
            name in changes and changes[name] is not getattr(self, name) for name in _MATERIAL_FIELDS
        )
        if not keep:
            return ContactProblem(**values)
        copy = object.__new__(ContactProblem)
        for name, value in values.items():
            object.__setattr__(copy, name, value)
        object.__setattr__(copy, "_fields", weakref.WeakKeyDictionary(self._fields))
        copy.__post_init__()
        return copy

    # -- what the solvers read -----------------------------------------------------------------
    @property
    def cm(self) -> ContactMesh:
        """The tagged mesh (InputError when the problem has none: give it one with ``on(mesh)``)."""
        if self.mesh is None:
            raise InputError(
                f"the problem {self.name!r} has no mesh: put it on one with problem.on(mesh) "
                "(e.g. geometry.unit_square(64, 16) or geometry.read_mesh('my.msh'))"
            )
        return self.mesh

    @property
    def comm(self) -> MPI.Comm:
        return self.cm.comm

    @property
    def dim(self) -> int:
        """The geometric dimension (the mesh's)."""
        return self.cm.mesh.geometry.dim

    @property
    def h(self) -> float:
        """The fine mesh size (``ContactMesh.h``)."""
        return self.cm.h

    @property
    def length(self) -> float:
        """L_ref, the body's size: the largest side of the mesh's bounding box (``geometry.mesh_extent``; 1 on the
        unit square; collective). The length-dependent defaults (ε, α, β) take h relative to it."""
        return mesh_extent(self.cm.mesh)

    def contact_range(self, name: str = "E") -> tuple[float, float]:
        """(smallest, largest) of the cellwise field ``name`` ("E", "nu", "lmbda", "mu") over the cells touching
        Γ_C, over all ranks."""
        msh, values = self.cm.mesh, getattr(self.fields, name).x.array
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        facets = self.cm.facet_tags.find(Boundary.GAMMA_C)
        cells = np.unique(np.concatenate([f2c.links(f) for f in facets] or [[]])).astype(np.int32)
        if msh.comm.allreduce(int(cells.size), op=MPI.SUM) == 0:
            raise InputError("the mesh has no Γ_C facets")
        lo = msh.comm.allreduce(float(np.min(values[cells], initial=np.inf)), op=MPI.MIN)
        hi = msh.comm.allreduce(float(np.max(values[cells], initial=-np.inf)), op=MPI.MAX)
        return float(lo), float(hi)

    def contact_modulus(self, *, smallest: bool = False) -> float:
        """The largest (``smallest``: smallest) Young's modulus of the cells touching Γ_C, over all ranks."""
        return self.contact_range("E")[0 if smallest else 1]

    @property
    def fields(self) -> MaterialFields:
        """E, ν, λ, μ and f (DG0) on the problem's mesh, with its boundary data and obstacle."""
        return self.fields_on(self.cm.mesh)

    def fields_on(self, msh: dmesh.Mesh) -> MaterialFields:
        """The problem's cellwise fields on ``msh`` (the mesh, a part of it, a replica), built once per mesh."""
        built = self._fields.get(msh)
        if built is None:
            built = material_fields(msh, self)
            self._fields[msh] = built
        return built._replace(boundary=self.boundary, obstacle=self.obstacle)

    def check_loaded(self) -> None:
        """InputError when nothing loads the body: a body force that vanishes on every cell of the mesh, no
        Γ_D displacement, no tractions and no obstacle (the solution would be u = 0)."""
        loaded_otherwise = not self.boundary.is_default or self.obstacle is not None
        f = self.fields.f
        if loaded_otherwise:
            return
        if self.comm.allreduce(float(np.max(np.abs(f.x.array), initial=0.0)), op=MPI.MAX) != 0.0:
            return
        if self.comm.allreduce(self._load_vanishes_in_cells(), op=MPI.LAND):
            raise InputError(
                f"nothing loads the body of {self.name!r}: its body force is zero everywhere in it, Gamma_D holds "
                "it at u = 0, and it has no traction and no obstacle: the solution is u = 0. Give a load (a body "
                "force, a traction, a displacement on Gamma_D or an obstacle pressed into the body)."
            )
        raise InputError(
            f"the body force of {self.name!r} is zero on every cell of this mesh (too coarse to resolve the "
            "load bands?): the solution would be u = 0. Refine the mesh (the built-in loads act on x >= 15/16)."
        )

    def _load_vanishes_in_cells(self) -> bool:
        """True when the body force is zero at the vertices, edge midpoints and inner points of every local cell
        (the load itself vanishes, not only at the cell midpoints that the DG0 body force samples)."""
        if isinstance(self.load, FunctionField):
            return False  # (a function: its values are the DG0 field's own)
        msh = self.cm.mesh
        nodes = msh.geometry.x[msh.geometry.dofmaps[0]]  # (cells, vertices, 3): affine cells
        n = nodes.shape[1]
        eye = np.eye(n)
        weights = [*eye, *((eye[i] + eye[j]) / 2 for i in range(n) for j in range(i + 1, n))]
        weights += [0.7 * eye[i] + 0.3 / n for i in range(n)] + [np.full(n, 1.0 / n)]
        points = np.concatenate([np.einsum("v,cvd->cd", w, nodes) for w in weights]).T
        try:
            values = np.asarray(self.load(points), dtype=np.float64)
        except Exception:  # noqa: BLE001 -- the user's callable off the midpoints: no verdict, the mesh is blamed
            return False
        return bool(np.all(values == 0.0))


def _require_entities_of(msh: dmesh.Mesh, tags, what: str) -> None:
    """InputError when the MeshTags ``tags`` name entities this rank's part of ``msh`` does not have (tags of
    another mesh)."""
    if not isinstance(tags, dmesh.MeshTags):
        raise InputError(f"{what} must be a dolfinx.mesh.MeshTags, got {type(tags).__name__}")
    msh.topology.create_entities(tags.dim)
    imap = msh.topology.index_map(tags.dim)
    count = imap.size_local + imap.num_ghosts
    beyond = msh.comm.allreduce(int(np.count_nonzero(tags.indices >= count)), op=MPI.SUM)
    if beyond:
        raise InputError(
            f"{what} tag {beyond} entities of dimension {tags.dim} that the mesh does not have (it has "
            f"{imap.size_global}): the tags belong to another mesh"
        )


def _tags(value, what: str) -> tuple[int, ...]:
    try:
        values = (value,) if isinstance(value, (int, np.integer)) else tuple(value)
    except TypeError:  # (neither a tag nor a sequence: a float, None)
        values = ()
    if not values or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in values):
        raise InputError(f"{what} must be a tag (an integer) or a list of tags, got {value!r}")
    return tuple(int(v) for v in values)


def _num_cells(msh: dmesh.Mesh) -> int:
    imap = msh.topology.index_map(msh.topology.dim)
    return imap.size_local + imap.num_ghosts


def _retagged(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, groups: list[tuple[tuple[int, ...], int]]) -> dmesh.MeshTags:
    """The facets of each group of user tags, tagged with the package's tag (``tags.Boundary``, Γ_N groups)."""
    entities, values, used = [], [], {}
    for user, tag in groups:
        for t in user:
            if t in used:
                raise InputError(f"facet tag {t} is given for two boundaries (tags {used[t]} and {tag})")
            used[t] = tag
            found = facet_tags.find(t)
            if msh.comm.allreduce(found.size, op=MPI.SUM) == 0:
                present = sorted({int(v) for v in np.concatenate(msh.comm.allgather(np.unique(facet_tags.values)))})
                raise InputError(f"no facet has the tag {t} (the facet tags are {present})")
            entities.append(found)
            values.append(np.full(found.size, tag, dtype=np.int32))
    entities, values = np.concatenate(entities), np.concatenate(values)
    order = np.argsort(entities, kind="stable")
    return dmesh.meshtags(msh, msh.topology.dim - 1, entities[order].astype(np.int32), values[order])
