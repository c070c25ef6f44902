"""The ``[mesh]`` table of a case file: the planar built-in meshes and a gmsh file (``problem.case``).

``read_mesh_spec`` reads the table into a mesh specification, a small frozen dataclass that builds its
``CaseMesh`` (collective) and echoes its resolved keys; the 3D built-in meshes are read by
``problem.case_meshes3d``. A value that is not what its key asks for is an InputError naming the key.
"""

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from mpi4py import MPI

from fenics_contact.problem.case_meshes3d import BUILTINS_3D, CaseMesh, MeshSpec3D, read_mesh_3d
from fenics_contact.problem.case_values import (
    Source,
    Table,
    read_integer,
    read_number,
    read_string,
    read_strings,
    show_value,
)
from fenics_contact.problem.cell_groups import read_cell_groups
from fenics_contact.problem.geometry import SIDES, read_mesh, unit_square
from fenics_contact.problem.meshes import bulged_square, hertz_block
from fenics_contact.problem.tags import is_neumann_name

__all__ = ["UnitSquareMesh", "BulgedSquareMesh", "HertzBlockMesh", "MeshFile", "read_mesh_spec"]


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
    in the mesh's units); at most one of them.  The coarse cells are the squares of that side over the bounding box
    (the mesh must resolve them), on a mesh of tetrahedra the cubes that hold the Ω₁ cells' centroids
    (``geometry.read_mesh``).
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
        centroids = read_cell_groups(self.path, overlays, comm=comm)
        cm = read_mesh(self.path, comm=comm, H=self.coarse, overlay_groups=list(centroids))
        return CaseMesh(cm, centroids)

    @property
    def traction_groups(self) -> set[str] | None:
        return None  # known once the file is read

    def echo(self) -> dict:
        return {"file": str(self.path), "H": self.H, "coarse-size": self.coarse_size}


MeshSpec = UnitSquareMesh | BulgedSquareMesh | HertzBlockMesh | MeshFile | MeshSpec3D
_BUILTINS = ("unit-square", "hertz-block", "bulged-square", *BUILTINS_3D)


def read_mesh_spec(source: Source, data) -> MeshSpec:
    """The mesh specification of the ``[mesh]`` table ``data`` (exactly one of ``builtin`` and ``file``)."""
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
