"""Case files: a whole contact problem in one TOML file (``fenics-contact run --case FILE.toml``).

A case names the mesh (built-in or a gmsh file), the materials, the loads, the boundary
conditions, the obstacle with its indentation steps, and the run options; ``load_case`` reads
it into a ``Case`` of small frozen dataclasses, validated on construction (InputError /
MeshTagError naming the key, e.g. ``mesh.h``, or the group).  Every table and key is optional
unless said; unknown keys are refused.  Relative file names are relative to the case file.

    description = "..."                      # free text, echoed in the summary

    [mesh]                                   # one of builtin = ... or file = ...
    builtin = "unit-square"                  # h = 64 (1/h), H = 16 (1/H: strip width), clamped = [sides],
                                             #   neumann = {side = "Gamma_N_<label>"}  (sides: left, bottom, top)
    builtin = "hertz-block"                  # a (contact half-width, required), refinement = 1,
                                             #   width = 80, depth = 40, strip = 2, contact-width = 3 (x a)
    builtin = "bulged-square"                # h = 32, H = 4, bulge = 0.1, clamped = ["left"]
    builtin = "unit-cube" | "hertz-quarter-block" | "fibre-block"   # 3D (problem.case_meshes3d)
    file = "my.msh"                          # coarse-size = H (a length) or H = 1/H: the coarse grid (multiscale
                                             #   methods) and, without Omega1/Omega2/gamma in the file, the strip;
                                             #   triangles, or tetrahedra (3D: volume groups)

    [material]                               # E and nu: required unless model is given
    E  = 1.0 | {Omega1 = 1.0, fibres = 1e3} | {pixels = "E.npy", extent = [x0, x1, y0, y1]}
         | {python = "fields.py:E"}          # a number, by cell group, a pixel map, a callable x -> (N,)
    nu = 0.3                                 # the same forms
    model = 1                                # E, nu and body force of built-in model 1, 2, 3 (2D) or 4, 5 (3D)
    E-high = 1e3                             # with model: its E in / outside the pattern
    E-low = 1.0

    [load]
    body-force = [fx, fy] | {group = [fx, fy], ...} | {python = "fields.py:f"}   # default zero

    [boundary]
    displacement = [ux, uy] | {python = "fields.py:u_D"}      # on Gamma_D; default clamped
    tractions = {Gamma_N_top = [tx, ty] | {python = ...}, ...} # one per Gamma_N group of the mesh
    rollers = {z = [0.0, 1.0]}                                 # symmetry planes: u_z = 0 on z = 0 and z = 1

    [obstacle]
    shape = "wall"                           # flush with Gamma_C, zero gap (the default)
    shape = "plane"                          # point = [x, y], normal = [nx, ny] (outward, towards the body)
    shape = "circle"                         # centre = [x, y], radius = R
    shape = "sphere"                         # centre = [x, y, z], radius = R (3D)
    indentation = 1e-3 | [2e-4, 4e-4, ...]   # rigid motion by depth x direction; a list = load steps
    direction = [dx, dy]                     # default: the plane's normal (into the body); required for a circle
                                             #   or a sphere
    motion = [[dx, dy], ...]                 # or: rigid displacements, one per load step (a sliding path)

    [friction]                               # default: frictionless
    law = "coulomb"                          # mu = 0.3 (the Coulomb coefficient)
    law = "tresca"                           # threshold = s (the slip threshold, a traction)
    stiffness-ratio = 1.0                    # the stick stiffness 1/delta_t over the normal penalty 1/delta

    [run]          method, accel, front-window, tol, max-iterations, reference, out, plots
    [primal]       alpha, delta, solver    (primal, primal-ms; solver: the monolithic reference's)
    [mixed]        beta, epsilon           (mixed, mixed-ms)
    [multiscale]   layers, nbasis, cache-dir   (primal-ms, mixed-ms)
    [mixed-ms]     min-gap, max-nbasis

On a 3D mesh every vector has three components ([fx, fy, fz], ...): a vector, an obstacle shape or a model of
the other dimension is refused naming its key (``Case.check_dimension``; for a mesh file once it is read).

The run tables use the command line's option names; the command line validates them
(``cli.RunOptions``) and its flags override them.  A method's table is used only when
that method runs, so one case runs with every method.  Cell groups (``Omega1``,
``Omega2`` and, in a gmsh file, any other surface group) set a material or a load by
group: an overlay group's value wins over its Omega group's; every cell needs a
material value.  ``overrides`` (``--set mesh.h=16``) replace single keys before the
validation.

A ``python`` reference runs that file's code: use it only with case files you trust.
"""

