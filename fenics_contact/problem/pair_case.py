"""Case files of two deformable bodies in contact (``fenics-contact run --case FILE.toml``).

A case with a ``[pair]`` table describes two bodies on one gmsh mesh (``problem.pair.TwoBodyProblem``): the
file's surface groups are the cells of the bodies (a body may span several groups, e.g. layers of different
materials), its curve groups carry the supports, the tractions and the two contact surfaces, all by physical
name; in a 3D file (tetrahedra) the volume groups are the cells and the surface groups the facets, and every
vector has three components.  ``load_pair_case`` reads it into a ``PairCase``; every key is validated
(InputError naming the key, MeshTagError naming a group the mesh lacks), unknown keys are refused.

    description = "..."

    [mesh]
    file = "two_blocks.msh"                  # planar triangles, or tetrahedra (3D); the two bodies meshed apart
    coarse-size = 5.0                        # primal-ms: H, the side of the coarse squares of both bulks (a length
                                             #   in mesh units), or H = 1/H (an integer, as --H)

    [bodies.lower]                           # two bodies, each its own table (any names)
    cells = ["lower_sandstone", "lower_shale"]   # its surface groups (a string for one)
    E = 2.0e4 | {lower_sandstone = 2e4, lower_shale = 8e3} | {python = "fields.py:E"}
    nu = 0.25                                # the same forms
    body-force = [fx, fy] | {python = ...}   # default zero; every vector [x, y, z] on a 3D mesh
    supports = [{facets = "lower_bottom"},   # u = 0 on the group, or u = displacement, on the
                {facets = "lower_left", components = [0]}]  # components listed (0: x, 1: y, 2: z; default all)
    tractions = {lower_right = [tx, ty]}     # σn = t on the group

    [pair]
    slave = "upper_bottom"                   # Γ_C, where the contact integral lives
    master = "lower_top"                     # Γ_C_other, onto which the slave points are projected
    quadrature-degree = 3
    rule = "segments"                        # or "vertices" (node-to-segment, for comparison)
    basis = "dual"                           # or "standard": the pressure basis (default: dual, with or
                                             #   without friction; standard node-to-segment; ContactPair.basis)

    [friction]                               # default: frictionless; on the relative slip of the two faces
    law = "coulomb"                          # mu = 0.6, or law = "tresca" with threshold = s (a stress)
    mu = 0.6
    stiffness-ratio = 1.0                    # the stick stiffness over the normal penalty

    [load]                                   # load steps: one support's displacement or one traction, by step
    support = "upper_top"                    # the facets of a support of either body (or traction = "group":
    steps = [[0.0, -0.01], [0.0, -0.02]]     #   a group of a body's tractions); its value at each step, the
                                             #   last the run's

The run tables ``[run]`` (method ``primal-monolithic``, ``primal`` or ``primal-ms``, out, plots, delta),
``[primal]`` (tol, max-iterations, accel, layers: the strip layers, alpha-scale; primal and primal-ms) and
``[multiscale]`` (layers: the oversampling layers, nbasis; primal-ms) are read by ``cli.pair``.
"""

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import dolfinx.io.gmsh
import gmsh
import numpy as np
import scipy.spatial
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.case_values import (
    Bad,
    ByGroup,
    FieldSpec,
    PythonField,
    Source,
    Table,
    Uniform,
    echo_friction,
    read_field,
    read_friction,
    read_integer,
    read_number,
    read_point,
    read_string,
    show_value,
)
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import gmsh_session
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import TwoBodyMesh

__all__ = [
    "PAIR_RUN_TABLES",
    "SupportSpec",
    "BodySpec",
    "PairSpec",
    "LoadSteps",
    "PairCase",
    "read_pair_case",
    "read_pair_mesh",
]

#: the run tables of a two-body case (their keys: ``cli.pair.RUN_KEYS``)
PAIR_RUN_TABLES = ("run", "primal", "multiscale")
_TABLES = ("mesh", "bodies", "pair", "load", "friction")


@dataclass(frozen=True, slots=True)
class SupportSpec:
    """u = displacement (None: 0) on the facet group ``facets``, for ``components`` (None: all)."""

    facets: str
    displacement: Uniform | PythonField | None = None
    components: tuple[int, ...] | None = None

    def echo(self, dim: int = 2) -> dict:
        return {
            "facets": self.facets,
            "displacement": self.displacement.echo() if self.displacement else [0.0] * dim,
            "components": list(self.components) if self.components is not None else list(range(dim)),
        }


