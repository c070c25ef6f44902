"""The built-in 3D meshes of a case file (tetrahedra): ``[mesh] builtin = "unit-cube" | "hertz-quarter-block" |
"fibre-block"``.

    builtin = "unit-cube"             # h = 8 (1/h), H = 4 (1/H: the strip x > 1 - 1/H and the coarse cubes),
                                      #   clamped = ["xmin"] (faces), neumann = {face = "Gamma_N_<label>"}; Gamma_C
                                      #   the face x = 1
    builtin = "hertz-quarter-block"   # a (contact radius, required), refinement = 1 (contact cells a/(20 r)),
                                      #   size = 20, strip = 2, coarse-size (x a; primal-ms: the coarse cubes);
                                      #   the symmetry planes x = 0, y = 0 on rollers
    builtin = "fibre-block"           # model 5's block: h = 8, H = 4 (the strip and the coarse cubes),
                                      #   contact-size = 1/h, contact-radius = 0.25; cell groups fibres and matrix

The faces of a box are ``meshes3d.FACES`` (xmin, xmax, ymin, ymax, zmin, zmax).  Each spec builds a
``case.CaseMesh`` (through ``build``) and echoes its resolved keys for the summary.  The coarse grid of Algorithm 3
(``ContactMesh.coarse_cell``) is the cubes of side 1/H over the unit cube (which the unit cube's cells resolve), and
on the gmsh meshes of the fibre block and the Hertz block the cubes that hold the Ω₁ cells' centroids
(``strip.omega1_coarse_cells``: unions of whole tetrahedra, which Algorithm 3 takes as any coarse partition).
"""

from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.problem.case_values import Source, Table, read_integer, read_number, read_strings
from fenics_contact.problem.composite3d import fibre_block_3d_mesh, in_fibres
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.meshes3d import FACES, hertz_quarter_block, unit_cube
from fenics_contact.problem.strip import omega1_coarse_cells
from fenics_contact.problem.tags import is_neumann_name

__all__ = ["BUILTINS_3D", "CaseMesh", "FibreBlockMesh", "HertzQuarterBlockMesh", "UnitCubeMesh", "read_mesh_3d"]

#: the names of the built-in 3D meshes
BUILTINS_3D = ("unit-cube", "hertz-quarter-block", "fibre-block")
#: the cell groups of the fibre block (materials by group)
FIBRE_GROUPS = ("fibres", "matrix")
#: the faces of the unit cube that may be clamped or carry a traction (xmax is Gamma_C)
_SIDE_FACES = tuple(face for face in FACES if face != "xmax")


class CaseMesh(NamedTuple):
    """A built mesh with the case's cell groups (overlay centroids), for the Hertz block its sizes, and the
    symmetry planes (axis, value) the mesh holds on rollers."""

    cm: ContactMesh
    overlays: dict
    hertz: object | None = None
    rollers: tuple[tuple[int, float], ...] = ()


@dataclass(frozen=True, slots=True)
class UnitCubeMesh:
    """The structured unit cube (``meshes3d.unit_cube``): 1/h, 1/H (the strip), the clamped faces and the traction
    groups by face (x = 1 is Gamma_C)."""

    h: int = 8
    H: int = 4
    clamped: tuple[str, ...] = ("xmin",)
    neumann: tuple[tuple[str, str], ...] = ()
    kind = "unit-cube"
    dim = 3
    groups = ()

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        H = 1.0 / self.H
        cm = unit_cube(self.h, clamped=self.clamped, neumann=dict(self.neumann), strip=H, H=H, comm=comm)
        return CaseMesh(cm, {})

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
class HertzQuarterBlockMesh:
    """The quarter block under a sphere (``meshes3d.hertz_quarter_block``): sizes in multiples of the contact
    radius a, contact cells a/(20·refinement), the symmetry planes x = 0 and y = 0 on rollers; with
    ``coarse_size`` the coarse cubes of side ``coarse_size``·a over the block (Algorithm 3)."""

    a: float
    refinement: float = 1.0
    size: float = 20.0
    strip: float = 2.0
    coarse_size: float | None = None
    kind = "hertz-quarter-block"
    dim = 3
    groups = ()

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        h = self.a / (20.0 * self.refinement)
        cm = hertz_quarter_block(self.a, h, size=self.size, strip=self.strip, comm=comm)
        if self.coarse_size is not None:
            H = self.coarse_size * self.a
            cm = cm._replace(H=H, coarse_cell=omega1_coarse_cells(cm.mesh, cm.cell_tags, H), coarse_grid=True)
        return CaseMesh(cm, {}, None, ((0, 0.0), (1, 0.0)))

    @property
    def traction_groups(self) -> set[str] | None:
        return set()

    def echo(self) -> dict:
        return {
            "builtin": self.kind,
            "a": self.a,
            "refinement": self.refinement,
            "size": self.size,
            "strip": self.strip,
            "coarse-size": self.coarse_size,
            "rollers": {"x": [0.0], "y": [0.0]},  # (the symmetry planes the mesh holds)
        }