import codecs
import math
import tomllib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gmsh
import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.case_dimension import check_dimension
from fenics_contact.problem.case_meshes3d import BUILTINS_3D, CaseMesh, MeshSpec3D, read_mesh_3d
from fenics_contact.problem.case_values import (
    Bad,
    ByGroup,
    FieldSpec,
    Pixels,
    PythonField,
    Source,
    Table,
    Uniform,
    echo_friction,
    read_direction,
    read_field,
    read_friction,
    read_integer,
    read_number,
    read_point,
    read_points,
    read_rollers,
    read_string,
    read_strings,
    show_value,
)
from fenics_contact.problem.cell_groups import SUBDOMAIN_NAMES, CellGroups, bounding_box, read_cell_groups
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import SIDES, ContactMesh, query_gmsh_file, read_mesh, unit_square
from fenics_contact.problem.meshes import bulged_square, hertz_block
from fenics_contact.problem.models import MODELS_3D, get_model, pixel_field
from fenics_contact.problem.obstacles import Circle, Obstacle, Plane, Sphere
from fenics_contact.problem.pair_case import PairCase, read_pair_case
from fenics_contact.problem.problem import ContactProblem, Frictionless, constant_field, zero_load
from fenics_contact.problem.tags import is_neumann_name

__all__ = [
    "RUN_TABLES",
    "Case",
    "CaseMesh",
    "load_case",
    "parse_override",
    "UnitSquareMesh",
    "HertzBlockMesh",
    "BulgedSquareMesh",
    "MeshFile",
    "Uniform",
    "ByGroup",
    "Pixels",
    "PythonField",
    "Material",
    "Boundary",
    "ObstacleSpec",
]

#: the run-option tables (the command line says which methods read each: ``cli.TABLE_METHODS``)
RUN_TABLES = ("run", "primal", "mixed", "multiscale", "mixed-ms")
_PROBLEM_TABLES = ("mesh", "material", "load", "boundary", "obstacle", "friction")


# ---------------------------------------------------------------------------------------------
# meshes
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class UnitSquareMesh:
    """The structured unit square: 1/h, 1/H, the clamped sides and the traction groups by side (x = 1 is Gamma_C)."""

    h: int = 64
    H: int = 16
    clamped: tuple[str, ...] = SIDES
    neumann: tuple[tuple[str, str], ...] = ()
    kind = "unit-square"
    dim = 2
    groups = ()

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        return CaseMesh(unit_square(self.h, self.H, comm=comm, clamped=self.clamped, neumann=dict(self.neumann)), {})

    @property
    def traction_groups(self) -> set[str] | None:
        return {name for _, name in self.neumann}

    def echo(self) -> dict:
        return {
            "builtin": self.kind,
            "h": self.h,
            "H": self.H,
            "clamped": list(self.clamped),
            "neumann": dict(self.neumann),
        }


@dataclass(frozen=True, slots=True)
class BulgedSquareMesh:
    """The unit square with a curved contact side bulging out by ``bulge`` (``meshes.bulged_square``)."""

    h: int = 32
    H: int = 4
    bulge: float = 0.1
    clamped: tuple[str, ...] = ("left",)
    kind = "bulged-square"
    dim = 2
    groups = ()

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        return CaseMesh(
            bulged_square(1.0 / self.h, 1.0 / self.H, bulge=self.bulge, clamped=self.clamped, comm=comm), {}
        )

    @property
    def traction_groups(self) -> set[str] | None:
        return set()

    def echo(self) -> dict:
        return {"builtin": self.kind, "h": self.h, "H": self.H, "bulge": self.bulge, "clamped": list(self.clamped)}