@dataclass(frozen=True, slots=True)
class BodySpec:
    """One body: its cell groups, E, ν, body force, supports and tractions (by group name)."""

    name: str
    cells: tuple[str, ...]
    E: FieldSpec
    nu: FieldSpec
    body_force: FieldSpec | None
    supports: tuple[SupportSpec, ...]
    tractions: tuple[tuple[str, FieldSpec], ...] = ()

    def echo(self, dim: int = 2) -> dict:
        return {
            "cells": list(self.cells),
            "E": self.E.echo(),
            "nu": self.nu.echo(),
            "body-force": self.body_force.echo() if self.body_force else [0.0] * dim,
            "supports": [s.echo(dim) for s in self.supports],
            "tractions": {name: spec.echo() for name, spec in self.tractions},
        }


@dataclass(frozen=True, slots=True)
class PairSpec:
    """The contact surfaces by facet group name (``problem.pair.ContactPair``)."""

    slave: str
    master: str
    quadrature_degree: int = 3
    rule: str = "segments"
    basis: str | None = None

    def echo(self) -> dict:
        out = {
            "slave": self.slave,
            "master": self.master,
            "quadrature-degree": self.quadrature_degree,
            "rule": self.rule,
        }
        return out if self.basis is None else out | {"basis": self.basis}


@dataclass(frozen=True, slots=True)
class LoadSteps:
    """At each load step, the displacement of the support (``kind`` "support") or the traction (``kind``
    "traction") on the facet group ``group``."""

    group: str
    steps: tuple[tuple[float, float], ...]
    kind: str = "support"

    @property
    def quantity(self) -> str:
        """What each step gives: "displacement" or "traction"."""
        return "displacement" if self.kind == "support" else "traction"

    def echo(self) -> dict:
        return {self.kind: self.group, "steps": [list(s) for s in self.steps]}


