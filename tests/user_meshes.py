"""User mesh files written with gmsh for the mesh-checking tests: three tagged columns, a solid, quadrangles."""

import gmsh

from fenics_contact.problem.geometry import gmsh_session

__all__ = ["GOOD", "build_columns", "solid_or_quads"]

#: the three columns A = (0, 3/8), B = (3/8, 3/4), C = (3/4, 1) of the unit square; Ω₁ = A ∪ B, Ω₂ = C
GOOD = dict(
    omega1=("A", "B"),
    omega2=("C",),
    gamma=("v2",),
    gamma_c=("v3",),
    gamma_d=("v0", "b0", "b1", "b2", "t0", "t1", "t2"),
)


def build_columns(
    path,
    *,
    omega1=GOOD["omega1"],
    omega2=GOOD["omega2"],
    gamma=GOOD["gamma"],
    gamma_c=GOOD["gamma_c"],
    gamma_d=GOOD["gamma_d"],
    interface="shared",
    z=0.0,
    surface_groups=None,
    curve_groups=None,
    n=8,
):
    """A structured triangle mesh of three columns, tagged as asked.

    Curves: verticals v0..v3 at x = 0, 3/8, 3/4, 1; bottom b0..b2 and top t0..t2 segments.
    ``interface``: 'shared' (C built on v2), 'duplicate' (C on its own copy of v2: same nodes
    twice) or 'hanging' (C's copy has half the nodes). ``surface_groups`` / ``curve_groups``:
    extra {name: [entities]} (surface_groups replaces Omega1/Omega2 when given).
    """
    with gmsh_session():
        gmsh.model.add("columns")
        geo = gmsh.model.geo
        xs = [0.0, 0.375, 0.75, 1.0]
        bottom = [geo.addPoint(x, 0.0, z) for x in xs]
        top = [geo.addPoint(x, 1.0, z) for x in xs]
        curve = {f"v{k}": geo.addLine(bottom[k], top[k]) for k in range(4)}
        curve |= {f"b{k}": geo.addLine(bottom[k], bottom[k + 1]) for k in range(3)}
        curve |= {f"t{k}": geo.addLine(top[k], top[k + 1]) for k in range(3)}
        v2c = curve["v2"]
        if interface != "shared":
            pb, pt = geo.addPoint(0.75, 0.0, z), geo.addPoint(0.75, 1.0, z)
            v2c = geo.addLine(pb, pt)
            curve["b2"] = geo.addLine(pb, bottom[3])
            curve["t2"] = geo.addLine(pt, top[3])
        loops = {"A": ("b0", "v1", "t0", "v0"), "B": ("b1", "v2", "t1", "v1"), "C": ("b2", "v3", "t2", "v2")}
        surface = {}
        for name, (b, right, t, left) in loops.items():
            left_curve = v2c if (name == "C") else curve[left]
            right_curve = curve[right]
            surface[name] = geo.addPlaneSurface([geo.addCurveLoop([curve[b], right_curve, -curve[t], -left_curve])])
        geo.synchronize()
        coarse_c = n // 2 if interface == "hanging" else n
        for name, tag in curve.items():
            cells = {"v": n, "b": 3, "t": 3}[name[0]]
            if name == "v3" or (name[0] in "bt" and name.endswith("2")):
                cells = coarse_c if name == "v3" else 2
            gmsh.model.mesh.setTransfiniteCurve(tag, cells + 1)
        if interface != "shared":
            gmsh.model.mesh.setTransfiniteCurve(v2c, coarse_c + 1)
        for s in surface.values():
            gmsh.model.mesh.setTransfiniteSurface(s)
        groups2 = surface_groups if surface_groups is not None else {"Omega1": omega1, "Omega2": omega2}
        for name, members in groups2.items():
            gmsh.model.addPhysicalGroup(2, [surface[m] for m in members], name=name)
        groups1 = {"gamma": gamma, "Gamma_C": gamma_c, "Gamma_D": gamma_d} | (curve_groups or {})
        for name, members in groups1.items():
            if members:
                gmsh.model.addPhysicalGroup(1, [v2c if m == "v2c" else curve[m] for m in members], name=name)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        gmsh.model.remove()
    return path


def solid_or_quads(path, kind):
    """A box of second-order tetrahedra (``kind`` "tetrahedra") or a quadrangle square, tagged Omega1: meshes of
    the wrong kind."""
    with gmsh_session():
        gmsh.model.add(kind)
        if kind == "tetrahedra":
            gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(3, [1], name="Omega1")
            gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
            gmsh.option.setNumber("Mesh.ElementOrder", 2)
            gmsh.model.mesh.generate(3)
        else:
            gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(2, [1], name="Omega1")
            gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        gmsh.model.remove()
        gmsh.option.setNumber("Mesh.RecombineAll", 0)
        gmsh.option.setNumber("Mesh.ElementOrder", 1)
    return path