@dataclass(frozen=True, slots=True)
class HertzBlockMesh:
    """The Hertz block (``meshes.hertz_block``): sizes in multiples of the contact half-width a."""

    a: float
    refinement: float = 1.0
    width: float = 80.0
    depth: float = 40.0
    strip: float = 2.0
    contact_width: float = 3.0
    kind = "hertz-block"
    dim = 2
    groups = ()

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        cm, spec = hertz_block(
            self.a,
            refinement=self.refinement,
            width=self.width,
            depth=self.depth,
            strip=self.strip,
            contact_width=self.contact_width,
            comm=comm,
        )
        return CaseMesh(cm, {}, spec)

    @property
    def traction_groups(self) -> set[str] | None:
        return set()

    def echo(self) -> dict:
        return {
            "builtin": self.kind,
            "a": self.a,
            "refinement": self.refinement,
            "width": self.width,
            "depth": self.depth,
            "strip": self.strip,
            "contact-width": self.contact_width,
        }


@dataclass(frozen=True, slots=True)
class MeshFile:
    """A gmsh file with the groups Gamma_D, Gamma_C (and Gamma_N*, material groups), and Omega1, Omega2, gamma
    or none of them (the strip is then built along Gamma_C).

    ``H`` is 1/H of the coarse grid (a unit-square mesh), ``coarse_size`` the coarse size itself (a length,
    in the mesh's units); at most one of them.
    """

    path: Path
    H: int | None = None
    coarse_size: float | None = None
    kind = "file"
    dim = None  #: known once the file is read

    @property
    def coarse(self) -> float | None:
        """The coarse size H (a length), None when the case gives none."""
        return self.coarse_size if self.coarse_size is not None else 1.0 / self.H if self.H else None

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        """The mesh; every surface group but Omega1/Omega2 is an overlay (materials), ``overlays`` must exist."""
        if self.coarse is not None and query_gmsh_file(self.path, comm, _holds_tetrahedra, False):
            key = "mesh.H" if self.H is not None else "mesh.coarse-size"
            raise InputError(
                f"{key}: {self.path.name} is a mesh of tetrahedra, which takes no coarse grid (the multiscale "
                "methods are planar): leave it out (without Omega1/Omega2/gamma in the file, the strip is then the "
                "band of cells along Gamma_C)"
            )
        centroids = read_cell_groups(self.path, overlays, comm=comm)
        cm = read_mesh(self.path, comm=comm, H=self.coarse, overlay_groups=list(centroids))
        return CaseMesh(cm, centroids)

    @property
    def traction_groups(self) -> set[str] | None:
        return None  # known once the file is read

    def echo(self) -> dict:
        return {"file": str(self.path), "H": self.H, "coarse-size": self.coarse_size}


def _holds_tetrahedra() -> bool:
    """Whether the gmsh model (a file merged by ``geometry.query_gmsh_file``) holds 3D cells."""
    return len(gmsh.model.mesh.getElementTypes(3)) > 0


MeshSpec = UnitSquareMesh | BulgedSquareMesh | HertzBlockMesh | MeshFile | MeshSpec3D
_BUILTINS = ("unit-square", "hertz-block", "bulged-square", *BUILTINS_3D)