@dataclass(frozen=True, slots=True)
class PairCase:
    """A validated two-body case: the mesh file, the two bodies, the pair, the load steps, the raw run tables."""

    path: Path
    description: str
    mesh_file: Path
    bodies: tuple[BodySpec, BodySpec]
    pair: PairSpec
    load: LoadSteps | None
    run: Mapping[str, Mapping[str, Any]]
    overrides: tuple[tuple[str, Any], ...] = ()
    friction: Friction | None = None  #: the pair's friction law (``[friction]``; None: frictionless)
    #: primal-ms: the side of the coarse squares of both bulks, in mesh units (``mesh.coarse-size`` or 1/``mesh.H``)
    coarse_size: float | None = None

    def build_mesh(self, comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[TwoBodyMesh, dict[str, tuple[int, int]]]:
        """The mesh with the file's cell and facet tags and the physical groups by name: (dim, tag). Collective."""
        return read_pair_mesh(self.mesh_file, comm)

    def problem(self, built: tuple[TwoBodyMesh, dict], step: int | None = None) -> TwoBodyProblem:
        """The two-body problem on the built mesh (collective); with load steps, at ``step`` (default the last).

        The bodies' cells get the tags 1 and 2 (a body spanning several groups is one body); E and ν by group
        are read from the file's cell tags.
        """
        tbm, groups = built
        msh, file_cells = tbm.mesh, tbm.cell_tags
        tdim = msh.topology.dim
        self.check_dimension(msh.geometry.dim)
        body_cells, laws = [], []
        for k, body in enumerate(self.bodies):
            tags = [self._group(groups, name, tdim, f"bodies.{body.name}.cells") for name in body.cells]
            cells = np.unique(np.concatenate([file_cells.find(t) for t in tags]))
            body_cells.append(cells)
            E = self._scalar(body.E, f"bodies.{body.name}.E", tbm, groups)
            nu = self._scalar(body.nu, f"bodies.{body.name}.nu", tbm, groups)
            force = None
            if isinstance(body.body_force, Uniform):
                force = body.body_force.value
            elif isinstance(body.body_force, PythonField):
                force = body.body_force.function
            laws.append(Body(k + 1, E, nu, force))
        if np.intersect1d(*body_cells).size:
            raise self._error("the two bodies share cell groups: give each group to one body", MeshTagError)
        n_cells = np.concatenate(body_cells)
        values = np.concatenate([np.full(c.size, k + 1, dtype=np.int32) for k, c in enumerate(body_cells)])
        order = np.argsort(n_cells)
        cell_tags = dmesh.meshtags(msh, tdim, n_cells[order].astype(np.int32), values[order])
        fdim = tdim - 1
        stepped = self.load.steps[-1 if step is None else step] if self.load else None
        moved = {self.load.group: stepped} if self.load and self.load.kind == "support" else {}
        loaded = {self.load.group: stepped} if self.load and self.load.kind == "traction" else {}
        supports, tractions = [], {}
        for body in self.bodies:
            for s in body.supports:
                tag = self._group(groups, s.facets, fdim, f"bodies.{body.name}.supports")
                u_D = _vector_law(s.displacement)
                if s.facets in moved:
                    u_D = moved[s.facets]
                supports.append(Support(tag, u_D, s.components))
            for name, spec in body.tractions:
                law = loaded.get(name, _vector_law(spec))
                tractions[self._group(groups, name, fdim, f"bodies.{body.name}.tractions")] = law
        pair = ContactPair(
            self._group(groups, self.pair.slave, fdim, "pair.slave"),
            self._group(groups, self.pair.master, fdim, "pair.master"),
            self.pair.quadrature_degree,
            self.pair.rule,
            self.friction,
            self.pair.basis,
        )
        return TwoBodyProblem(
            msh, cell_tags, tbm.facet_tags, tuple(laws), pair, tuple(supports), tractions, name=self.path.stem
        )

    @property
    def dimension(self) -> int:
        """The number of components of the case's vectors (2 when it gives none)."""
        return next((n for _, n in self.vectors()), 2)

    def vectors(self) -> list[tuple[str, int]]:
        """(key, number of components) of every vector the case gives, and (key, axis + 1) of every support
        component listed."""
        found = []
        for body in self.bodies:
            key = f"bodies.{body.name}"
            if isinstance(body.body_force, Uniform):
                found.append((f"{key}.body-force", len(body.body_force.value)))
            for i, s in enumerate(body.supports):
                if isinstance(s.displacement, Uniform):
                    found.append((f"{key}.supports[{i}].displacement", len(s.displacement.value)))
            found.extend((f"{key}.tractions.{n}", len(v.value)) for n, v in body.tractions if isinstance(v, Uniform))
        if self.load is not None:
            found.extend((f"load.steps[{k}]", len(v)) for k, v in enumerate(self.load.steps))
        return found

    def check_dimension(self, dim: int | None) -> None:
        """InputError naming the key when a vector does not have ``dim`` components or a support lists an axis
        beyond it (None: the vectors agree among themselves)."""
        vectors = self.vectors()
        if dim is None:
            if len({n for _, n in vectors}) > 1:
                (k1, n1), (k2, n2) = vectors[0], next(v for v in vectors if v[1] != vectors[0][1])
                raise self._error(
                    f"{k1} has {n1} components but {k2} has {n2}: the vectors of a case all have the mesh's "
                    "dimension ([x, y] in 2D, [x, y, z] in 3D)"
                )
            return
        cells = "tetrahedra" if dim == 3 else "triangles"
        for key, n in vectors:
            if n != dim:
                raise self._error(
                    f"{key} has {n} components but the mesh {self.mesh_file.name} is {dim}D ({cells}): give "
                    f"{'[x, y, z]' if dim == 3 else '[x, y]'}"
                )
        for body in self.bodies:
            for i, s in enumerate(body.supports):
                if s.components is not None and max(s.components) >= dim:
                    raise self._error(
                        f"bodies.{body.name}.supports[{i}].components lists the axis {max(s.components)} but the "
                        f"mesh {self.mesh_file.name} is {dim}D"
                    )

    def _error(self, message: str, kind: type = InputError) -> Exception:
        return kind(f"case {self.path}: {message}")

    def _group(self, groups: dict, name: str, dim: int, key: str) -> int:
        if name not in groups or groups[name][0] != dim:
            tdim = max((d for d, _ in groups.values()), default=2)
            kind = {3: "volume", 2: "surface", 1: "curve"}[dim] + (" (cell)" if dim == max(tdim, 2) else " (facet)")
            known = sorted(n for n, (d, _) in groups.items() if d == dim)
            raise self._error(
                f"{key}: the mesh {self.mesh_file.name} has no {kind} group {name!r}; its {kind} groups are {known}",
                MeshTagError,
            )
        return groups[name][1]

    def _scalar(self, spec: FieldSpec, key: str, tbm: TwoBodyMesh, groups: dict) -> object:
        if isinstance(spec, Uniform):
            return spec.value
        if isinstance(spec, PythonField):
            return spec.function
        tdim = tbm.mesh.topology.dim
        by_tag = {self._group(groups, name, tdim, f"{key}.{name}"): value for name, value in spec.values}
        return group_field(tbm.mesh, tbm.cell_tags, by_tag)

    @property
    def description_or_name(self) -> str:
        return self.description or f"case {self.path.name}"

    def to_dict(self) -> dict:
        """The resolved case, for the summary."""
        return {
            "file": str(self.path),
            "description": self.description,
            "mesh": {"file": str(self.mesh_file), "coarse-size": self.coarse_size},
            "bodies": {b.name: b.echo(self.dimension) for b in self.bodies},
            "pair": self.pair.echo(),
            "load": self.load.echo() if self.load else None,
            "friction": echo_friction(self.friction),
            "overrides": {key: value for key, value in self.overrides},
        }


def _vector_law(spec) -> object:
    if spec is None:
        return None
    return spec.value if isinstance(spec, Uniform) else spec.function


def group_field(msh: dmesh.Mesh, cell_tags: dmesh.MeshTags, values: Mapping[int, float]) -> Callable:
    """x (3, N) -> the value of the group of the local cell whose midpoint is x (NaN at any other point): a law
    evaluated at cell midpoints (``TwoBodyProblem`` evaluates E and ν there)."""
    tdim = msh.topology.dim
    cells = [cell_tags.find(tag) for tag in values]
    all_cells = np.concatenate(cells + [np.zeros(0, np.int32)])
    group_values = np.concatenate([np.full(c.size, v) for c, v in zip(cells, values.values(), strict=True)] + [[]])
    midpoints = dmesh.compute_midpoints(msh, tdim, all_cells.astype(np.int32))
    tree = scipy.spatial.cKDTree(midpoints) if all_cells.size else None
    extent = float(np.ptp(msh.geometry.x, axis=0).max(initial=1.0)) if msh.geometry.x.size else 1.0

    def law(x: np.ndarray) -> np.ndarray:
        out = np.full(x.shape[1], np.nan)
        if tree is None or not x.shape[1]:
            return out
        distance, index = tree.query(x.T)
        near = distance <= 1e-9 * extent
        out[near] = group_values[index[near]]
        return out

    return law


def read_pair_mesh(path: Path, comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[TwoBodyMesh, dict[str, tuple[int, int]]]:
    """A planar triangle or a tetrahedral mesh from a gmsh file, with its cell and facet tags and its physical
    groups by name.

    InputError when gmsh cannot read it, it is neither planar triangles nor tetrahedra, or a cell lies in no
    cell group (it would be left out of the mesh). Collective; the file is read on rank 0."""
    with gmsh_session():
        problem, dim = None, 2
        if comm.rank == 0:
            gmsh.model.add("two bodies")
            try:
                gmsh.merge(str(path))
            except Exception as err:  # gmsh raises a bare Exception with its parser's message
                problem = f"cannot read {path} as a gmsh mesh: {err}"
            else:
                dim = 3 if len(gmsh.model.mesh.getElementTypes(3)) else 2
                problem = _mesh_problem(path, dim)
                gmsh.model.mesh.renumberNodes()  # (the DOLFINx reader needs node tags 1..N; a file may skip some)
        problem, dim = comm.bcast((problem, dim), root=0)
        if problem is not None:
            raise InputError(problem)
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=dim)
    groups = {name: (int(g.dim), int(g.tag)) for name, g in data.physical_groups.items()}
    return TwoBodyMesh(data.mesh, data.cell_tags, data.facet_tags), groups


def _mesh_problem(path: Path, tdim: int) -> str | None:
    """What is wrong with the gmsh model of ``path`` as a mesh of two bodies of dimension ``tdim``, or None."""
    types = set(gmsh.model.mesh.getElementTypes(tdim))
    one, cell, gmsh_type, group = (
        ("triangle", "triangles", 2, "surface") if tdim == 2 else ("tetrahedron", "tetrahedra", 4, "volume")
    )
    if types != {gmsh_type}:
        return f"{path} must hold 4-node tetrahedra or 3-node triangles only (gmsh type 4 or 2), got {sorted(types)}"
    _, coords, _ = gmsh.model.mesh.getNodes()
    if tdim == 2 and np.any(np.abs(np.asarray(coords).reshape(-1, 3)[:, 2]) > 0.0):
        return f"{path} is not planar: its nodes must have z = 0"
    members, used = [], []
    for dim, tag in gmsh.model.getPhysicalGroups(tdim):
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            _, elements, nodes = gmsh.model.mesh.getElements(tdim, entity)
            members.extend(np.concatenate(elements or [np.zeros(0)]).tolist())
            used.append(np.concatenate(nodes or [np.zeros(0)]))
    node_tags = gmsh.model.mesh.getNodes()[0]
    stray = np.setdiff1d(node_tags, np.concatenate(used or [np.zeros(0)]))
    if stray.size:
        return (
            f"{path}: {stray.size} of its nodes belong to no {one} of a {group} group (cells left out of every "
            f"group, or written without their elements); every {one} must belong to the cell group of a body"
        )
    grouped = set(members)
    if len(grouped) < len(members):
        return f"{path}: {len(members) - len(grouped)} {cell} lie in two {group} groups; give each to one group"
    total = np.concatenate(gmsh.model.mesh.getElements(tdim)[1] or [np.zeros(0)]).size
    if len(grouped) < total:
        return (
            f"{path}: {total - len(grouped)} of its {total} {cell} lie in no {group} group; every {one} must "
            "belong to the cell group of a body"
        )
    return None


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------
def _names(source: Source, key: str, value) -> tuple[str, ...]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not items or not all(isinstance(v, str) and v for v in items):
        raise source.error(f"{key} must be a group name or a list of them, got {show_value(value)}")
    if len(set(items)) < len(items):
        raise source.error(f"{key} lists a group twice: {items}")
    return tuple(items)


def _vector_or_python(source: Source, key: str, value) -> Uniform | PythonField:
    spec = read_field(source, key, value, read_point, vector=True, pixels=False)
    if isinstance(spec, ByGroup):
        raise source.error(f"{key} must be a vector [x, y] or [x, y, z] or {{python = 'file.py:name'}}, got a table")
    return spec


def _support(source: Source, key: str, value) -> SupportSpec:
    t = Table(source, key, value)
    facets = t.get("facets", read_string(), required=True)
    displacement = t.raw("displacement")
    components = t.raw("components")
    t.finish()
    if components is not None:
        if (
            not isinstance(components, list)
            or not components
            or any(isinstance(c, bool) or c not in (0, 1, 2) for c in components)
            or len(set(components)) < len(components)
        ):
            raise source.error(f"{key}.components must list distinct axes 0 (x), 1 (y), 2 (z), got {components!r}")
        components = tuple(int(c) for c in components)
    u_D = _vector_or_python(source, f"{key}.displacement", displacement) if displacement is not None else None
    return SupportSpec(facets, u_D, components)


def _body(source: Source, name: str, data) -> BodySpec:
    key = f"bodies.{name}"
    t = Table(source, key, data)
    if not t.has("cells"):
        raise source.error(f"{key}.cells is required (the body's surface groups)")
    cells = _names(source, f"{key}.cells", t.raw("cells"))
    positive = read_number(positive=True)
    E = read_field(source, f"{key}.E", t.raw("E"), positive, vector=False, pixels=False) if t.has("E") else None
    nu = (
        read_field(source, f"{key}.nu", t.raw("nu"), read_number(low=-1.0, high=0.5), vector=False, pixels=False)
        if t.has("nu")
        else None
    )
    force = t.raw("body-force")
    supports = t.raw("supports")
    tractions = t.raw("tractions")
    t.finish()
    if E is None or nu is None:
        raise source.error(f"{key}: E and nu are required")
    for spec, what in ((E, "E"), (nu, "nu")):
        if isinstance(spec, ByGroup):
            stray = sorted({n for n, _ in spec.values} - set(cells))
            if stray:
                raise source.error(f"{key}.{what}.{stray[0]}: not a cell group of this body (its cells: {list(cells)})")
            missing = sorted(set(cells) - {n for n, _ in spec.values})
            if missing:
                raise source.error(f"{key}.{what} gives no value for the body's cell group {missing[0]!r}")
    force = _vector_or_python(source, f"{key}.body-force", force) if force is not None else None
    if supports is None:
        supports = []
    if not isinstance(supports, list) or not all(isinstance(s, dict) for s in supports):
        raise source.error(
            f'{key}.supports must be a list of tables [{{facets = "..."}}, ...], got {show_value(supports)}'
        )
    supports = tuple(_support(source, f"{key}.supports[{i}]", s) for i, s in enumerate(supports))
    if tractions is not None and not isinstance(tractions, dict):
        raise source.error(f"{key}.tractions must be a table {{group = [tx, ty]}}, got {show_value(tractions)}")
    pairs = tuple(
        (group, _vector_or_python(source, f"{key}.tractions.{group}", value))
        for group, value in sorted((tractions or {}).items())
    )
    return BodySpec(name, cells, E, nu, force, supports, pairs)


def _pair(source: Source, data) -> PairSpec:
    t = Table(source, "pair", data)
    spec = PairSpec(
        t.get("slave", read_string(), required=True),
        t.get("master", read_string(), required=True),
        t.get("quadrature-degree", read_integer(1), 3),
        t.get("rule", read_string(("segments", "vertices")), "segments"),
        t.get("basis", read_string(("dual", "standard")), None),
    )
    t.finish()
    if spec.basis == "dual" and spec.rule != "segments":
        raise source.error('pair.basis = "dual" needs pair.rule = "segments"')
    if spec.slave == spec.master:
        raise source.error(f"pair.slave and pair.master name the same group {spec.slave!r}")
    if spec.quadrature_degree > 10:
        raise source.error(f"pair.quadrature-degree must be at most 10, got {spec.quadrature_degree}")
    return spec


def _load(source: Source, data, bodies: Sequence[BodySpec]) -> LoadSteps | None:
    if data is None:
        return None
    t = Table(source, "load", data)
    support = t.get("support", read_string())
    traction = t.get("traction", read_string())
    steps = t.raw("steps")
    t.finish(" for a two-body case (body forces are given per body)")
    if (support is None) == (traction is None):
        raise source.error(
            "[load] steps one boundary: give exactly one of load.support (a support's displacement) and "
            "load.traction (a traction's value)"
        )
    if not isinstance(steps, list) or not steps:
        raise source.error("load.steps must be a non-empty list of vectors [[x, y], ...] (one per step)")
    try:
        values = tuple(read_point(v) for v in steps)
    except Bad as bad:
        raise source.error(f"load.steps: each step {bad}") from None
    if support is not None:
        known = sorted(s.facets for b in bodies for s in b.supports)
        if support not in known:
            raise source.error(
                f"load.support = {support!r} is not the facet group of a support (the supports: {known})"
            )
        return LoadSteps(support, values, "support")
    known = sorted(name for b in bodies for name, _ in b.tractions)
    if traction not in known:
        raise source.error(
            f"load.traction = {traction!r} is not a group of a body's tractions (the tractions: {known}); give the "
            "group a traction in [bodies.<name>] tractions (its value is replaced step by step)"
        )
    return LoadSteps(traction, values, "traction")


def read_pair_case(source: Source, data: dict, overrides: Sequence[tuple[str, Any]] = ()) -> PairCase:
    """The two-body case of an already parsed case file (``data``, the overrides applied)."""
    unknown = sorted(set(data) - {"description", *_TABLES, *PAIR_RUN_TABLES})
    if unknown:
        raise source.error(
            f"unknown key or table {unknown[0]!r} in a two-body case (it has [pair]); the tables are "
            f"{[*_TABLES, *PAIR_RUN_TABLES]} (and the key description)"
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise source.error(f"description must be a string, got {show_value(description)}")
    mesh = Table(source, "mesh", data.get("mesh", {}))
    path = mesh.get("file", lambda v: source.file(v, "mesh.file"), required=True)
    inverse = mesh.get("H", read_integer(1))
    coarse_size = mesh.get("coarse-size", read_number(positive=True))
    mesh.finish(" for a two-body case")
    if inverse is not None and coarse_size is not None and all(key != "mesh.H" for key, _ in overrides):
        raise source.error(
            "mesh.H (1/H) and mesh.coarse-size (H itself, a length) give the same coarse size: give one of them"
        )
    if inverse is not None:
        coarse_size = 1.0 / inverse
    bodies = data.get("bodies")
    if not isinstance(bodies, dict) or len(bodies) != 2:
        count = len(bodies) if isinstance(bodies, dict) else 0
        raise source.error(f"a two-body case needs two tables [bodies.<name>], got {count}")
    specs = tuple(_body(source, name, value) for name, value in bodies.items())
    pair = _pair(source, data["pair"])
    load = _load(source, data.get("load"), specs)
    run = {}
    for table in PAIR_RUN_TABLES:
        values = data.get(table, {})
        if not isinstance(values, dict):
            raise source.error(f"{table} must be a table ([{table}]), got {show_value(values)}")
        run[table] = dict(values)
    friction = read_friction(source, data.get("friction"))
    case = PairCase(source.path, description, path, specs, pair, load, run, tuple(overrides), friction, coarse_size)
    case.check_dimension(None)
    return case
