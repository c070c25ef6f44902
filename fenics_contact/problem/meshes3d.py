"""Tagged tetrahedral meshes of boxes: the 3D bodies of the primal monolithic solve.

* ``box_mesh(x, y, z)``: the box over the grid planes x, y, z (increasing arrays: a graded grid
  where they are not evenly spaced), every grid hexahedron cut into six tetrahedra. Its faces are
  named by the coordinate and the side, ``FACES`` = xmin, xmax, ymin, ymax, zmin, zmax. Γ_C is
  (a part of) the face ``contact``, Γ_D the faces ``clamped``, a traction group (``Gamma_N*``) on
  each face of ``neumann``; the other faces are traction free. Ω₂ is the layer of cells within
  ``strip`` of the contact face (snapped to a grid plane), Ω₁ the rest, γ the grid plane between.
* ``unit_cube(n)``: the unit cube, h = 1/n, Γ_C the face x = 1 (the 3D ``unit_square``).
* ``graded_planes(length, fine=…, h=…)``: grid planes 0 … length, of spacing h up to ``fine`` and
  growing geometrically beyond: a mesh refined under the contact.
* ``hertz_quarter_block(a, h_contact)``: the quarter block (0, L)² × (−L, 0) under a sphere pressed at the origin,
  unstructured gmsh tetrahedra of size h_contact within ``fine`` of the origin and growing linearly with the
  distance beyond (cells of every size close to equilateral, which algebraic multigrid needs; a graded grid
  of planes stretches its cells where a fine plane crosses a coarse one).  Its coarse partition of Ω₁
  (Algorithm 3) follows the grading: boxes about ``coarse`` local cell sizes across
  (``partition.graded_coarse_cells``).

The tags follow ``tags.PHYSICAL_NAMES``; they are set by the geometry of the grid (every rank
tags its own and its ghost entities alike), so the meshes are correct by construction and are
not passed through ``validation``.
"""

from collections.abc import Callable, Mapping, Sequence

import gmsh
import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.geometry import (
    ContactMesh,
    check_memory,
    contact_mesh_from_model,
    gmsh_session,
    mesh_size,
)
from fenics_contact.problem.partition import UNRESOLVED, cartesian_coarse_cells, graded_coarse_cells
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, neumann_tag

__all__ = ["FACES", "box_mesh", "unit_cube", "graded_planes", "hertz_quarter_block", "hertz_coarse_size"]

#: The faces of a box: the coordinate and the side (min or max).
FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def _planes(values, axis: str) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size < 2 or not np.all(np.isfinite(v)) or np.any(np.diff(v) <= 0):
        raise InputError(f"the grid planes along {axis} must be at least two increasing finite numbers, got {values!r}")
    return v


def _face(name: str) -> tuple[int, int]:
    """(axis, 0 for min / 1 for max) of a face name."""
    if name not in FACES:
        raise InputError(f"unknown face {name!r}: the faces of a box are {FACES}")
    return "xyz".index(name[0]), int(name.endswith("max"))


def graded_planes(length: float, *, fine: float, h: float, growth: float = 1.25) -> np.ndarray:
    """Grid planes 0 = t₀ < … < t_m = ``length``: spacing ``h`` on [0, ``fine``], then each step ``growth``
    times the last (the steps beyond ``fine`` scaled so that the last plane is ``length``)."""
    if not (
        np.isfinite(length)
        and np.isfinite(fine)
        and np.isfinite(h)
        and 0 < h <= fine <= length
        and np.isfinite(growth)
        and growth >= 1
    ):
        raise InputError(
            f"graded_planes needs 0 < h <= fine <= length and growth >= 1, got length {length!r}, "
            f"fine {fine!r}, h {h!r}, growth {growth!r}"
        )
    n_fine = max(1, int(round(fine / h)))
    planes = list(np.linspace(0.0, fine, n_fine + 1))
    steps, step, rest = [], fine / n_fine, length - fine
    while rest > 1e-12 * length and sum(steps) < rest:
        step *= growth
        steps.append(step)
    if steps:
        steps = np.asarray(steps) * rest / sum(steps)
        planes += list(fine + np.cumsum(steps))
        planes[-1] = length
    return np.asarray(planes)


