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
                                             #   methods; on tetrahedra the cubes holding the Omega1 cells'
                                             #   centroids) and, without Omega1/Omega2/gamma in the file, the strip;
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
    [multiscale]   layers, nbasis, cache-dir   (primal-ms, mixed-ms; nbasis a number, or "rigid" | "all" for
                                                primal-ms)
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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.case_boundary import Boundary, read_boundary
from fenics_contact.problem.case_dimension import check_dimension
from fenics_contact.problem.case_material import Material, read_material
from fenics_contact.problem.case_meshes import (
    BulgedSquareMesh,
    HertzBlockMesh,
    MeshFile,
    MeshSpec,
    UnitSquareMesh,
    read_mesh_spec,
)
from fenics_contact.problem.case_meshes3d import CaseMesh
from fenics_contact.problem.case_obstacle import ObstacleSpec, read_obstacle
from fenics_contact.problem.case_values import (
    ByGroup,
    FieldSpec,
    Pixels,
    PythonField,
    Source,
    Uniform,
    echo_friction,
    read_friction,
    show_value,
)
from fenics_contact.problem.cell_groups import SUBDOMAIN_NAMES, CellGroups, bounding_box
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.models import get_model, pixel_field
from fenics_contact.problem.pair_case import PairCase, read_pair_case
from fenics_contact.problem.problem import ContactProblem, Frictionless, constant_field, zero_load

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
    mesh = read_mesh_spec(source, data["mesh"])
    material = read_material(source, data.get("material"), data.get("load"))
    if not isinstance(mesh, MeshFile):
        other = sorted(material.groups() - {*SUBDOMAIN_NAMES, *mesh.groups})
        if other:
            raise source.error(
                f"the cell group {other[0]!r} is named in [material]/[load], but the built-in "
                f"{mesh.kind} mesh has only {[*SUBDOMAIN_NAMES, *mesh.groups]}",
                MeshTagError,
            )
    boundary = read_boundary(source, data.get("boundary"), mesh)
    obstacle = read_obstacle(source, data.get("obstacle"))
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
