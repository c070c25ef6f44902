"""Two deformable bodies in contact: the bodies, their supports, the contact pair, one ``TwoBodyProblem``.

One mesh holds both bodies, disjoint (no shared vertex), each the cells of one cell tag; their meshes need
not match across the contact surfaces.  Each body has its own Young's modulus E(x), Poisson ratio ν(x) and
body force f(x) (``Body``); the facet groups of both carry the boundary conditions (``Support``: u = u_D
on all or some components, ``tractions``: σn = t), every other exterior facet is traction free.  The pair of
potential contact surfaces is a ``ContactPair``: the slave facets Γ_C (where the contact integral lives)
and the master facets Γ_C_other (onto which the slave points are projected); the small-deformation gap is
measured once, on the reference configuration (``fem.mortar``).

    problem = TwoBodyProblem(mesh, cell_tags, facet_tags, bodies=(Body(1, E=…, nu=…), Body(2, E=…, nu=…)),
                             pair=ContactPair(slave=12, master=14), supports=(Support(21), Support(22, (0, -d))))
    result = fc.solve(problem, "primal-monolithic")
"""

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.boundary import constant_vector
from fenics_contact.problem.fields import MaterialFields, cell_function
from fenics_contact.problem.fields import _checked as checked_values
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import mesh_extent
from fenics_contact.problem.materials import check_poisson_ratio, check_youngs_modulus, lame

__all__ = ["Body", "Support", "ContactPair", "PRESSURE_BASES", "TwoBodyProblem"]

#: the bases of a pair's penalty pressure on the slave surface (``fem.mortar.weight_functions``)
PRESSURE_BASES = ("standard", "dual")


def _field(value, what: str, shape: tuple = ()):
    """A callable x (3, N) -> values, or a constant (number, or vector when ``shape``) as one."""
    if callable(value):
        return value
    if shape:
        try:
            return constant_vector(value)
        except (TypeError, ValueError) as err:
            raise InputError(f"{what} must be a callable x -> (gdim, N) or a constant vector, got {value!r}") from err
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not np.isfinite(value):
        raise InputError(f"{what} must be a callable x (3, N) -> (N,) or a finite number, got {value!r}")
    number = float(value)
    return lambda x: np.full(x.shape[1], number)


def _tag(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{what} must be an integer tag, got {value!r}")
    return int(value)


@dataclass(frozen=True, slots=True)
class Body:
    """One body: the cells of the tag ``cells``, its E(x), ν(x) and body force f(x) (numbers, constant vectors
    or callables x (3, N) -> (N,) / (gdim, N); f default zero)."""

    cells: int
    youngs_modulus: object
    poisson_ratio: object
    load: object = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "cells", _tag(self.cells, "Body.cells"))
        object.__setattr__(self, "youngs_modulus", _field(self.youngs_modulus, "Body.youngs_modulus (E)"))
        object.__setattr__(self, "poisson_ratio", _field(self.poisson_ratio, "Body.poisson_ratio (nu)"))
        if self.load is not None:
            object.__setattr__(self, "load", _field(self.load, "Body.load", shape=(2,)))


@dataclass(frozen=True, slots=True)
class Support:
    """u_i = u_D,i on the facets of the tag ``facets`` for the components i in ``components`` (None: all;
    ``(0,)``: a roller that holds x only); ``displacement`` u_D a constant vector or a callable (None: 0)."""

    facets: int
    displacement: object = None
    components: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "facets", _tag(self.facets, "Support.facets"))
        if self.displacement is not None:
            object.__setattr__(self, "displacement", _field(self.displacement, "Support.displacement", shape=(2,)))
        if self.components is not None:
            comps = tuple(self.components)
            if (
                not comps
                or any(isinstance(c, bool) or c not in (0, 1, 2) for c in comps)
                or len(set(comps)) < len(comps)
            ):
                raise InputError(f"Support.components must be distinct axes among 0, 1, 2, got {self.components!r}")
            object.__setattr__(self, "components", tuple(int(c) for c in comps))