@dataclass(frozen=True, slots=True)
class FibreBlockMesh:
    """The block of the fibre composite (``composite3d.fibre_block_3d_mesh``): 1/h, 1/H (the strip and the coarse
    cubes), the cells near the middle of Gamma_C; its cell groups ``fibres`` and ``matrix``."""

    h: int = 8
    H: int = 4
    contact_size: float | None = None
    contact_radius: float = 0.25
    kind = "fibre-block"
    dim = 3
    groups = FIBRE_GROUPS

    def build(self, comm: MPI.Comm, overlays: Iterable[str] = ()) -> CaseMesh:
        cm = fibre_block_3d_mesh(
            self.h,
            strip=1.0 / self.H,
            contact_size=self.contact_size,
            contact_radius=self.contact_radius,
            comm=comm,
        )
        cm = cm._replace(coarse_cell=omega1_coarse_cells(cm.mesh, cm.cell_tags, 1.0 / self.H))
        msh = cm.mesh
        owned = np.arange(msh.topology.index_map(3).size_local, dtype=np.int32)
        midpoints = np.concatenate(comm.allgather(dmesh.compute_midpoints(msh, 3, owned)))
        fibre = in_fibres(midpoints.T)
        return CaseMesh(cm, {"fibres": midpoints[fibre], "matrix": midpoints[~fibre]})

    @property
    def traction_groups(self) -> set[str] | None:
        return set()

    def echo(self) -> dict:
        return {
            "builtin": self.kind,
            "h": self.h,
            "H": self.H,
            "contact-size": self.contact_size if self.contact_size is not None else 1.0 / self.h,
            "contact-radius": self.contact_radius,
        }


MeshSpec3D = UnitCubeMesh | HertzQuarterBlockMesh | FibreBlockMesh


def read_mesh_3d(source: Source, t: Table, kind: str) -> MeshSpec3D:
    """The built-in 3D mesh ``kind`` from the keys of the ``[mesh]`` table ``t`` (which the caller finishes)."""
    positive = read_number(positive=True)
    if kind == "hertz-quarter-block":
        spec = HertzQuarterBlockMesh(
            t.get("a", positive, required=True),
            t.get("refinement", read_number(low=0.05, high=np.inf), 1.0),
            t.get("size", read_number(low=2.0, high=np.inf), 20.0),
            t.get("strip", positive, 2.0),
            t.get("coarse-size", positive),
        )
        if spec.strip >= spec.size:
            raise source.error(f"mesh.strip = {spec.strip:g} must be < mesh.size = {spec.size:g} (both times a)")
        if spec.coarse_size is not None and spec.coarse_size > spec.size / 2:
            raise source.error(
                f"mesh.coarse-size = {spec.coarse_size:g} must be at most half of mesh.size = {spec.size:g} (both "
                "times a): Algorithm 3 needs at least two coarse cubes along the block"
            )
        return spec
    if kind == "fibre-block":
        spec = FibreBlockMesh(
            t.get("h", read_integer(2), 8),
            t.get("H", read_integer(2), 4),
            t.get("contact-size", positive),
            t.get("contact-radius", read_number(low=0.0, high=1.0), 0.25),
        )
        if spec.contact_size is not None and spec.contact_size > 1.0 / spec.h:
            raise source.error(
                f"mesh.contact-size = {spec.contact_size:g} must be at most the cell size 1/h = {1.0 / spec.h:g}: "
                "it refines the mesh under the contact"
            )
        return spec
    spec = UnitCubeMesh(
        t.get("h", read_integer(2), 8),
        t.get("H", read_integer(2), 4),
        t.get("clamped", read_strings(_SIDE_FACES), ("xmin",)),
        _neumann_faces(source, t),
    )
    if spec.H >= spec.h or spec.h % spec.H:
        raise source.error(
            f"mesh.h = {spec.h} must be a multiple of mesh.H = {spec.H} and larger: the strip x > 1 - 1/H is a "
            "union of cell layers, at least one"
        )
    if not spec.clamped:
        raise source.error(
            "mesh.clamped = [] leaves no Gamma_D: nothing holds the body, whose rigid motions make the problem "
            'singular; clamp at least one face (e.g. ["xmin"])'
        )
    both = sorted(set(spec.clamped) & {face for face, _ in spec.neumann})
    if both:
        raise source.error(
            f"mesh.neumann: face {both[0]!r} is also in mesh.clamped: a face is clamped (Gamma_D) or carries a "
            "traction (Gamma_N), not both"
        )
    return spec


def _neumann_faces(source: Source, t: Table) -> tuple[tuple[str, str], ...]:
    table = t.raw("neumann")
    if table is None:
        return ()
    if not isinstance(table, dict):
        raise source.error(f'mesh.neumann must be a table {{face = "Gamma_N_<label>"}}, got {table!r}')
    pairs = []
    for face, name in sorted(table.items()):
        if face not in _SIDE_FACES:
            raise source.error(
                f"mesh.neumann.{face}: unknown face; the faces are {list(_SIDE_FACES)} (xmax is Gamma_C)"
            )
        if not isinstance(name, str) or not is_neumann_name(name):
            raise source.error(
                f"mesh.neumann.{face}: a traction group is named 'Gamma_N' or 'Gamma_N_<label>', got {name!r}"
            )
        pairs.append((face, name))
    return tuple(pairs)
