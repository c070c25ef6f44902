"""Write the composite of ``cases/composite.toml``: a unit square of matrix with stiff circular fibres.

    .venv/bin/python cases/make_composite_mesh.py --h 0.05 --out cases/composite.msh

A user-style gmsh model (unstructured, OpenCASCADE), as a user would draw one: the square is
cut by the coarse grid of squares of side 1/4 (so the multiscale methods can use ``mesh.H = 4``)
and by six discs, one of them crossing the interface γ (x = 3/4).  Physical groups:

* surfaces ``Omega1`` (x < 3/4), ``Omega2`` (the strip x > 3/4) — the hybrid split — and,
  overlaying them, the material groups ``matrix`` and ``fibres`` (every triangle in one of each);
* curves ``Gamma_D`` (x = 0, clamped), ``Gamma_C`` (x = 1, contact), ``gamma`` (x = 3/4),
  ``Gamma_N_top`` (y = 1, a traction); the bottom y = 0 is untagged: traction free.
"""

import argparse
from pathlib import Path

import gmsh

from fenics_contact.problem.geometry import gmsh_session

#: the fibres: (x, y, radius); the third crosses gamma (x = 3/4), none touches the outer boundary
FIBRES = [(0.2, 0.27, 0.08), (0.46, 0.68, 0.1), (0.7, 0.36, 0.1), (0.86, 0.78, 0.07), (0.3, 0.84, 0.07),
          (0.55, 0.12, 0.06)]
STRIP = 0.75  #: gamma: x = 1 - H with H = 1/4


def build(h: float) -> None:
    """The tagged model in the current gmsh session, meshed with size h."""
    occ = gmsh.model.occ
    gmsh.model.add("composite")
    squares = [(2, occ.addRectangle(0.25 * i, 0.25 * j, 0.0, 0.25, 0.25)) for j in range(4) for i in range(4)]
    discs = [(2, occ.addDisk(x, y, 0.0, r, r)) for x, y, r in FIBRES]
    _, children = occ.fragment(squares, discs)
    occ.synchronize()
    fibres = {tag for dim_tags in children[len(squares):] for _, tag in dim_tags}
    surfaces = [tag for _, tag in gmsh.model.getEntities(2)]
    omega2 = {s for s in surfaces if gmsh.model.getBoundingBox(2, s)[0] > STRIP - 1e-6}
    groups2 = {"Omega1": set(surfaces) - omega2, "Omega2": omega2, "fibres": fibres,
               "matrix": set(surfaces) - fibres}
    for name, tags in groups2.items():
        gmsh.model.addPhysicalGroup(2, sorted(tags), name=name)
    eps = 1e-6  # OCC bounding boxes are padded by its tolerance (1e-7)
    groups1 = {"Gamma_D": [], "Gamma_C": [], "gamma": [], "Gamma_N_top": []}
    for _, curve in gmsh.model.getEntities(1):
        x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, curve)
        if x1 < eps:
            groups1["Gamma_D"].append(curve)
        elif x0 > 1 - eps:
            groups1["Gamma_C"].append(curve)
        elif y0 > 1 - eps:
            groups1["Gamma_N_top"].append(curve)
        elif abs(x0 - STRIP) < eps and abs(x1 - STRIP) < eps:
            groups1["gamma"].append(curve)
    for name, curves in groups1.items():
        gmsh.model.addPhysicalGroup(1, curves, name=name)
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)
    gmsh.option.setNumber("Mesh.MeshSizeMin", h / 2)
    gmsh.model.mesh.generate(2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--h", type=float, default=0.05, help="mesh size (default 0.05)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "composite.msh")
    args = parser.parse_args()
    with gmsh_session():
        build(args.h)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(args.out))
    print("written", args.out)


if __name__ == "__main__":
    main()