def _mesh(source: Source, data) -> MeshSpec:
    t = Table(source, "mesh", data)
    if t.has("builtin") == t.has("file"):
        raise source.error(
            "[mesh] needs exactly one of builtin = " + " | ".join(f'"{b}"' for b in _BUILTINS) + ' and file = "my.msh"'
        )
    if t.has("file"):
        path = t.get("file", lambda v: source.file(v, "mesh.file"))
        spec = MeshFile(path, t.get("H", read_integer(1)), t.get("coarse-size", read_number(positive=True)))
        if spec.H is not None and spec.coarse_size is not None:
            raise source.error(
                "mesh.H (1/H) and mesh.coarse-size (H itself, a length) give the same coarse size: give one of them"
            )
        t.finish(" for a mesh file")
        return spec
    kind = t.get("builtin", read_string(_BUILTINS))
    if kind in BUILTINS_3D:
        spec = read_mesh_3d(source, t, kind)
        t.finish(f' for builtin = "{kind}"')
        return spec
    if kind == "hertz-block":
        positive = read_number(positive=True)
        spec = HertzBlockMesh(
            t.get("a", positive, required=True),
            t.get("refinement", positive, 1.0),
            t.get("width", positive, 80.0),
            t.get("depth", positive, 40.0),
            t.get("strip", positive, 2.0),
            t.get("contact-width", positive, 3.0),
        )
    elif kind == "bulged-square":
        spec = BulgedSquareMesh(
            t.get("h", read_integer(4), 32),
            t.get("H", read_integer(2), 4),
            t.get("bulge", read_number(low=0.0, high=0.5), 0.1),
            t.get("clamped", read_strings(SIDES), ("left",)),
        )
        if spec.H >= spec.h:
            raise source.error(f"mesh.H = {spec.H} must be < mesh.h = {spec.h} (the strip is 1/H wide)")
    else:
        spec = UnitSquareMesh(
            t.get("h", read_integer(2), 64),
            t.get("H", read_integer(2), 16),
            t.get("clamped", read_strings(SIDES), SIDES),
            _neumann_sides(source, t),
        )
        if spec.h % spec.H:
            raise source.error(
                f"mesh.h = {spec.h} is not a multiple of mesh.H = {spec.H}: the coarse grid must be "
                "a union of fine cells"
            )
        both = sorted(set(spec.clamped) & {side for side, _ in spec.neumann})
        if both:
            raise source.error(
                f"mesh.neumann: side {both[0]!r} is also in mesh.clamped: a side is clamped (Gamma_D) "
                "or carries a traction (Gamma_N), not both"
            )
    if not getattr(spec, "clamped", True):
        raise source.error(
            "mesh.clamped = [] leaves no Gamma_D: nothing holds the body, whose rigid motions make "
            "the problem singular; clamp at least one side (boundary.displacement prescribes u on "
            "the clamped sides instead of 0)"
        )
    t.finish(f' for builtin = "{kind}"')
    return spec


def _neumann_sides(source: Source, t: Table) -> tuple[tuple[str, str], ...]:
    table = t.raw("neumann")
    if table is None:
        return ()
    if not isinstance(table, dict):
        raise source.error(f'mesh.neumann must be a table {{side = "Gamma_N_<label>"}}, got {show_value(table)}')
    pairs = []
    for side, name in sorted(table.items()):
        if side not in SIDES:
            raise source.error(f"mesh.neumann.{side}: unknown side; the sides are {list(SIDES)} (x = 1 is Gamma_C)")
        if not isinstance(name, str) or not is_neumann_name(name):
            raise source.error(
                f"mesh.neumann.{side}: a traction group is named 'Gamma_N' or 'Gamma_N_<label>', got {show_value(name)}"
            )
        pairs.append((side, name))
    return tuple(pairs)


# ---------------------------------------------------------------------------------------------
# material, load, boundary conditions, obstacle
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Material:
    """Young's modulus and Poisson ratio (fields), or a built-in model's, and the body force."""

    E: FieldSpec | None = None
    nu: FieldSpec | None = None
    model: int | None = None
    E_high: float | None = None
    E_low: float | None = None
    body_force: FieldSpec | None = None

    def groups(self) -> set[str]:
        return {name for f in (self.E, self.nu, self.body_force) if isinstance(f, ByGroup) for name, _ in f.values}

    def echo(self) -> dict:
        out = {"E": self.E.echo() if self.E else None, "nu": self.nu.echo() if self.nu else None}
        if self.model is not None:
            out |= {"model": self.model, "E-high": self.E_high, "E-low": self.E_low}
        return out


_MODELS = (1, 2, 3, *MODELS_3D)


def _material(source: Source, data, load) -> Material:
    t = Table(source, "material", data or {})
    model = t.get("model", read_integer(1))
    if model is not None and model not in _MODELS:
        raise source.error(f"material.model must be 1, 2 or 3 (2D) or 4 or 5 (3D) (the built-in models), got {model}")
    E_high = t.get("E-high", read_number(positive=True))
    E_low = t.get("E-low", read_number(positive=True))
    if model is None and (E_high is not None or E_low is not None):
        raise source.error("material.E-high and material.E-low set a built-in model's moduli: they need material.model")
    E = t.raw("E")
    nu = t.raw("nu")
    E = read_field(source, "material.E", E, read_number(positive=True), vector=False) if E is not None else None
    nu = (
        read_field(source, "material.nu", nu, read_number(low=-1.0, high=0.5), vector=False) if nu is not None else None
    )
    if model is None and (E is None or nu is None):
        raise source.error(f"material.{'E' if E is None else 'nu'} is required (or material.model = 1, ..., 5)")
    t.finish()
    lt = Table(source, "load", load or {})
    force = lt.raw("body-force")
    lt.finish()
    force = (
        read_field(source, "load.body-force", force, read_point, vector=True, pixels=False)
        if force is not None
        else None
    )
    return Material(E, nu, model, E_high if model else None, E_low if model else None, force)


