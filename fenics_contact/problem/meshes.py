"""Tagged gmsh meshes beyond the unit square: a curved contact boundary and the Hertz block.

* ``bulged_square(h, H, bulge)``: the unit square whose side x = 1 is replaced by
  a circle arc through (1, 0), (1 + bulge, ½), (1, 1) (Γ_C, curved); Ω₂ is the
  part right of γ = {x = 1 − H}; Γ_D the sides listed in ``clamped``, the other
  straight sides traction free.
* ``hertz_block(a, ...)``: the block (−L, L) × (−D, 0) (default 80a × 40a) for a
  cylinder pressed into its top face (the plane-strain Hertz benchmark): Γ_C the top segment
  |x| ≤ ``contact_width``, the rest of the top and the sides traction free, the
  bottom clamped; Ω₂ the strip y > −``strip``, γ the line y = −``strip``;
  mesh size ``h_contact`` on the contact zone |x| ≤ ``refine_width``,
  y ≥ −``refine_depth``, growing linearly (rate ``grading``) up to ``h_far``.

* ``composite_block(a, ...)``: a block (−L, L) × (−D, 0) (default 52a × 24a) of soft matrix with
  a lattice of stiff square inclusions, for a cylinder pressed into its top face (the
  showcase): the mesh resolves the inclusions and the Cartesian coarse grid of squares of side H
  (default 4a) from the corner (−L, −D), so all four methods run on it; Ω₂ the top row of coarse
  cells (γ: y = −H, which cuts a row of inclusions and a stiff fibre right under the contact); Γ_C the top
  segment |x| ≤ ``contact_width``, the rest of the top traction free; the bottom and both
  sides clamped (Γ_D), ≥ 20a from the contact by default.

All use unstructured triangles; the tags follow ``tags.PHYSICAL_NAMES``.

The Hertz block's default size (80a × 40a) is chosen so that the block hardly limits the
comparison with the half-space solution: the discrete pressure profiles converge to the
finite block's, which differs from Hertz by about 0.2 % in L² (``benchmarks/analytic_benchmarks.py``);
a smaller block leaves a larger difference.
"""

from dataclasses import dataclass

import gmsh
import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.geometry import ContactMesh, check_memory, contact_mesh_from_model, gmsh_session
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain

__all__ = ["bulged_square", "HertzBlock", "hertz_block", "CompositeBlock", "composite_block"]


def _add_groups(groups: dict) -> None:
    for tag, (dim, entities) in groups.items():
        if entities:
            gmsh.model.addPhysicalGroup(dim, entities, int(tag), name=PHYSICAL_NAMES[tag])


def bulged_square(
    h: float, H: float, *, bulge: float = 0.1, clamped=("left",), comm: MPI.Comm = MPI.COMM_WORLD
) -> ContactMesh:
    """The unit square with a curved contact side (circle arc bulging out by ``bulge`` at y = ½)."""
    if not (0 < h <= 0.25 and 0 < H < 1 and 0 < bulge < 0.5):
        raise InputError(f"bulged_square needs 0 < h <= 1/4, 0 < H < 1, 0 < bulge < 1/2; got {h}, {H}, {bulge}")
    sides = ("left", "bottom", "top")
    if any(side not in sides for side in clamped):
        raise InputError(f"clamped sides must be among {sides}, got {clamped}")
    s = (0.25 - bulge**2) / (2.0 * bulge)  # arc centre at (1 − s, ½)
    # vertices ≈ 2/√3 per h² of area (equilateral triangles), the area at most 1 + bulge
    check_memory(1.2 * (1.0 + bulge) / h**2, f"the bulged square with h = {h:g}")
    with gmsh_session():
        if comm.rank == 0:
            geo = gmsh.model.geo
            gmsh.model.add("bulged_square")
            xs = 1.0 - H
            p = [geo.addPoint(x, y, 0.0, h) for x, y in [(0, 0), (xs, 0), (1, 0), (1, 1), (xs, 1), (0, 1)]]
            centre = geo.addPoint(1.0 - s, 0.5, 0.0, h)
            b1, b2 = geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2])
            arc = geo.addCircleArc(p[2], centre, p[3])
            t2, t1 = geo.addLine(p[3], p[4]), geo.addLine(p[4], p[5])
            left = geo.addLine(p[5], p[0])
            gam = geo.addLine(p[1], p[4])
            s1 = geo.addPlaneSurface([geo.addCurveLoop([b1, gam, t1, left])])
            s2 = geo.addPlaneSurface([geo.addCurveLoop([b2, arc, t2, -gam])])
            geo.synchronize()
            side = {"left": [left], "bottom": [b1, b2], "top": [t1, t2]}
            _add_groups(
                {
                    Subdomain.OMEGA1: (2, [s1]),
                    Subdomain.OMEGA2: (2, [s2]),
                    Boundary.GAMMA_D: (1, [c for name in clamped for c in side[name]]),
                    Boundary.GAMMA_C: (1, [arc]),
                    Boundary.INTERFACE: (1, [gam]),
                }
            )
            gmsh.option.setNumber("Mesh.MeshSizeMax", h)
            gmsh.model.mesh.generate(2)
        return contact_mesh_from_model(comm, h=h, H=None)  # unstructured: no coarse grid