@dataclass(frozen=True, slots=True)
class ContactPair:
    """The potential contact surfaces: ``slave`` (Γ_C, integrated) and ``master`` (Γ_C_other, projected onto)
    facet tags, on different bodies; ``quadrature_degree`` of the Gauss rule on each piece of a slave facet;
    ``rule``: ``"segments"`` (segment-to-segment, ``fem.mortar``) or ``"vertices"`` (one-pass node-to-segment,
    which fails the contact patch test on non-matching meshes: for comparison only); ``friction``: a
    ``Friction`` law on the relative slip of the two surfaces (``fem.two_body_friction``), None: frictionless;
    ``basis``: of the penalty pressure on the slave surface (``fem.mortar.weight_functions``), ``"dual"`` (the
    biorthogonal basis: the nodal pressures are the nodal values of the gap's local projection, accurate up to
    the contact edge; segment-to-segment rule only) or ``"standard"`` (P1 hat functions); None: dual with the
    segment-to-segment rule, with or without friction (one basis for a pair whatever its friction: μ = 0 is the
    frictionless pair), standard with the node-to-segment rule."""

    slave: int
    master: int
    quadrature_degree: int = 3
    rule: str = "segments"
    friction: Friction | None = None
    basis: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "slave", _tag(self.slave, "ContactPair.slave"))
        object.__setattr__(self, "master", _tag(self.master, "ContactPair.master"))
        if self.slave == self.master:
            raise InputError(f"ContactPair: the slave and master surfaces need different tags, got {self.slave} twice")
        degree = self.quadrature_degree
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or not 1 <= degree <= 10:
            raise InputError(f"ContactPair.quadrature_degree must be an integer in [1, 10], got {degree!r}")
        if self.rule not in ("segments", "vertices"):
            raise InputError(f"ContactPair.rule must be 'segments' or 'vertices', got {self.rule!r}")
        if self.basis is None:
            object.__setattr__(self, "basis", "dual" if self.rule == "segments" else "standard")
        if self.basis not in PRESSURE_BASES:
            raise InputError(f"ContactPair.basis must be 'standard' or 'dual', got {self.basis!r}")
        if self.basis == "dual" and self.rule != "segments":
            raise InputError("ContactPair: the dual pressure basis needs the segment-to-segment rule (rule='segments')")
        if self.friction is not None and not isinstance(self.friction, Friction):
            raise InputError(f"ContactPair.friction must be a Friction law or None, got {self.friction!r}")


def _count(comm: MPI.Comm, local: int) -> int:
    return comm.allreduce(int(local), op=MPI.SUM)


def _vertices_of(msh: dmesh.Mesh, dim: int, entities: np.ndarray) -> np.ndarray:
    msh.topology.create_connectivity(dim, 0)
    conn = msh.topology.connectivity(dim, 0)
    return np.unique(np.concatenate([conn.links(e) for e in entities] or [np.zeros(0, np.int32)]))