@dataclass(frozen=True, slots=True)
class Boundary:
    """u_D on Gamma_D (None: clamped) and the traction of every Gamma_N group."""

    displacement: Uniform | PythonField | None = None
    tractions: tuple[tuple[str, Uniform | PythonField], ...] = ()
    rollers: tuple[tuple[int, float], ...] = ()  #: symmetry planes (axis, value): u_axis = 0 there

    def conditions(self, rollers: tuple[tuple[int, float], ...] = ()) -> BoundaryConditions:
        """The conditions, with the mesh's own symmetry planes ``rollers`` added to the case's."""

        def value(spec):
            return spec.value if isinstance(spec, Uniform) else spec.function

        return BoundaryConditions(
            displacement=value(self.displacement) if self.displacement is not None else None,
            tractions={name: value(spec) for name, spec in self.tractions},
            rollers=tuple(dict.fromkeys((*self.rollers, *rollers))),
        )

    def echo(self) -> dict:
        out = {
            "displacement": self.displacement.echo() if self.displacement else "clamped",
            "tractions": {name: spec.echo() for name, spec in self.tractions},
        }
        if self.rollers:
            out["rollers"] = {"xyz"[axis]: [v for a, v in self.rollers if a == axis] for axis, _ in self.rollers}
        return out


def _vector_or_python(source: Source, key: str, value) -> Uniform | PythonField:
    spec = read_field(source, key, value, read_point, vector=True, pixels=False)
    if isinstance(spec, ByGroup):
        raise source.error(f"{key} must be a vector [x, y] or [x, y, z] or {{python = 'file.py:name'}}, got a table")
    return spec


def _boundary(source: Source, data, mesh: MeshSpec) -> Boundary:
    t = Table(source, "boundary", data or {})
    displacement = t.raw("displacement")
    tractions = t.raw("tractions")
    rollers = read_rollers(source, t.raw("rollers"))
    t.finish()
    displacement = (
        _vector_or_python(source, "boundary.displacement", displacement) if displacement is not None else None
    )
    if tractions is not None and not isinstance(tractions, dict):
        raise source.error(
            f"boundary.tractions must be a table {{Gamma_N_<label> = [tx, ty]}}, got {show_value(tractions)}"
        )
    pairs = []
    for name, value in sorted((tractions or {}).items()):
        if not is_neumann_name(name):
            raise source.error(
                f"boundary.tractions.{name}: a traction group is named 'Gamma_N' or "
                "'Gamma_N_<label>' (a facet group of the mesh)"
            )
        pairs.append((name, _vector_or_python(source, f"boundary.tractions.{name}", value)))
    known = mesh.traction_groups
    if known is not None:
        for name, _ in pairs:
            if name not in known:
                raise source.error(
                    f"boundary.tractions.{name}: the mesh has no traction group {name!r} (its groups: "
                    f"{sorted(known)}; on the unit square name one with mesh.neumann)",
                    MeshTagError,
                )
        given = {name for name, _ in pairs}
        if known - given:
            raise source.error(
                f"the mesh has the traction group {sorted(known - given)[0]!r} but "
                "boundary.tractions gives it no traction"
            )
    return Boundary(displacement, tuple(pairs), rollers)


