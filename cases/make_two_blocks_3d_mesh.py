"""Make ``cases/two_blocks_3d.msh``: a block pressed onto a larger block with a stiff inclusion, in millimetres,
meshed by gmsh into tetrahedra.

The lower block x, y ∈ [0, 20] mm, z ∈ [−10, 0] mm holds a stiff box inclusion x, y ∈ [6, 14] mm, z ∈ [−7, −3] mm
(volume group ``lower_inclusion``; the rest ``lower_matrix``); the upper block x, y ∈ [4, 16] mm, z ∈ [0, 8] mm
(``upper``) rests on it. The two blocks touch on z = 0 without sharing a node: each is meshed on its own (cells of
1.6 mm on the lower block's top, 1.3 mm on the upper block's bottom), so the meshes do not match across the
contact. Surface groups: ``lower_bottom``, ``lower_top``, ``lower_sides``, ``upper_bottom``, ``upper_top``,
``upper_sides``.

    python cases/make_two_blocks_3d_mesh.py [out.msh] [scale]      # scale < 1 refines (cell sizes × scale)
"""

import gmsh
from gmsh_blocks import size_by_contact_plane, write_mesh

LOWER = (0.0, 0.0, -10.0, 20.0, 20.0, 10.0)  # x0, y0, z0, dx, dy, dz (mm)
INCLUSION = (6.0, 6.0, -7.0, 8.0, 8.0, 4.0)
UPPER = (4.0, 4.0, 0.0, 12.0, 12.0, 8.0)
SIZES = {"lower": (1.6, 4.0), "upper": (1.3, 3.0)}  # (at the contact face z = 0, far from it) in mm


def _faces(volumes: list[int], z0: float, z1: float) -> dict[str, list[int]]:
    """The outer faces of a block of ``volumes`` by side: bottom (z = z0), top (z = z1), the four sides."""
    faces = {"bottom": [], "top": [], "sides": []}
    for _, face in gmsh.model.getBoundary([(3, v) for v in volumes], oriented=False):
        z_lo, z_hi = gmsh.model.getBoundingBox(2, abs(face))[2::3]
        if z_hi - z_lo < 1e-6 and abs(z_lo - z0) < 1e-6:
            faces["bottom"].append(abs(face))
        elif z_hi - z_lo < 1e-6 and abs(z_lo - z1) < 1e-6:
            faces["top"].append(abs(face))
        else:
            faces["sides"].append(abs(face))
    return faces


def model(scale: float = 1.0) -> None:
    """The two blocks and the inclusion with their groups, cell sizes × ``scale``, in the current gmsh session."""
    gmsh.model.add("two_blocks_3d")
    occ = gmsh.model.occ
    lower = occ.addBox(*LOWER)
    inclusion = occ.addBox(*INCLUSION)
    pieces, _ = occ.fragment([(3, lower)], [(3, inclusion)])
    upper = occ.addBox(*UPPER)
    occ.synchronize()
    lower_volumes = [t for _, t in pieces]
    inside = [t for t in lower_volumes if abs(occ.getMass(3, t) - INCLUSION[3] * INCLUSION[4] * INCLUSION[5]) < 1e-6]
    gmsh.model.addPhysicalGroup(3, inside, name="lower_inclusion")
    gmsh.model.addPhysicalGroup(3, [t for t in lower_volumes if t not in inside], name="lower_matrix")
    gmsh.model.addPhysicalGroup(3, [upper], name="upper")
    blocks = {"lower": (lower_volumes, LOWER), "upper": ([upper], UPPER)}
    for name, (volumes, (_, _, z0, _, _, dz)) in blocks.items():
        for side, tags in _faces(volumes, z0, z0 + dz).items():
            gmsh.model.addPhysicalGroup(2, tags, name=f"{name}_{side}")
        size_by_contact_plane([(3, v) for v in volumes], 2, SIZES[name], scale)


if __name__ == "__main__":
    write_mesh(model, 3, "cases/two_blocks_3d.msh")
