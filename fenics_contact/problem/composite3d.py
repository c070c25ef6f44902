"""The built-in 3D fibre composite (model 5): a block with stiff fibres along y, some crossing γ into the strip.

* **Body and boundary** (``fibre_block_3d_mesh``, gmsh tetrahedra): Ω = (0, 1)³, Γ_C the face x = 1, Γ_D the
  face x = 0 (clamped), the other faces traction free. Ω₂ is the layer x > 1 − ``strip`` (default ¼), γ the
  plane between; the mesh carries them as the groups Omega1, Omega2 and gamma.
* **Fibres** (``FIBRES_3D``): prisms along y through the whole block whose section is the regular polygon of
  ``FIBRE_SIDES`` sides inscribed in the circle of radius ``FIBRE_RADIUS`` about (x, z): faceted cylinders,
  conforming to the mesh. Two lie deep in Ω₁, one at mid-depth, two are cut by γ at x = ¾ (they cross γ into
  the strip) and one lies in Ω₂ under the middle of Γ_C, 0.06 below it. E = ``E_high`` in the fibres (contrast up
  to 1e6), ``E_low`` in the matrix, ν = 0.35. The fibres' faces are faces of the mesh and the sections are
  convex, so a cell's midpoint lies in a fibre exactly when the cell does: the modulus is a function of x.
* **Load** (in Ω₁, for a run against the flush wall): f = (f₁, 0, 0) on the slab 0.4 < x < 0.6, f₁ = 1 for
  y < ½ (pushes onto the wall) and f₁ = −1 for y > ¾ (pulls away). An indentation replaces it by an obstacle
  (``demos/demo_sphere_composite_3d.py``: a sphere pressed into the middle of Γ_C).

``contact_size`` refines the mesh within ``contact_radius`` of the middle (1, ½, ½) of Γ_C (a gmsh ball field).
"""

import math

import gmsh
import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import ContactMesh, check_memory, contact_mesh_from_model, gmsh_session
from fenics_contact.problem.models3d import slab_load
from fenics_contact.problem.problem import ContactProblem, ScalarField, constant_field
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain

__all__ = [
    "CONTACT_CENTRE_3D",
    "FIBRES_3D",
    "FIBRE_RADIUS",
    "FIBRE_SIDES",
    "MODEL_COMPOSITE_3D",
    "fibre_block_3d",
    "fibre_block_3d_mesh",
    "in_fibres",
]

#: the number of the 3D fibre composite among the built-in models (``models.get_model``, ``--model``)
MODEL_COMPOSITE_3D = 5
#: the fibre axes (x, z): each fibre runs along y through the block
FIBRES_3D = ((0.3, 0.25), (0.3, 0.75), (0.55, 0.5), (0.75, 0.25), (0.75, 0.75), (0.88, 0.5))
#: the radius of the circle each fibre's polygonal section is inscribed in
FIBRE_RADIUS = 0.06
#: the number of sides of a fibre's section
FIBRE_SIDES = 12
#: the middle of Γ_C, where the mesh is refined (``contact_size``) and the demo's sphere touches
CONTACT_CENTRE_3D = (1.0, 0.5, 0.5)
_LOAD_SLAB = (0.4, 0.6)


def _section(xc: float, zc: float) -> np.ndarray:
    """The vertices (FIBRE_SIDES, 2) in (x, z) of a fibre's section, counter-clockwise."""
    angles = 2.0 * np.pi * np.arange(FIBRE_SIDES) / FIBRE_SIDES
    return np.column_stack([xc + FIBRE_RADIUS * np.cos(angles), zc + FIBRE_RADIUS * np.sin(angles)])


def in_fibres(x: np.ndarray) -> np.ndarray:
    """Whether each point x (3, N) lies strictly inside a fibre (inside every edge of its convex section)."""
    inside = np.zeros(np.shape(x)[1], dtype=bool)
    for xc, zc in FIBRES_3D:
        v = _section(xc, zc)
        edge = np.roll(v, -1, axis=0) - v
        # the cross product of each edge with the vector to the point: > 0 left of every edge (counter-clockwise)
        cross = edge[:, 0, None] * (x[2][None, :] - v[:, 1, None]) - edge[:, 1, None] * (x[0][None, :] - v[:, 0, None])
        inside |= np.all(cross > 0.0, axis=0)
    return inside


def _fibre_modulus(E_high: float, E_low: float) -> ScalarField:
    def field(x: np.ndarray) -> np.ndarray:
        return np.where(in_fibres(x), E_high, E_low)

    return field


def fibre_block_3d(
    *, E_high: float = 1.0e3, E_low: float = 1.0, nu: float = 0.35, load_scale: float = 1.0
) -> ContactProblem:
    """The 3D fibre composite (module docstring): stiff fibres along y, two crossing γ, one in the strip, the load
    in Ω₁, clamped at x = 0; put it on ``fibre_block_3d_mesh(n)``."""
    return ContactProblem(
        name="model5",
        youngs_modulus=_fibre_modulus(float(E_high), float(E_low)),
        poisson_ratio=constant_field(nu),
        load=slab_load(float(load_scale), _LOAD_SLAB),
        boundary=BoundaryConditions(),
        description=f"3D fibre composite, E={E_high:g}/{E_low:g}, nu={nu:g}",
    )


