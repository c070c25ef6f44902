"""Interfaces γ that bend, for the mixed methods' tests: the zigzag of an automatic band along Γ_C and a box-shaped
strip under part of the contact side (model 2, inclusions of E = 10³)."""

from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.problem import strip
from fenics_contact.problem.geometry import ContactMesh, unit_square
from fenics_contact.problem.models import model_2
from fenics_contact.problem.tags import Boundary

#: the band's width: γ cuts the columns of triangles between their centroids (a zigzag at n = 16 and 24)
WIDTH = 0.15


def zigzag_problem(n: int, H: float | None = None, comm: MPI.Comm = MPI.COMM_WORLD):
    """Model 2 on unit_square(n) with Ω₂ the band of width ``WIDTH`` along Γ_C (``H``: coarse cells of side H)."""
    cm = unit_square(n, 4, comm=comm)
    keep = cm.facet_tags.values != Boundary.INTERFACE  # the physics tags alone, as on a user's mesh
    tags = dmesh.meshtags(cm.mesh, 1, cm.facet_tags.indices[keep], cm.facet_tags.values[keep])
    split = strip.automatic_split(cm.mesh, tags, H=H, width=WIDTH)
    return model_2().on(ContactMesh(cm.mesh, split.cell_tags, split.facet_tags, cm.h, split.H, split.coarse_cell))


def box_problem(n: int, E_high: float = 1.0e3):
    """Model 2 (``E_high`` in the inclusions) on unit_square(n) with Γ_C the middle of the right side
    (0.3 < y < 0.7) and Ω₂ the two squares of side 1/4 along it: γ is the box's boundary, bending at
    (0.75, 0.25) and (0.75, 0.75) by a right angle, its ends on the traction-free rest of the side."""
    cm = unit_square(n, 4)
    ft = cm.facet_tags
    y = cm.mesh.geometry.x[dmesh.entities_to_geometry(cm.mesh, 1, ft.indices)][:, :, 1].mean(axis=1)
    contact = (y > 0.3) & (y < 0.7)
    keep = (ft.values != Boundary.INTERFACE) & ((ft.values != Boundary.GAMMA_C) | contact)
    tags = dmesh.meshtags(cm.mesh, 1, ft.indices[keep], ft.values[keep])
    split = strip.automatic_split(cm.mesh, tags, H=0.25)
    box = ContactMesh(cm.mesh, split.cell_tags, split.facet_tags, cm.h, split.H, split.coarse_cell)
    return model_2(E_high=E_high).on(box)
