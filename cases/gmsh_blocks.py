"""What the two-block mesh scripts share (``make_two_blocks_mesh.py``, ``make_two_blocks_3d_mesh.py``): the blocks
meshed apart, finer at the contact plane, written as a gmsh 4.1 file from the command line ``[out.msh] [scale]``.
"""

import sys
from collections.abc import Callable

import gmsh

from fenics_contact.problem.geometry import gmsh_session

__all__ = ["size_by_contact_plane", "write_mesh"]


def size_by_contact_plane(entities: list[tuple[int, int]], axis: int, sizes: tuple[float, float], scale: float) -> None:
    """Mesh size at the points of the boundary of ``entities`` (dim, tag): ``scale``·sizes[0] on the contact plane
    (coordinate ``axis`` = 0), ``scale``·sizes[1] elsewhere."""
    fine, coarse = (scale * s for s in sizes)
    for dim, tag in gmsh.model.getBoundary(entities, combined=False, recursive=True):
        at = gmsh.model.getValue(0, tag, [])[axis]
        gmsh.model.mesh.setSize([(dim, tag)], fine if abs(at) < 1e-9 else coarse)


def write_mesh(model: Callable[[float], None], dim: int, default: str) -> None:
    """Build ``model(scale)`` in a gmsh session, mesh it in dimension ``dim`` and write it to the path of the
    command line's first argument (``default`` without one); the second argument, if any, is the scale."""
    path = sys.argv[1] if len(sys.argv) > 1 else default
    scale = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    with gmsh_session():
        model(scale)
        gmsh.model.mesh.generate(dim)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(path)