@dataclass(frozen=True, slots=True)
class HertzBlock:
    """Geometry and mesh sizes of the Hertz block (lengths in the units of a)."""

    a: float  #: expected contact half-width (sets the sizes below)
    half_width: float  #: L: the block is (−L, L) × (−D, 0)
    depth: float  #: D
    strip: float  #: thickness of Ω₂ below the top face
    contact_width: float  #: Γ_C = top segment |x| <= contact_width
    refine_width: float  #: mesh size h_contact on |x| <= refine_width, y >= −refine_depth
    refine_depth: float
    h_contact: float
    h_far: float
    grading: float  #: growth of the mesh size per unit distance from the refined zone


def hertz_block(
    a: float,
    *,
    h_contact: float | None = None,
    width: float = 80.0,
    depth: float = 40.0,
    strip: float = 2.0,
    contact_width: float = 3.0,
    refine_width: float = 1.5,
    refine_depth: float = 1.0,
    grading: float = 0.25,
    h_far: float = 8.0,
    refinement: float = 1.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> tuple[ContactMesh, HertzBlock]:
    """The tagged Hertz block for a contact half-width ``a``; lengths other than ``a`` are multiples of a.

    ``refinement`` r refines the whole mesh: h_contact = a/(20r) (unless given), far size
    ``h_far``·a/r, grading/r. Returns the mesh and its ``HertzBlock`` description.
    """
    if not (np.isfinite(a) and a > 0):
        raise InputError(f"the contact half-width a must be > 0, got {a!r}")
    if not (np.isfinite(refinement) and refinement > 0):
        raise InputError(f"the refinement factor must be > 0, got {refinement!r}")
    hc = a / (20.0 * refinement) if h_contact is None else float(h_contact)
    spec = HertzBlock(
        a,
        0.5 * width * a,
        depth * a,
        strip * a,
        contact_width * a,
        refine_width * a,
        refine_depth * a,
        hc,
        h_far * a / refinement,
        grading / refinement,
    )
    if not (
        0 < hc <= spec.refine_width
        and grading > 0
        and spec.refine_width <= spec.contact_width < spec.half_width
        and 0 < spec.strip < spec.depth
    ):
        raise InputError(f"inconsistent Hertz block sizes: {spec}")
    # vertices ≈ area / size²: the refined box (size hc, with a factor 2 to spare), the graded zone around it
    # (size hc + grading·r up to h_far: ∫ perimeter dr / size² = perimeter (1/hc − 1/h_far) / grading)
    perimeter = 4.0 * (spec.refine_width + spec.refine_depth)
    check_memory(
        4.0 * spec.refine_width * spec.refine_depth / hc**2
        + perimeter * (1.0 / hc - 1.0 / max(spec.h_far, hc)) / spec.grading,
        f"the Hertz block with a contact cell of {hc:g}",
    )
    L, D, S, W = spec.half_width, spec.depth, spec.strip, spec.contact_width
    with gmsh_session():
        if comm.rank == 0:
            geo = gmsh.model.geo
            gmsh.model.add("hertz_block")
            coords = [(-L, -D), (L, -D), (L, -S), (L, 0), (W, 0), (-W, 0), (-L, 0), (-L, -S)]
            p = [geo.addPoint(x, y, 0.0) for x, y in coords]
            bottom = geo.addLine(p[0], p[1])
            r1, r2 = geo.addLine(p[1], p[2]), geo.addLine(p[2], p[3])
            top_r, contact, top_l = geo.addLine(p[3], p[4]), geo.addLine(p[4], p[5]), geo.addLine(p[5], p[6])
            l2, l1 = geo.addLine(p[6], p[7]), geo.addLine(p[7], p[0])
            gam = geo.addLine(p[7], p[2])
            s1 = geo.addPlaneSurface([geo.addCurveLoop([bottom, r1, -gam, l1])])
            s2 = geo.addPlaneSurface([geo.addCurveLoop([gam, r2, top_r, contact, top_l, l2])])
            geo.synchronize()
            _add_groups(
                {
                    Subdomain.OMEGA1: (2, [s1]),
                    Subdomain.OMEGA2: (2, [s2]),
                    Boundary.GAMMA_D: (1, [bottom]),
                    Boundary.GAMMA_C: (1, [contact]),
                    Boundary.INTERFACE: (1, [gam]),
                }
            )
            # size: h_contact on the refined zone, + grading·distance, capped at h_far
            zone = gmsh.model.mesh.field.add("Box")
            gmsh.model.mesh.field.setNumber(zone, "VIn", hc)
            gmsh.model.mesh.field.setNumber(zone, "VOut", spec.h_far)
            for key, value in (
                ("XMin", -spec.refine_width),
                ("XMax", spec.refine_width),
                ("YMin", -spec.refine_depth),
                ("YMax", 0.0),
            ):
                gmsh.model.mesh.field.setNumber(zone, key, value)
            gmsh.model.mesh.field.setNumber(zone, "Thickness", (spec.h_far - hc) / spec.grading)
            gmsh.model.mesh.field.setAsBackgroundMesh(zone)
            for name in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
                gmsh.option.setNumber(name, 0)
            gmsh.model.mesh.generate(2)
        cm = contact_mesh_from_model(comm, h=hc, H=None)  # graded: no coarse grid
    return cm, spec


@dataclass(frozen=True, slots=True)
class CompositeBlock:
    """Geometry, inclusions and mesh sizes of the composite block (lengths in the units of a)."""

    a: float  #: the length unit: the expected contact half-width
    half_width: float  #: L: the block is (−L, L) × (−D, 0)
    depth: float  #: D
    H: float  #: side of the coarse squares (from the corner (−L, −D)); Ω₂ is the top row, γ: y = −H
    contact_width: float  #: Γ_C = top segment |x| <= contact_width
    inclusions: tuple  #: stiff squares (x0, x1, y0, y1)
    h_contact: float
    h_far: float
    grading: float

    def modulus(self, inclusion: float, matrix: float):
        """E(x): ``inclusion`` inside the squares, ``matrix`` elsewhere (a field x (3, N) -> (N,))."""
        boxes = np.asarray(self.inclusions, dtype=float).reshape(-1, 4)

        def E(x: np.ndarray) -> np.ndarray:
            inside = np.zeros(x.shape[1], dtype=bool)
            for x0, x1, y0, y1 in boxes:
                inside |= (x[0] > x0) & (x[0] < x1) & (x[1] > y0) & (x[1] < y1)
            return np.where(inside, float(inclusion), float(matrix))

        return E


def _lattice(L: float, D: float, H: float, side: float) -> list[tuple[float, float, float, float]]:
    """The stiff squares of the composite block, every one inside a coarse column (none on a grid line):

    * under the contact (the middle column, x = 0) a fibre of width side/2 from y = −3H/8 down through γ
      to y = −13H/8 (its top part in Ω₂);
    * in every other column but the outer ones a square of side ``side`` centred on γ (y = −H), cut in two;
    * one square in the middle of every coarse cell from the third row down (not the bottom row).
    """
    nx, ny = int(round(2 * L / H)), int(round(D / H))
    boxes = [(-side / 4, side / 4, -13 * H / 8, -3 * H / 8)]
    centres = [(-L + (i + 0.5) * H, -H) for i in range(1, nx - 1) if i != nx // 2]
    centres += [(-L + (i + 0.5) * H, -(j + 0.5) * H) for j in range(2, ny - 1) for i in range(1, nx - 1)]
    return boxes + [(x - side / 2, x + side / 2, y - side / 2, y + side / 2) for x, y in centres]


def composite_block(
    a: float,
    *,
    width: float = 52.0,
    depth: float = 24.0,
    coarse: float = 4.0,
    inclusion: float = 2.0,
    contact_width: float = 3.0,
    refine_width: float = 1.5,
    refine_depth: float = 1.0,
    refinement: float = 1.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> tuple[ContactMesh, CompositeBlock]:
    """The tagged composite block for a contact half-width ``a``; the other lengths are multiples of a.

    ``width`` × ``depth``: the block; ``coarse``: the side H of the coarse squares (``width``/H an odd and
    ``depth``/H a whole number, so that x = 0 is the middle of a coarse column); ``inclusion``: the side of
    the stiff squares (``_lattice``: a fibre from 3H/8 below the contact down through γ, a row of squares cut
    by γ, and one in every coarse cell from the third row down, away from the clamped sides). ``refinement`` r:
    h_contact = a/(20r) on |x| <= ``refine_width``, y >= −``refine_depth``, growing by 0.5/r per unit
    distance up to h_far = min(H/2, 2a/r). Returns the mesh (``ContactMesh.H`` = H, the coarse grid
    resolved) and its ``CompositeBlock``.
    """
    if not (np.isfinite(a) and a > 0 and np.isfinite(refinement) and refinement > 0):
        raise InputError(f"composite_block needs a > 0 and refinement > 0, got {a!r}, {refinement!r}")
    nx, ny = width / coarse, depth / coarse
    if not (
        abs(nx - round(nx)) < 1e-9
        and abs(ny - round(ny)) < 1e-9
        and round(ny) >= 2
        and round(nx) >= 3
        and round(nx) % 2 == 1
    ):
        raise InputError(
            f"composite_block: width/coarse must be an odd and depth/coarse a whole number >= 2, got "
            f"{width}/{coarse}, {depth}/{coarse}"
        )
    if not (0 < inclusion < coarse and 0 < refine_width <= contact_width < width / 2 and 0 < refine_depth < coarse):
        raise InputError(
            f"composite_block: inconsistent sizes (inclusion {inclusion}, coarse {coarse}, contact width "
            f"{contact_width}, refine {refine_width} x {refine_depth})"
        )
    nx, ny = int(round(nx)), int(round(ny))
    L, D, H, W = 0.5 * width * a, depth * a, coarse * a, contact_width * a
    hc = a / (20.0 * refinement)
    h_far = min(0.5 * H, 2.0 * a / refinement)
    grading = 0.5 / refinement
    boxes = _lattice(L, D, H, inclusion * a)
    # vertices ≈ area / size²: the refined box (size hc, a factor 2 to spare), the rest at most at the far size
    check_memory(
        4.0 * refine_width * refine_depth * a**2 / hc**2 + 2.0 * L * D / h_far**2,
        f"the composite block with a contact cell of {hc:g}",
    )
    spec = CompositeBlock(a, L, D, H, W, tuple(boxes), hc, h_far, grading)
    tol = 1e-4 * a  # (OCC bounding boxes are padded by ~1e-7)
    with gmsh_session():
        if comm.rank == 0:
            occ = gmsh.model.occ
            gmsh.model.add("composite_block")
            cells = [(2, occ.addRectangle(-L + i * H, -D + j * H, 0.0, H, H)) for j in range(ny) for i in range(nx)]
            squares = [(2, occ.addRectangle(x0, y0, 0.0, x1 - x0, y1 - y0)) for x0, x1, y0, y1 in boxes]
            marks = [(0, occ.addPoint(x, 0.0, 0.0)) for x in (-W, W)]
            occ.fragment(cells + squares, marks)
            occ.synchronize()

            def centre(dim, tag):
                return np.array(gmsh.model.occ.getCenterOfMass(dim, tag)[:2])

            surfaces = [t for _, t in gmsh.model.getEntities(2)]
            omega2 = [t for t in surfaces if centre(2, t)[1] > -H]
            omega1 = [t for t in surfaces if t not in omega2]
            groups = {"bottom": [], "sides": [], "contact": [], "gamma": []}
            for _, c in gmsh.model.getEntities(1):
                x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, c)
                if abs(y0 + D) < tol and abs(y1 + D) < tol:
                    groups["bottom"].append(c)
                elif (abs(x0 + L) < tol and abs(x1 + L) < tol) or (abs(x0 - L) < tol and abs(x1 - L) < tol):
                    groups["sides"].append(c)
                elif abs(y0) < tol and abs(y1) < tol and x0 > -W - tol and x1 < W + tol:
                    groups["contact"].append(c)
                elif abs(y0 + H) < tol and abs(y1 + H) < tol:
                    groups["gamma"].append(c)
            _add_groups(
                {
                    Subdomain.OMEGA1: (2, omega1),
                    Subdomain.OMEGA2: (2, omega2),
                    Boundary.GAMMA_D: (1, groups["bottom"] + groups["sides"]),
                    Boundary.GAMMA_C: (1, groups["contact"]),
                    Boundary.INTERFACE: (1, groups["gamma"]),
                }
            )
            field = gmsh.model.mesh.field
            zone = field.add("Box")
            field.setNumber(zone, "VIn", hc)
            field.setNumber(zone, "VOut", h_far)
            for key, value in (
                ("XMin", -refine_width * a),
                ("XMax", refine_width * a),
                ("YMin", -refine_depth * a),
                ("YMax", 0.0),
            ):
                field.setNumber(zone, key, value)
            field.setNumber(zone, "Thickness", (h_far - hc) / grading)
            field.setAsBackgroundMesh(zone)
            for name in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
                gmsh.option.setNumber(name, 0)
            gmsh.model.mesh.generate(2)
        cm = contact_mesh_from_model(comm, h=hc, H=H)
    return cm, spec