@dataclass(frozen=True, slots=True)
class ObstacleSpec:
    """The rigid obstacle and its indentation steps (depths along ``direction``)."""

    shape: str = "wall"
    point: tuple[float, ...] | None = None
    normal: tuple[float, ...] | None = None
    centre: tuple[float, ...] | None = None
    radius: float | None = None
    depths: tuple[float, ...] = ()
    direction: tuple[float, ...] | None = None
    steps: bool = False  #: ``indentation`` was a list: load steps, a force–indentation curve
    motions: tuple[tuple[float, ...], ...] = ()  #: rigid displacements, one per load step (a sliding path)

    def base(self) -> Obstacle | None:
        """The obstacle where the case places it (None: the wall flush with Gamma_C)."""
        if self.shape == "plane":
            return Plane(self.point, self.normal)
        if self.shape == "circle":
            return Circle(self.centre, self.radius)
        if self.shape == "sphere":
            return Sphere(self.centre, self.radius)
        return None

    def at(self, depth: float) -> Obstacle:
        return self.base().indented(depth, self.direction)

    def final(self) -> Obstacle | None:
        """The obstacle at the last indentation depth or motion (the one the run solves for)."""
        if self.motions:
            return self.base().translated(self.motions[-1])
        return self.at(self.depths[-1]) if self.depths else self.base()

    def echo(self) -> dict:
        out = {"shape": self.shape}
        if self.shape == "plane":
            out |= {"point": list(self.point), "normal": list(self.normal)}
        elif self.shape in ("circle", "sphere"):
            out |= {"centre": list(self.centre), "radius": self.radius}
        if self.depths:
            out |= {
                "indentation": list(self.depths) if self.steps else self.depths[0],
                "direction": list(self.direction),
            }
        if self.motions:
            out["motion"] = [list(m) for m in self.motions]
        return out


def _obstacle(source: Source, data) -> ObstacleSpec:
    t = Table(source, "obstacle", data or {})
    shape = t.get("shape", read_string(("wall", "plane", "circle", "sphere")), "wall")
    point = normal = centre = radius = None
    if shape == "plane":
        point = t.get("point", read_point, required=True)
        normal = t.get("normal", read_direction, required=True)
    elif shape in ("circle", "sphere"):
        centre = t.get("centre", read_point, required=True)
        radius = t.get("radius", read_number(positive=True), required=True)
    indentation = t.raw("indentation")
    direction = t.get("direction", read_direction)
    motions = t.get("motion", read_points, ())
    t.finish(f' for shape = "{shape}"')
    if motions and (indentation is not None or shape == "wall"):
        raise source.error(
            "obstacle.motion moves a plane, a circle or a sphere (not the default wall) and replaces "
            "obstacle.indentation: "
            "give one of the two"
        )
    steps = isinstance(indentation, list)
    if indentation is None:
        depths = ()
    else:
        values = indentation if steps else [indentation]
        if steps and not values:
            raise source.error("obstacle.indentation is an empty list: give the depths of the load steps")
        try:
            depths = tuple(read_number()(v) for v in values)
        except Bad as bad:
            raise source.error(f"obstacle.indentation {bad}") from None
    if depths and shape == "wall":
        raise source.error(
            'obstacle.indentation moves a plane, a circle or a sphere: give shape = "plane", "circle" or "sphere" '
            "(the default wall is flush with Gamma_C)"
        )
    if direction is not None and not depths:
        raise source.error("obstacle.direction is the direction of obstacle.indentation, which is not given")
    if depths and direction is None:
        if shape != "plane":
            raise source.error(
                f"obstacle.direction is required with obstacle.indentation for a {shape} (the direction "
                f"it moves in, e.g. {'[0, -1]' if shape == 'circle' else '[0, 0, -1]'})"
            )
        direction = normal  # along its outward normal: into the body
    if direction is not None:
        length = math.hypot(*direction)
        direction = tuple(v / length for v in direction)
    return ObstacleSpec(shape, point, normal, centre, radius, depths, direction, steps, motions)


