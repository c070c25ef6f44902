"""Make ``cases/two_blocks.msh``: two layered blocks of rock across a fault, in millimetres, meshed by gmsh.

The lower block x ∈ [0, 40] mm, y ∈ [−20, 0] mm: sandstone for y < −8 (group ``lower_sandstone``), shale above
(``lower_shale``); the upper block x ∈ [5, 35] mm, y ∈ [0, 16] mm: shale for y < 5 (``upper_shale``),
sandstone above (``upper_sandstone``). The two blocks touch along y = 0 without sharing a node: each is meshed
on its own (cells of 1.0 mm on the lower block's top, 1.4 mm on the upper block's bottom), so the meshes do
not match across the fault. Facet groups: ``lower_bottom``, ``lower_top``, ``lower_left``, ``lower_right``,
``upper_bottom``, ``upper_top``, ``upper_left``, ``upper_right``.

    python cases/make_two_blocks_mesh.py [out.msh] [scale]      # scale < 1 refines (cell sizes × scale)
"""

import gmsh
from gmsh_blocks import size_by_contact_plane, write_mesh

LOWER = (0.0, -20.0, 40.0, 20.0, -8.0)  # x0, y0, width, height, y of the layer boundary (mm)
UPPER = (5.0, 0.0, 30.0, 16.0, 5.0)
SIZES = {"lower": (1.0, 3.0), "upper": (1.4, 3.0)}  # (at the fault, far from it) in mm


def _block(spec: tuple) -> list[tuple[int, int]]:
    """Two rectangles (the layers) fragmented into one conforming block: its two surfaces."""
    occ = gmsh.model.occ
    x0, y0, w, h, yl = spec
    below = occ.addRectangle(x0, y0, 0.0, w, yl - y0)
    above = occ.addRectangle(x0, yl, 0.0, w, y0 + h - yl)
    out, _ = occ.fragment([(2, below)], [(2, above)])
    return out


def model(scale: float = 1.0) -> None:
    """The two blocks of rock with their groups, cell sizes × ``scale``, in the current gmsh session."""
    gmsh.model.add("two_blocks")
    blocks = {
        "lower": (LOWER, ("lower_sandstone", "lower_shale")),
        "upper": (UPPER, ("upper_shale", "upper_sandstone")),
    }
    surfaces = {name: _block(spec) for name, (spec, _) in blocks.items()}
    gmsh.model.occ.synchronize()
    for name, (spec, layers) in blocks.items():
        x0, y0, w, h, yl = spec
        ordered = sorted(surfaces[name], key=lambda e: gmsh.model.occ.getCenterOfMass(*e)[1])
        for (dim, tag), layer in zip(ordered, layers, strict=True):
            gmsh.model.addPhysicalGroup(2, [tag], name=layer)
        sides = {"bottom": [], "top": [], "left": [], "right": []}
        curves = {c for s in ordered for c in (abs(t) for _, t in gmsh.model.getBoundary([s], oriented=False))}
        for curve in sorted(curves):
            x, y, _ = gmsh.model.occ.getCenterOfMass(1, curve)
            if abs(y - y0) < 1e-9:
                sides["bottom"].append(curve)
            elif abs(y - (y0 + h)) < 1e-9:
                sides["top"].append(curve)
            elif abs(x - x0) < 1e-9:
                sides["left"].append(curve)
            elif abs(x - (x0 + w)) < 1e-9:
                sides["right"].append(curve)
        for side, tags in sides.items():
            gmsh.model.addPhysicalGroup(1, tags, name=f"{name}_{side}")
        size_by_contact_plane(ordered, 1, SIZES[name], scale)


if __name__ == "__main__":
    write_mesh(model, 2, "cases/two_blocks.msh")