def hertz_quarter_block(
    a: float,
    h_contact: float,
    *,
    size: float = 20.0,
    fine: float = 1.25,
    growth: float = 0.3,
    strip: float = 2.0,
    coarse: float = 4.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> ContactMesh:
    """The quarter block (0, L)² × (−L, 0), L = ``size``·a, of a sphere pressed into its top at the origin
    (contact radius about a): gmsh tetrahedra of size ``h_contact`` within ``fine``·a of the origin, of size
    h(r) = h_contact + ``growth``·(r − ``fine``·a) at a distance r beyond, at most L/4.

    Γ_C the top face z = 0, Γ_D the bottom z = −L, the symmetry planes x = 0 and y = 0 and the sides traction
    free (symmetry: rollers, ``BoundaryConditions(rollers=((0, 0.0), (1, 0.0)))``); Ω₂ the layer
    z > −``strip``·a, γ the plane between.  ``h`` of the result is ``h_contact``.  The coarse cells of Ω₁
    (Algorithm 3, ``coarse_cell``) are boxes of side at most ``coarse``·h(r) at their centre's distance r
    (``hertz_coarse_size``, ``partition.graded_coarse_cells``): about ``coarse`` fine cells across, the
    smallest at the top of Ω₁ under the contact, the largest far from it.
    """
    values = (a, h_contact, size, fine, growth, strip, coarse)
    if not all(isinstance(v, (int, float, np.number)) and np.isfinite(v) and v > 0 for v in values):
        raise InputError(
            f"hertz_quarter_block needs finite a, h_contact, size, fine, growth, strip, coarse > 0, got {values}"
        )
    if not (h_contact < fine * a and strip < size and fine < size):
        raise InputError(
            f"hertz_quarter_block needs h_contact < fine·a and fine, strip < size (got h_contact {h_contact:g}, "
            f"a {a:g}, fine {fine:g}, strip {strip:g}, size {size:g})"
        )
    L = size * a
    check_memory((fine * a / h_contact) ** 3, f"the Hertz block with contact cells a/{a / h_contact:g}")
    with gmsh_session():
        if comm.rank == 0:
            _hertz_block_model(L, strip * a, fine * a, h_contact, growth)
        cm = contact_mesh_from_model(comm, h=h_contact, H=strip * a, gdim=3)
    coarse_size = hertz_coarse_size(a, h_contact, size=size, fine=fine, growth=growth, cells=coarse)
    omega1 = cm.cell_tags.find(Subdomain.OMEGA1)
    graded = graded_coarse_cells(cm.mesh, coarse_size, cells=omega1).astype(np.int32)
    return cm._replace(coarse_cell=graded, coarse_grid=False)


def hertz_coarse_size(
    a: float, h_contact: float, *, size: float = 20.0, fine: float = 1.25, growth: float = 0.3, cells: float = 4.0
) -> Callable[[np.ndarray], np.ndarray]:
    """x (3, k) ↦ ``cells``·h(r), r = |x|: the coarse size of ``hertz_quarter_block`` (h(r) its cell size at the
    distance r from the first contact point, h_contact + ``growth``·(r − ``fine``·a) beyond ``fine``·a, at most
    ``size``·a/4)."""

    def coarse_size(x: np.ndarray) -> np.ndarray:
        r = np.linalg.norm(x, axis=0)
        h = np.minimum(h_contact + growth * np.maximum(r - fine * a, 0.0), size * a / 4)
        return cells * h

    return coarse_size


def _hertz_block_model(L: float, depth: float, r_fine: float, h: float, growth: float) -> None:
    """The gmsh model of ``hertz_quarter_block`` (rank 0, in a gmsh session): two boxes, their faces grouped."""
    occ = gmsh.model.occ
    gmsh.model.add("hertz block")
    occ.fragment([(3, occ.addBox(0, 0, -depth, L, L, depth))], [(3, occ.addBox(0, 0, -L, L, L, L - depth))])
    occ.synchronize()
    volumes = sorted((occ.getCenterOfMass(3, t)[2], t) for _, t in gmsh.model.getEntities(3))
    tol = 1e-6 * L  # (gmsh pads bounding boxes by its geometry tolerance)
    faces = {Boundary.GAMMA_C: [], Boundary.GAMMA_D: [], Boundary.INTERFACE: []}
    for _, t in gmsh.model.getEntities(2):
        z = occ.getCenterOfMass(2, t)[2]
        zmin, zmax = gmsh.model.getBoundingBox(2, t)[2::3]
        if zmax - zmin < tol:  # a horizontal face: the top, the bottom, or γ
            key = Boundary.GAMMA_C if abs(z) < tol else Boundary.GAMMA_D if abs(z + L) < tol else Boundary.INTERFACE
            faces[key].append(t)
    gmsh.model.addPhysicalGroup(3, [volumes[0][1]], int(Subdomain.OMEGA1), name=PHYSICAL_NAMES[Subdomain.OMEGA1])
    gmsh.model.addPhysicalGroup(3, [volumes[1][1]], int(Subdomain.OMEGA2), name=PHYSICAL_NAMES[Subdomain.OMEGA2])
    for tag, surfaces in faces.items():
        gmsh.model.addPhysicalGroup(2, surfaces, int(tag), name=PHYSICAL_NAMES[tag])
    centre = [t for _, t in gmsh.model.getEntitiesInBoundingBox(-tol, -tol, -tol, tol, tol, tol, 0)]
    field = gmsh.model.mesh.field
    distance = field.add("Distance")
    field.setNumbers(distance, "PointsList", centre)
    coarse = L / 4
    threshold = field.add("Threshold")
    field.setNumber(threshold, "InField", distance)
    field.setNumber(threshold, "SizeMin", h)
    field.setNumber(threshold, "SizeMax", coarse)
    field.setNumber(threshold, "DistMin", r_fine)
    field.setNumber(threshold, "DistMax", r_fine + (coarse - h) / growth)
    field.setAsBackgroundMesh(threshold)
    for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(option, 0)
    # Netgen's optimization: better shaped tetrahedra (a/20: the L² pressure error 3.1 % instead of 4.0 %)
    gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
    gmsh.model.mesh.generate(3)


def box_mesh(
    x: Sequence[float],
    y: Sequence[float],
    z: Sequence[float],
    *,
    contact: str = "zmax",
    contact_region: Callable[[np.ndarray], np.ndarray] | None = None,
    clamped: Sequence[str] = ("zmin",),
    neumann: Mapping[str, str] | None = None,
    strip: float | None = None,
    H: float | None = None,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> ContactMesh:
    """The tagged tetrahedral mesh of the box over the grid planes ``x``, ``y``, ``z``.

    Γ_C: the facets of the face ``contact`` whose vertices x (3, k) satisfy ``contact_region`` (default:
    the whole face); Γ_D: the faces ``clamped``; ``neumann``: face -> traction group name (``Gamma_N*``);
    Ω₂: the cells within ``strip`` (default: a quarter of the box across the contact face, snapped to the
    nearest grid plane) of the contact face. ``h`` of the result is ``mesh_size`` on Γ_C; ``H`` (optional) the
    coarse grid of the multiscale methods: cubes of side H over the box (``partition.cartesian_coarse_cells``).
    """
    planes = [_planes(v, a) for v, a in zip((x, y, z), "xyz")]
    check_memory(
        float(np.prod([p.size for p in planes])), f"the box of {' x '.join(str(p.size - 1) for p in planes)} grid cells"
    )
    contact_axis, contact_side = _face(contact)
    clamped = tuple(clamped)
    neumann = dict(neumann or {})
    for face in (*clamped, *neumann):
        _face(face)
    if contact in clamped or contact in neumann:
        raise InputError(f"the contact face {contact!r} cannot also be clamped or carry a traction group")
    both = sorted(set(clamped) & set(neumann))
    if both:
        raise InputError(f"face(s) {both} cannot be clamped (Gamma_D) and carry a traction group (Gamma_N) at once")
    for name in neumann.values():
        neumann_tag(name)  # validates the name
    if not clamped:
        raise InputError("box_mesh needs at least one clamped face (Gamma_D): the rigid motions would be free")

    n = [p.size - 1 for p in planes]
    msh = dmesh.create_box(comm, [np.zeros(3), np.asarray(n, dtype=np.float64)], n, dmesh.CellType.tetrahedron)
    xg = msh.geometry.x
    for axis in range(3):  # the integer grid i ↦ the grid plane planes[axis][i]
        xg[:, axis] = np.interp(xg[:, axis], np.arange(n[axis] + 1, dtype=np.float64), planes[axis])

    tdim = msh.topology.dim
    lo, hi = np.array([p[0] for p in planes]), np.array([p[-1] for p in planes])
    tol = 1e-10 * float(np.max(hi - lo))

    def on_face(name: str) -> Callable[[np.ndarray], np.ndarray]:
        axis, side = _face(name)
        value = hi[axis] if side else lo[axis]
        return lambda p: np.abs(p[axis] - value) < tol

    across = planes[contact_axis]
    depth = 0.25 * (across[-1] - across[0]) if strip is None else float(strip)
    if not (np.isfinite(depth) and depth > 0):
        raise InputError(f"the strip width must be > 0, got {strip!r}")
    distance = across[-1] - across if contact_side else across - across[0]
    inner = [i for i in range(1, across.size - 1)]
    if not inner:
        raise InputError(f"box_mesh needs at least two cells across the contact face {contact!r} (Omega1 and Omega2)")
    k = min(inner, key=lambda i: abs(distance[i] - depth))
    gamma_value = across[k]

    facets, values = [], []

    def add(found: np.ndarray, tag: int) -> None:
        facets.append(found.astype(np.int32))
        values.append(np.full(found.size, tag, dtype=np.int32))

    face_c = on_face(contact)
    region = contact_region or (lambda p: np.ones(p.shape[1], dtype=bool))
    add(
        dmesh.locate_entities_boundary(msh, tdim - 1, lambda p: face_c(p) & np.asarray(region(p), dtype=bool)),
        Boundary.GAMMA_C,
    )
    for face in clamped:
        add(dmesh.locate_entities_boundary(msh, tdim - 1, on_face(face)), Boundary.GAMMA_D)
    for face, name in sorted(neumann.items()):
        add(dmesh.locate_entities_boundary(msh, tdim - 1, on_face(face)), neumann_tag(name))
    add(dmesh.locate_entities(msh, tdim - 1, lambda p: np.abs(p[contact_axis] - gamma_value) < tol), Boundary.INTERFACE)
    entities, tags = np.concatenate(facets), np.concatenate(values)
    order = np.argsort(entities, kind="stable")
    entities, tags = entities[order], tags[order]
    if np.any(np.diff(entities) == 0):
        raise InputError(
            "box_mesh: a facet lies in two groups (a clamped face, a traction face and the contact "
            "face must be different faces)"
        )
    facet_tags = dmesh.meshtags(msh, tdim - 1, entities, tags)

    imap = msh.topology.index_map(tdim)
    cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    mid = dmesh.compute_midpoints(msh, tdim, cells)[:, contact_axis]
    in_strip = (mid > gamma_value) if contact_side else (mid < gamma_value)
    cell_tags = dmesh.meshtags(
        msh, tdim, cells, np.where(in_strip, int(Subdomain.OMEGA2), int(Subdomain.OMEGA1)).astype(np.int32)
    )
    names = {neumann_tag(name): name for name in neumann.values()}
    coarse = np.full(cells.size, UNRESOLVED, dtype=np.int32)
    if H is not None:
        coarse = cartesian_coarse_cells(msh, H)[0].astype(np.int32)
        H = float(H)
    return ContactMesh(msh, cell_tags, facet_tags, mesh_size(msh, facet_tags), H, coarse, names or None)


def unit_cube(
    n: int,
    *,
    clamped: Sequence[str] = ("xmin",),
    neumann: Mapping[str, str] | None = None,
    strip: float | None = None,
    H: float | None = None,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> ContactMesh:
    """The tagged mesh of (0, 1)³ with h = 1/n: Γ_C the face x = 1, Γ_D the faces ``clamped``, traction groups
    on the faces of ``neumann``, the other faces traction free; Ω₂ the layer x > 1 − ``strip`` (default ¼);
    ``H`` the coarse grid of cubes of side H (multiscale methods; None: no coarse grid)."""
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 2:
        raise InputError(f"unit_cube needs an integer n >= 2 (h = 1/n), got {n!r}")
    planes = np.linspace(0.0, 1.0, int(n) + 1)
    return box_mesh(
        planes, planes, planes, contact="xmax", clamped=clamped, neumann=neumann, strip=strip, H=H, comm=comm
    )
