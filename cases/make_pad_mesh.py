"""Make ``cases/pad.msh``: a rubber pad bonded on a steel base, in millimetres, meshed by gmsh.

The block x ∈ [−20, 20] mm, y ∈ [−12, 0] mm: rubber for y > −4 (group ``rubber``), steel below
(``steel``); the bottom is ``Gamma_D``, the middle of the top face, x ∈ [−6, 6], is ``Gamma_C``; the
rest of the top and the sides carry no group (traction free). The mesh is refined to 0.1 mm in the
box x ∈ [−6, 6], y ∈ [−2, 0] under the indenter and coarsens to 1.5 mm away from it. The file has
no Omega1/Omega2/gamma groups: the package builds the contact strip itself.

    python cases/make_pad_mesh.py [out.msh]
"""

import sys

import gmsh

L, D, T = 20.0, 12.0, 4.0  # half-width, depth, rubber thickness (mm)
C = 6.0  # half-width of Gamma_C and of the refined box (mm)
FINE, COARSE = 0.1, 1.5  # cell sizes (mm)


def build(path: str) -> None:
    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("pad")
    occ = gmsh.model.occ
    rubber = occ.addRectangle(-L, -T, 0.0, 2 * L, T)
    steel = occ.addRectangle(-L, -D, 0.0, 2 * L, D - T)
    occ.fragment([(2, rubber)], [(2, steel)])
    top_points = [occ.addPoint(-C, 0.0, 0.0), occ.addPoint(C, 0.0, 0.0)]
    occ.fragment(occ.getEntities(2), [(0, p) for p in top_points])
    occ.synchronize()
    surfaces = sorted(gmsh.model.getEntities(2), key=lambda e: gmsh.model.occ.getCenterOfMass(*e)[1])
    steel_s, rubber_s = surfaces[0][1], surfaces[1][1]
    contact, bottom = [], []
    for dim, tag in gmsh.model.getEntities(1):
        x, y, _ = gmsh.model.occ.getCenterOfMass(dim, tag)
        if abs(y) < 1e-9 and abs(x) < C:
            contact.append(tag)
        elif abs(y + D) < 1e-9:
            bottom.append(tag)
    gmsh.model.addPhysicalGroup(2, [rubber_s], name="rubber")
    gmsh.model.addPhysicalGroup(2, [steel_s], name="steel")
    gmsh.model.addPhysicalGroup(1, contact, name="Gamma_C")
    gmsh.model.addPhysicalGroup(1, bottom, name="Gamma_D")
    box = gmsh.model.mesh.field.add("Box")
    for key, value in (("VIn", FINE), ("VOut", COARSE), ("XMin", -C), ("XMax", C), ("YMin", -2.0), ("YMax", 0.0),
                       ("Thickness", 4.0)):
        gmsh.model.mesh.field.setNumber(box, key, value)
    gmsh.model.mesh.field.setAsBackgroundMesh(box)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.model.mesh.generate(2)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(path)
    gmsh.finalize()


if __name__ == "__main__":
    build(sys.argv[1] if len(sys.argv) > 1 else "cases/pad.msh")
