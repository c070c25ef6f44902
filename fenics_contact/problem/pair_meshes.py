"""Meshes of two disjoint bodies with named tags, built with gmsh: two stacked blocks, a cylinder on a block.

The bodies are meshed independently (their common boundary is not fused), so the meshes do not match across
the contact surfaces; the cells of each body carry its tag (``PairTag.LOWER``, ``PairTag.UPPER``) and the
facets of each side a tag of its own (``PairTag.LOWER_TOP`` …).
"""

from enum import IntEnum
from typing import NamedTuple

import dolfinx.graph
import dolfinx.io.gmsh
import dolfinx.io.utils
import gmsh
import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.geometry import gmsh_session

__all__ = ["PairTag", "TwoBodyMesh", "two_blocks", "cylinder_on_block", "join_bodies", "fault_strata"]


class PairTag(IntEnum):
    """Cell tags of the two bodies and facet tags of their sides (x: left/right, y in 2D or z in 3D:
    bottom/top; ``*_SIDES`` the faces normal to the remaining axis in 3D)."""

    LOWER = 1
    UPPER = 2
    LOWER_BOTTOM = 21
    LOWER_LEFT = 22
    LOWER_RIGHT = 23
    LOWER_TOP = 24
    LOWER_SIDES = 25
    UPPER_BOTTOM = 31
    UPPER_LEFT = 32
    UPPER_RIGHT = 33
    UPPER_TOP = 34
    UPPER_SIDES = 35


class TwoBodyMesh(NamedTuple):
    """A mesh of two disjoint bodies with its cell and facet tags (``PairTag``)."""

    mesh: dmesh.Mesh
    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags


def _to_mesh(comm: MPI.Comm, gdim: int) -> TwoBodyMesh:
    data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=gdim)
    return TwoBodyMesh(data.mesh, data.cell_tags, data.facet_tags)


def _classify(body: tuple[int, int], lower: bool, box: tuple[np.ndarray, np.ndarray], gdim: int) -> dict:
    """The boundary entities of ``body`` by side: tag -> entity tags."""
    lo, hi = box
    up = gdim - 1  # the vertical axis
    names = ("BOTTOM", "LEFT", "RIGHT", "TOP", "SIDES")
    prefix = "LOWER_" if lower else "UPPER_"
    out = {PairTag[prefix + n]: [] for n in names}
    tol = 1e-6 * float(np.max(hi - lo))  # (gmsh pads bounding boxes by ~1e-7)
    for dim, tag in gmsh.model.getBoundary([body], oriented=False):
        b = np.asarray(gmsh.model.getBoundingBox(dim, tag)).reshape(2, 3)[:, :gdim]
        if abs(b[1, up] - b[0, up]) < tol:
            side = "BOTTOM" if abs(b[0, up] - lo[up]) < tol else "TOP"
        elif abs(b[1, 0] - b[0, 0]) < tol:
            side = "LEFT" if abs(b[0, 0] - lo[0]) < tol else "RIGHT"
        else:
            side = "SIDES"
        out[PairTag[prefix + side]].append(tag)
    return out


