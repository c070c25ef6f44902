"""Write the tagged, structured unit-square mesh of fenics-contact as a gmsh .msh file.

    .venv/bin/python meshes/make_unit_square.py --n 16 --H 4 --out meshes/unit_square_n16_H4.msh

Physical groups: Omega1, Omega2 (the strip of width H at x = 1), Gamma_D (x = 0, y = 0, y = 1),
Gamma_C (x = 1), gamma (x = 1 - H). The result can be passed to ``fenics-contact run --mesh``.
"""

import argparse
from pathlib import Path

import gmsh

from fenics_contact.problem.geometry import build_unit_square_model, gmsh_session


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, required=True, help="1/h")
    parser.add_argument("--H", type=int, required=True, help="1/H")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    with gmsh_session():
        build_unit_square_model(args.n, args.H)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(args.out))
    print("written", args.out)


if __name__ == "__main__":
    main()