# ---------------------------------------------------------------------------------------------
# the case
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Case:
    """A validated case file: the problem (mesh, material, boundary, obstacle) and the raw run tables."""

    path: Path
    description: str
    mesh: MeshSpec
    material: Material
    boundary: Boundary
    obstacle: ObstacleSpec
    run: Mapping[str, Mapping[str, Any]]  #: {table: {option: value}} (validated by the command line)
    overrides: tuple[tuple[str, Any], ...] = ()
    friction: Friction | None = None  #: the friction law of ``[friction]`` (None: frictionless)

    def check_dimension(self, dim: int | None, where: str) -> None:
        """InputError naming the key when a vector, the obstacle's shape or the model is not of the mesh's
        dimension ``dim`` (``case_dimension.check_dimension``; ``where`` names the mesh)."""
        check_dimension(self, dim, where)

    def build_mesh(self, comm: MPI.Comm = MPI.COMM_WORLD) -> CaseMesh:
        """The mesh (collective); a mesh file's material groups are read on rank 0."""
        overlays = [name for name in self.material.groups() if name not in SUBDOMAIN_NAMES]
        return self.mesh.build(comm, overlays)

    def problem(self, mesh: CaseMesh) -> ContactProblem:
        """The problem on the built mesh (collective), the obstacle at its last depth.

        Checked here: every cell has a material (groups, pixel maps), the traction groups match the mesh's.
        """
        cm = mesh.cm
        dim = cm.mesh.topology.dim
        if self.mesh.dim is None:
            self.check_dimension(dim, f"the mesh file {self.mesh.path.name}")
        material = self.material
        groups = CellGroups(cm, mesh.overlays) if material.groups() else None
        base = None
        if material.model is not None:
            kwargs = {k: v for k, v in (("E_high", material.E_high), ("E_low", material.E_low)) if v is not None}
            base = get_model(material.model, **kwargs)
        E = self._scalar(material.E, "material.E", cm, groups, (0.0, math.inf)) if material.E else base.youngs_modulus
        nu = self._scalar(material.nu, "material.nu", cm, groups, (-1.0, 0.5)) if material.nu else base.poisson_ratio
        if material.body_force is not None:
            load = self._vector(material.body_force, groups, dim)
        elif base is not None:
            load = base.load
        else:
            load = zero_load  # (of the mesh's dimension: a 3D mesh file takes it too)
        return ContactProblem(
            name=self.path.stem,
            youngs_modulus=E,
            poisson_ratio=nu,
            load=load,
            description=self.description or f"case {self.path.name}",
            boundary=self.boundary.conditions(mesh.rollers),
            obstacle=self.obstacle.final(),
            law=self.friction or Frictionless(),
            mesh=cm,
        )

    def _scalar(
        self, spec: FieldSpec, key: str, cm: ContactMesh, groups: CellGroups | None, bounds: tuple[float, float]
    ) -> Callable:
        if isinstance(spec, Uniform):
            return constant_field(spec.value)
        if isinstance(spec, PythonField):
            return spec.function
        if isinstance(spec, Pixels):
            box = bounding_box(cm.mesh)
            extent = spec.extent or box
            _check_pixels(spec, extent, box, key, bounds, self.path)
            return pixel_field(spec.values, extent)
        fn = groups.field(dict(spec.values))
        missing = groups.uncovered(fn)
        if missing:
            raise MeshTagError(
                f"case {self.path}: {key}: {missing} cells lie in none of the groups given "
                f"({[n for n, _ in spec.values]}); give a value for Omega1 and Omega2 or for groups "
                "that cover the domain"
            )
        return fn

    def _vector(self, spec: FieldSpec, groups: CellGroups | None, dim: int) -> Callable:
        if isinstance(spec, Uniform):
            value = np.asarray(spec.value)
            return lambda x: np.repeat(value[:, None], x.shape[1], axis=1)
        if isinstance(spec, PythonField):
            return spec.function
        return groups.field(dict(spec.values), shape=(dim,), default=0.0)

    def to_dict(self, dim: int = 2) -> dict:
        """The resolved case (defaults filled in, file names absolute), for the summary; ``dim`` the mesh's."""
        return {
            "file": str(self.path),
            "description": self.description,
            "mesh": self.mesh.echo(),
            "material": self.material.echo(),
            "load": {
                "body-force": self.material.body_force.echo()
                if self.material.body_force
                else ("model" if self.material.model else [0.0] * dim)
            },
            "boundary": self.boundary.echo(),
            "obstacle": self.obstacle.echo(),
            "friction": echo_friction(self.friction),
            "overrides": {key: value for key, value in self.overrides},
        }