@dataclass(frozen=True, eq=False)
class TwoBodyProblem:
    """Two elastic bodies on one mesh (disjoint cell groups), their supports and tractions, and a contact pair.

    ``bodies``: two ``Body``; ``pair``: the ``ContactPair``; ``supports``: the Dirichlet boundaries
    (``Support``), at least one on each body (frictionless contact does not hold a body tangentially);
    ``tractions``: facet tag -> traction t (σn = t).  Penalty contact on the pair (``fem.two_body``), with
    the pair's friction law if it has one (``fem.two_body_friction``).  Validated on construction
    (InputError / MeshTagError).
    """

    mesh: dmesh.Mesh
    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags
    bodies: tuple[Body, Body]
    pair: ContactPair
    supports: tuple[Support, ...]
    tractions: Mapping[int, object] = field(default_factory=dict)
    name: str = "two bodies"

    def __post_init__(self) -> None:
        msh = self.mesh
        tdim = msh.topology.dim
        if not isinstance(self.cell_tags, dmesh.MeshTags) or self.cell_tags.dim != tdim:
            raise InputError(f"cell_tags must be the cell MeshTags of the mesh (dimension {tdim})")
        if not isinstance(self.facet_tags, dmesh.MeshTags) or self.facet_tags.dim != tdim - 1:
            raise InputError(f"facet_tags must be the facet MeshTags of the mesh (dimension {tdim - 1})")
        bodies = tuple(self.bodies)
        if len(bodies) != 2 or not all(isinstance(b, Body) for b in bodies):
            raise InputError("TwoBodyProblem.bodies must be two Body")
        if bodies[0].cells == bodies[1].cells:
            raise InputError(f"the two bodies need different cell tags, got {bodies[0].cells} twice")
        if not isinstance(self.pair, ContactPair):
            raise InputError(f"TwoBodyProblem.pair must be a ContactPair, got {type(self.pair).__name__}")
        supports = tuple(self.supports)
        if not all(isinstance(s, Support) for s in supports):
            raise InputError("TwoBodyProblem.supports must be Support entries")
        tractions = {
            _tag(t, "a traction's facet tag"): _field(v, f"the traction on tag {t}", shape=(2,))
            for t, v in dict(self.tractions).items()
        }
        object.__setattr__(self, "bodies", bodies)
        object.__setattr__(self, "supports", supports)
        object.__setattr__(self, "tractions", tractions)
        self._check_mesh()
        object.__setattr__(self, "_fields", self._material_fields())

    # -- validation --------------------------------------------------------------------------------
    def _check_mesh(self) -> None:
        msh, comm = self.mesh, self.mesh.comm
        tdim = msh.topology.dim
        imap = msh.topology.index_map(tdim)
        owned = np.arange(imap.size_local, dtype=np.int32)
        vertex_sets = []
        for body in self.bodies:
            cells = self.cell_tags.find(body.cells)
            if _count(comm, np.count_nonzero(cells < imap.size_local)) == 0:
                raise MeshTagError(f"no cell has the body's tag {body.cells}")
            vertex_sets.append(_vertices_of(msh, tdim, cells))
        tagged = np.isin(owned, np.concatenate([self.cell_tags.find(b.cells) for b in self.bodies]))
        if _count(comm, np.count_nonzero(~tagged)):
            raise MeshTagError(f"{_count(comm, np.count_nonzero(~tagged))} cells belong to neither body")
        if comm.size == 1 and np.intersect1d(*vertex_sets).size:
            raise InputError(
                "the two bodies share vertices: they must be disjoint meshes (glued bodies are one body; "
                "mesh the two without fusing their common boundary)"
            )
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        body_of_cell = np.full(imap.size_local + imap.num_ghosts, -1)
        for k, body in enumerate(self.bodies):
            body_of_cell[self.cell_tags.find(body.cells)] = k
        exterior = dmesh.exterior_facet_indices(msh.topology)

        def body_of(tag: int, what: str) -> set[int]:
            facets = self.facet_tags.find(tag)
            if _count(comm, facets.size) == 0:
                raise MeshTagError(f"{what}: no facet has the tag {tag}")
            if not np.all(np.isin(facets, exterior)):
                raise MeshTagError(f"{what}: the facets of tag {tag} must lie on the boundary of a body")
            local = {int(body_of_cell[f2c.links(f)[0]]) for f in facets}
            return set().union(*comm.allgather(local))

        slave, master = body_of(self.pair.slave, "ContactPair.slave"), body_of(self.pair.master, "ContactPair.master")
        if len(slave) != 1 or len(master) != 1 or slave == master:
            raise InputError(
                f"the contact pair's surfaces must each lie on one body, and on different ones (slave tag "
                f"{self.pair.slave} on bodies {sorted(slave)}, master tag {self.pair.master} on {sorted(master)})"
            )
        held = set()
        for s in self.supports:
            held |= body_of(s.facets, "Support")
        for t in self.tractions:
            body_of(t, "a traction")
        loose = [self.bodies[k].cells for k in (0, 1) if k not in held]
        if loose:
            raise InputError(
                f"the bod{'ies' if len(loose) > 1 else 'y'} of cell tag {loose} ha{'ve' if len(loose) > 1 else 's'} no "
                "Support: frictionless contact does not hold a body tangentially, and with friction the first "
                "Newton step, before any contact, has no stiffness there; so each needs a Dirichlet boundary"
            )
        object.__setattr__(self, "_slave_body", slave.pop())

    def _material_fields(self) -> MaterialFields:
        """DG0 E, ν, λ, μ and f, each body's laws evaluated at the midpoints of its own cells only."""
        msh = self.mesh
        tdim, gdim = msh.topology.dim, msh.geometry.dim
        E = cell_function(msh, lambda x: np.ones(x.shape[1]), name="E")
        nu = cell_function(msh, lambda x: np.zeros(x.shape[1]), name="nu")
        f = cell_function(msh, lambda x: np.zeros((gdim, x.shape[1])), shape=(gdim,), name="f")
        for body in self.bodies:
            cells = self.cell_tags.find(body.cells)
            x = dmesh.compute_midpoints(msh, tdim, cells).T
            for fn, law, shape in ((E, body.youngs_modulus, ()), (nu, body.poisson_ratio, ()), (f, body.load, (gdim,))):
                if law is None or cells.size == 0:
                    continue
                values = checked_values(law, shape, f"{fn.name} of the body of cell tag {body.cells}")(x)
                dofs = fn.function_space.dofmap.list[cells, 0]
                if shape:
                    fn.x.array.reshape(-1, gdim)[dofs] = values.T
                else:
                    fn.x.array[dofs] = values
        for fn in (E, nu, f):
            fn.x.scatter_forward()
        check_youngs_modulus(E.x.array)
        check_poisson_ratio(nu.x.array)
        lm, mu_ = lame(E.x.array, nu.x.array)
        lmbda, mu = fem.Function(E.function_space, name="lambda"), fem.Function(E.function_space, name="mu")
        lmbda.x.array[:], mu.x.array[:] = lm, mu_
        return MaterialFields(E, nu, lmbda, mu, f)

    # -- what the solvers read -------------------------------------------------------------------
    @property
    def fields(self) -> MaterialFields:
        """E, ν, λ, μ and f (DG0) on the mesh, each body's on its cells."""
        return self._fields

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    @property
    def dim(self) -> int:
        """The geometric dimension (the mesh's)."""
        return self.mesh.geometry.dim

    @property
    def length(self) -> float:
        """L_ref, the pair's size: the largest side of the mesh's bounding box (``geometry.mesh_extent``;
        collective).  Algorithm 1's default α takes the γ facet size relative to it."""
        return mesh_extent(self.mesh)

    def contact_moduli(self) -> tuple[float, float]:
        """The largest E of the cells touching the slave and the master surface."""
        msh = self.mesh
        tdim = msh.topology.dim
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        out = []
        for tag in (self.pair.slave, self.pair.master):
            cells = [f2c.links(f)[0] for f in self.facet_tags.find(tag)]
            local = float(np.max(self._fields.E.x.array[cells], initial=0.0))
            out.append(self.comm.allreduce(local, op=MPI.MAX))
        return out[0], out[1]

    @property
    def friction(self) -> Friction | None:
        """The pair's friction law (None: frictionless)."""
        return self.pair.friction

    def body_cells(self, k: int) -> np.ndarray:
        """The local cells of body k (0 or 1)."""
        return self.cell_tags.find(self.bodies[k].cells)