def two_blocks(
    n_lower: int,
    n_upper: int,
    *,
    width: float = 1.0,
    heights: tuple[float, float] = (0.5, 0.5),
    gap: float = 0.0,
    offset: float = 0.0,
    dim: int = 2,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TwoBodyMesh:
    """Two blocks of the same width, one on the other: the lower (0, W) × (−h₁, 0), the upper shifted by
    ``offset`` along x and lifted by ``gap``, (offset, offset + W) × (gap, gap + h₂) (× (0, W) in 3D).

    Unstructured simplices of size W/n_lower and W/n_upper; the edges along x of the contact faces carry
    exactly n_lower and n_upper cells (2D).
    """
    for n in (n_lower, n_upper):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise InputError(f"two_blocks needs cell counts >= 1, got {n_lower!r}, {n_upper!r}")
    if dim not in (2, 3) or not (width > 0 and min(heights) > 0 and gap >= 0 and np.isfinite(offset)):
        raise InputError(
            f"two_blocks needs dim 2 or 3, width, heights > 0 and gap >= 0; got {dim}, {width}, {heights}, {gap}"
        )
    with gmsh_session():
        if comm.rank == 0:
            gmsh.model.add("two_blocks")
            occ = gmsh.model.occ
            boxes = []
            for lower, n, y0, h, x0 in (
                (True, n_lower, -heights[0], heights[0], 0.0),
                (False, n_upper, gap, heights[1], offset),
            ):
                if dim == 2:
                    tag = occ.addRectangle(x0, y0, 0.0, width, h)
                    lo, hi = np.array([x0, y0]), np.array([x0 + width, y0 + h])
                else:
                    tag = occ.addBox(x0, 0.0, y0, width, width, h)
                    lo, hi = np.array([x0, 0.0, y0]), np.array([x0 + width, width, y0 + h])
                boxes.append((lower, n, tag, (lo, hi)))
            occ.synchronize()
            for lower, n, tag, box in boxes:
                body = (dim, tag)
                gmsh.model.addPhysicalGroup(dim, [tag], int(PairTag.LOWER if lower else PairTag.UPPER))
                for side, entities in _classify(body, lower, box, dim).items():
                    if entities:
                        gmsh.model.addPhysicalGroup(dim - 1, entities, int(side))
                points = gmsh.model.getBoundary([body], recursive=True)
                gmsh.model.mesh.setSize(points, width / n)
                if dim == 2:
                    for _, curve in gmsh.model.getBoundary([body], oriented=False):
                        b = np.asarray(gmsh.model.getBoundingBox(1, curve)).reshape(2, 3)
                        if abs(b[1, 1] - b[0, 1]) < 1e-6 * width:
                            gmsh.model.mesh.setTransfiniteCurve(curve, n + 1)
            gmsh.model.mesh.generate(dim)
        out = _to_mesh(comm, dim)
    return out


def cylinder_on_block(
    radius: float,
    a: float,
    *,
    h_contact: float | None = None,
    refinement: float = 1.0,
    width: float = 80.0,
    depth: float = 40.0,
    refine_width: float = 1.5,
    refine_depth: float = 1.0,
    grading: float = 0.25,
    h_far: float = 8.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TwoBodyMesh:
    """A half-cylinder of radius R (the lower half of the disc of centre (0, R): cells ``UPPER``, its arc
    ``UPPER_BOTTOM``, its flat top y = R ``UPPER_TOP``) touching at the origin the block (−L, L) × (−D, 0)
    (cells ``LOWER``, top ``LOWER_TOP``, bottom ``LOWER_BOTTOM``).  Lengths are multiples of the expected
    contact half-width ``a`` (2L = ``width``·a, D = ``depth``·a); both bodies have the size h_contact =
    a/(20 r) (r = ``refinement``) on |x| ≤ ``refine_width``·a, |y| ≤ ``refine_depth``·a, growing by
    ``grading``/r per unit distance up to ``h_far``·a/r."""
    if not (np.isfinite(a) and a > 0 and np.isfinite(radius) and radius > 10 * a and refinement > 0):
        raise InputError(f"cylinder_on_block needs a > 0, R > 10a and refinement > 0; got {a}, {radius}, {refinement}")
    hc = a / (20.0 * refinement) if h_contact is None else float(h_contact)
    L, D = 0.5 * width * a, depth * a
    far = min(h_far * a / refinement, 0.25 * radius)
    with gmsh_session():
        if comm.rank == 0:
            gmsh.model.add("cylinder_on_block")
            geo = gmsh.model.geo
            p = [geo.addPoint(x, y, 0.0) for x, y in ((-L, -D), (L, -D), (L, 0.0), (-L, 0.0), (0.0, 0.0))]
            block = [
                geo.addLine(p[0], p[1]),
                geo.addLine(p[1], p[2]),
                geo.addLine(p[2], p[4]),
                geo.addLine(p[4], p[3]),
                geo.addLine(p[3], p[0]),
            ]
            s_block = geo.addPlaneSurface([geo.addCurveLoop(block)])
            q = [geo.addPoint(x, y, 0.0) for x, y in ((-radius, radius), (0.0, 0.0), (radius, radius), (0.0, radius))]
            arc_l, arc_r = geo.addCircleArc(q[0], q[3], q[1]), geo.addCircleArc(q[1], q[3], q[2])
            top = geo.addLine(q[2], q[0])
            s_cyl = geo.addPlaneSurface([geo.addCurveLoop([arc_l, arc_r, top])])
            geo.synchronize()
            groups = {
                PairTag.LOWER: (2, [s_block]),
                PairTag.UPPER: (2, [s_cyl]),
                PairTag.LOWER_BOTTOM: (1, [block[0]]),
                PairTag.LOWER_TOP: (1, [block[2], block[3]]),
                PairTag.UPPER_BOTTOM: (1, [arc_l, arc_r]),
                PairTag.UPPER_TOP: (1, [top]),
            }
            for tag, (d, entities) in groups.items():
                gmsh.model.addPhysicalGroup(d, entities, int(tag))
            field = gmsh.model.mesh.field
            zone = field.add("Box")
            field.setNumber(zone, "VIn", hc)
            field.setNumber(zone, "VOut", far)
            for key, value in (
                ("XMin", -refine_width * a),
                ("XMax", refine_width * a),
                ("YMin", -refine_depth * a),
                ("YMax", refine_depth * a),
            ):
                field.setNumber(zone, key, value)
            field.setNumber(zone, "Thickness", (far - hc) / (grading / refinement))
            field.setAsBackgroundMesh(zone)
            for name in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
                gmsh.option.setNumber(name, 0)
            gmsh.model.mesh.generate(2)
        out = _to_mesh(comm, 2)
    return out


def join_bodies(
    first: tuple[dmesh.Mesh, dmesh.MeshTags],
    second: tuple[dmesh.Mesh, dmesh.MeshTags],
    *,
    comm: MPI.Comm | None = None,
) -> TwoBodyMesh:
    """One mesh of two bodies given as two meshes with their facet tags (each on one process, e.g. built or
    read on ``MPI.COMM_SELF``): the cells of ``first`` tagged ``PairTag.LOWER`` (1), those of ``second``
    ``PairTag.UPPER`` (2), every facet keeping its tag (the two meshes' facet tags must differ).  Straight
    simplices of the same kind; the result lives on ``comm`` (default: the first mesh's)."""
    meshes = (first[0], second[0])
    if any(m.comm.size > 1 for m in meshes):
        raise InputError("join_bodies takes meshes held by one process each (build or read them on MPI.COMM_SELF)")
    if meshes[0].topology.cell_type != meshes[1].topology.cell_type or meshes[0].geometry.dim != meshes[1].geometry.dim:
        raise InputError("join_bodies: the two meshes must have the same cell type and dimension")
    if any(m.geometry.cmaps[0].degree != 1 for m in meshes):
        raise InputError("join_bodies: the meshes must have straight (degree-1) cells")
    shared = set(np.unique(first[1].values)) & set(np.unique(second[1].values))
    if shared:
        raise InputError(f"join_bodies: the facet tags {sorted(map(int, shared))} appear in both meshes; renumber them")
    comm = comm or meshes[0].comm
    gdim, tdim = meshes[0].geometry.dim, meshes[0].topology.dim
    xs, cells, entities, values, offset = [], [], [], [], 0
    for msh, tags in (first, second):
        msh.topology.create_connectivity(tdim - 1, tdim)
        xs.append(msh.geometry.x[:, :gdim])
        cells.append(msh.geometry.dofmaps[0].astype(np.int64) + offset)
        entities.append(dmesh.entities_to_geometry(msh, tdim - 1, tags.indices).astype(np.int64) + offset)
        values.append(tags.values.astype(np.int32))
        offset += msh.geometry.x.shape[0]
    rank0 = comm.rank == 0
    x = np.vstack(xs) if rank0 else np.zeros((0, gdim))
    all_cells = np.vstack(cells) if rank0 else np.zeros((0, tdim + 1), dtype=np.int64)
    joined = dmesh.create_mesh(comm, all_cells, meshes[0].ufl_domain(), x)
    num_first = cells[0].shape[0]
    imap = joined.topology.index_map(tdim)
    original = np.asarray(joined.topology.original_cell_index)[: imap.size_local + imap.num_ghosts]
    cell_values = np.where(original < num_first, int(PairTag.LOWER), int(PairTag.UPPER)).astype(np.int32)
    cell_tags = dmesh.meshtags(joined, tdim, np.arange(original.size, dtype=np.int32), cell_values)
    joined.topology.create_connectivity(tdim - 1, tdim)
    local, local_values = dolfinx.io.utils.distribute_entity_data(
        joined,
        tdim - 1,
        np.vstack(entities) if rank0 else np.zeros((0, tdim), dtype=np.int64),
        np.concatenate(values) if rank0 else np.zeros(0, dtype=np.int32),
    )
    facet_tags = dmesh.meshtags_from_entities(
        joined, tdim - 1, dolfinx.graph.adjacencylist(local.astype(np.int32)), local_values.astype(np.int32)
    )
    return TwoBodyMesh(joined, cell_tags, facet_tags)


def fault_strata(contrast: float):
    """Young's moduli of a fault-like pair on ``two_blocks(…, heights=(0.5, 0.4))`` (the fault at y = 0): the lower
    block in strata about 0.13 thick alternating E = ``contrast`` and 1 with a stiff disc in a soft stratum, the
    upper block in strata the other way round with a soft disc; returns the callables (lower, upper) of x."""

    def lower(x: np.ndarray) -> np.ndarray:
        E = np.where(np.sin(12.0 * x[1]) > 0.0, contrast, 1.0)
        return np.where((x[0] - 0.3) ** 2 + (x[1] + 0.25) ** 2 < 0.08**2, contrast, E)

    def upper(x: np.ndarray) -> np.ndarray:
        E = np.where(np.sin(10.0 * x[1] + 1.0) > 0.0, 1.0, contrast)
        return np.where((x[0] - 0.6) ** 2 + (x[1] - 0.2) ** 2 < 0.07**2, 1.0, E)

    return lower, upper