def fibre_block_3d_mesh(
    n: int,
    *,
    strip: float | None = None,
    contact_size: float | None = None,
    contact_radius: float = 0.25,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> ContactMesh:
    """The gmsh tetrahedra of the fibre block, size 1/n (``contact_size`` within ``contact_radius`` of the middle
    of Γ_C, growing to 1/n over as far again); Ω₂ the layer x > 1 − ``strip`` (default ¼).  ``h`` of the result
    is the size at the contact."""
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 2:
        raise InputError(f"fibre_block_3d_mesh needs an integer n >= 2 (h = 1/n), got {n!r}")
    h = 1.0 / int(n)
    strip = 0.25 if strip is None else strip
    fine = h if contact_size is None else contact_size
    values = (strip, fine, contact_radius)
    if not all(isinstance(v, (int, float, np.number)) and math.isfinite(v) and v > 0 for v in values):
        raise InputError(f"fibre_block_3d_mesh needs finite strip, contact_size, contact_radius > 0, got {values}")
    if not (strip < 1.0 and fine <= h and contact_radius < 1.0):
        raise InputError(
            f"fibre_block_3d_mesh needs strip < 1, contact_size <= 1/n and contact_radius < 1 (got strip {strip:g}, "
            f"contact_size {fine:g}, 1/n {h:g}, contact_radius {contact_radius:g})"
        )
    check_memory(
        1.0 / h**3 + (contact_radius / fine) ** 3, f"the fibre block with cells 1/{n}, {fine:g} at the contact"
    )
    with gmsh_session():
        if comm.rank == 0:
            _fibre_block_model(1.0 - strip, h, fine, contact_radius)
        cm = contact_mesh_from_model(comm, h=fine, H=strip, gdim=3)
    return cm


def _fibre_block_model(gamma: float, h: float, fine: float, radius: float) -> None:
    """The gmsh model of ``fibre_block_3d_mesh`` (rank 0, in a gmsh session): two boxes split at x = ``gamma``
    and the fibre prisms, fragmented into conforming volumes, grouped."""
    occ = gmsh.model.occ
    gmsh.model.add("fibre block")
    boxes = [(3, occ.addBox(0, 0, 0, gamma, 1, 1)), (3, occ.addBox(gamma, 0, 0, 1 - gamma, 1, 1))]
    fibres = []
    for xc, zc in FIBRES_3D:
        points = [occ.addPoint(px, 0.0, pz) for px, pz in _section(xc, zc)]
        lines = [occ.addLine(points[k], points[(k + 1) % len(points)]) for k in range(len(points))]
        face = occ.addPlaneSurface([occ.addCurveLoop(lines)])
        fibres += [e for e in occ.extrude([(2, face)], 0.0, 1.0, 0.0) if e[0] == 3]
    occ.fragment(boxes, fibres)
    occ.synchronize()
    tol = 1e-9
    sides = {Subdomain.OMEGA1: [], Subdomain.OMEGA2: []}
    for _, t in gmsh.model.getEntities(3):
        key = Subdomain.OMEGA1 if occ.getCenterOfMass(3, t)[0] < gamma else Subdomain.OMEGA2
        sides[key].append(t)
    faces = {Boundary.GAMMA_C: [], Boundary.GAMMA_D: [], Boundary.INTERFACE: []}
    for _, t in gmsh.model.getEntities(2):
        xmin, xmax = gmsh.model.getBoundingBox(2, t)[0::3]
        if xmax - xmin < 1e-4:  # a face in a plane x = const (gmsh pads bounding boxes, by up to about 1e-6)
            x = occ.getCenterOfMass(2, t)[0]
            for key, at in ((Boundary.GAMMA_C, 1.0), (Boundary.GAMMA_D, 0.0), (Boundary.INTERFACE, gamma)):
                if abs(x - at) < tol:
                    faces[key].append(t)
    for tag, volumes in sides.items():
        gmsh.model.addPhysicalGroup(3, volumes, int(tag), name=PHYSICAL_NAMES[tag])
    for tag, surfaces in faces.items():
        gmsh.model.addPhysicalGroup(2, surfaces, int(tag), name=PHYSICAL_NAMES[tag])
    field = gmsh.model.mesh.field
    ball = field.add("Ball")
    for key, value in zip(("XCenter", "YCenter", "ZCenter"), CONTACT_CENTRE_3D):
        field.setNumber(ball, key, value)
    field.setNumber(ball, "Radius", radius)
    field.setNumber(ball, "Thickness", radius)
    field.setNumber(ball, "VIn", fine)
    field.setNumber(ball, "VOut", h)
    field.setAsBackgroundMesh(ball)
    for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(option, 0)
    gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
    gmsh.model.mesh.generate(3)