def _check_pixels(spec: Pixels, extent, box, key: str, bounds: tuple[float, float], path: Path) -> None:
    """The map's extent covers the mesh's bounding box, and every pixel under it lies in the open interval
    ``bounds``."""
    ny, nx = spec.values.shape
    x0, x1, y0, y1 = extent
    tol = 1e-9 * max(x1 - x0, y1 - y0, box[1] - box[0], box[3] - box[2])
    if box[0] < x0 - tol or box[1] > x1 + tol or box[2] < y0 - tol or box[3] > y1 + tol:
        raise InputError(
            f"case {path}: {key}: the pixel map {spec.path.name} covers x in [{x0:g}, {x1:g}], y in "
            f"[{y0:g}, {y1:g}], but the mesh spans x in [{box[0]:g}, {box[1]:g}], y in [{box[2]:g}, "
            f"{box[3]:g}]: give the map's extent (extent = [x0, x1, y0, y1]) so that it covers the mesh"
        )
    i0, i1 = (int(np.clip(np.floor((x - x0) / (x1 - x0) * nx), 0, nx - 1)) for x in (box[0], box[1]))
    j0, j1 = (int(np.clip(np.floor((y - y0) / (y1 - y0) * ny), 0, ny - 1)) for y in (box[2], box[3]))
    covered = spec.values[j0 : j1 + 1, i0 : i1 + 1]
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(covered) & (covered > bounds[0]) & (covered < bounds[1]))
    if np.any(bad):
        j, i = np.argwhere(bad)[0]
        raise InputError(
            f"case {path}: {key}: {np.count_nonzero(bad)} pixels of {spec.path.name} under the domain "
            f"lie outside ({bounds[0]:g}, {bounds[1]:g}) (first: row {j + j0}, column {i + i0}, value "
            f"{float(covered[j, i])!r})"
        )


def parse_override(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` (``--set``): VALUE read as a TOML value, else as a string (``mesh.builtin=unit-square``)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise InputError(f"--set {text!r}: write KEY=VALUE with a dotted key, e.g. --set mesh.h=16")
    try:
        return key, tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        return key, value.strip()


def _apply(data: dict, key: str, value, source: Source) -> None:
    parts = key.split(".")
    table = data
    for depth, part in enumerate(parts[:-1]):
        inner = table.setdefault(part, {})
        if not isinstance(inner, dict):
            raise source.error(f"override {key}: {'.'.join(parts[: depth + 1])} is not a table")
        table = inner
    table[parts[-1]] = value


def load_case(path: str | Path, overrides: Sequence[tuple[str, Any]] = ()) -> "Case | PairCase":
    """Read and validate a case file; ``overrides`` ((dotted key, value), ...) replace keys first.  A case with a
    ``[pair]`` table is one of two deformable bodies: a ``problem.pair_case.PairCase``."""
    path = Path(path).resolve()
    source = Source(path)
    if not path.is_file():
        raise InputError(f"--case {path} does not exist" if not path.exists() else f"--case {path} is not a file")
    try:
        text = path.read_bytes().removeprefix(codecs.BOM_UTF8).decode("utf-8")  # editors may write a BOM
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise source.error(f"not a valid TOML file: {err}") from None
    except OSError as err:
        raise InputError(f"cannot read the case file {path}: {err}") from None
    for key, value in overrides:
        _apply(data, key, value, source)
    if "pair" in data:  # two deformable bodies (problem.pair_case)
        return read_pair_case(source, data, tuple(overrides))
    unknown = sorted(set(data) - {"description", *_PROBLEM_TABLES, *RUN_TABLES})
    if unknown:
        raise source.error(
            f"unknown key or table {unknown[0]!r}; the tables are {[*_PROBLEM_TABLES, *RUN_TABLES]} "
            "(and the key description)"
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise source.error(f"description must be a string, got {show_value(description)}")
    if "mesh" not in data:
        raise source.error('[mesh] is required (builtin = "unit-square" | ... or file = "my.msh")')
    mesh = _mesh(source, data["mesh"])
    material = _material(source, data.get("material"), data.get("load"))
    if not isinstance(mesh, MeshFile):
        other = sorted(material.groups() - {*SUBDOMAIN_NAMES, *mesh.groups})
        if other:
            raise source.error(
                f"the cell group {other[0]!r} is named in [material]/[load], but the built-in "
                f"{mesh.kind} mesh has only {[*SUBDOMAIN_NAMES, *mesh.groups]}",
                MeshTagError,
            )
    boundary = _boundary(source, data.get("boundary"), mesh)
    obstacle = _obstacle(source, data.get("obstacle"))
    friction = read_friction(source, data.get("friction"))
    run = {}
    for table in RUN_TABLES:
        values = data.get(table, {})
        if not isinstance(values, dict):
            raise source.error(f"{table} must be a table ([{table}]), got {show_value(values)}")
        run[table] = dict(values)
    case = Case(path, description, mesh, material, boundary, obstacle, run, tuple(overrides), friction)
    case.check_dimension(mesh.dim, f'the mesh (builtin = "{mesh.kind}")')
    return case
