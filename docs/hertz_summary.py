"""Tabulate plane-strain Hertz runs of ``fenics-contact run --case cases/hertz.toml`` against the closed form.

    python docs/hertz_summary.py --nu 0.45 results/hertz-*/      # one row per run directory

Each run's ``summary.json`` gives the contact force F (per unit thickness), the contact zone and the peak
pressure; Hertz gives, for a cylinder of radius R on an elastic half-space with E* = E/(1 − ν²),
a = 2·sqrt(R F/(π E*)) and p₀ = 2F/(π a). The half-width a_h is half the span of the contact nodes, so
(a_h − a)/h (h the contact cell size) lies within about one cell; p_max/p₀ − 1 is the peak error.
"""

import argparse
import json
import math
from pathlib import Path


def row(directory: Path, E: float, nu: float, R: float) -> str:
    s = json.loads((directory / "summary.json").read_text())
    force = s["contact_force"]
    a = 2.0 * math.sqrt(R * force / (math.pi * E / (1.0 - nu**2)))
    p0 = 2.0 * force / (math.pi * a)
    (x0, _), (x1, _) = s["contact_zone"]
    a_h = 0.5 * (x1 - x0)
    refinement = s["case"]["mesh"]["refinement"]
    return (
        f"| {s['method']} | {refinement:g} | a/{a / s['h']:.0f} | {force:.5e} | {a:.4f} | {(a_h - a) / s['h']:+.2f} "
        f"| {100 * (s['max_contact_pressure'] / p0 - 1):+.2f}% | {s['iterations']} | "
        f"{s['transmission_residual']:.1e} | {s['converged']} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--E", type=float, default=1.0)
    parser.add_argument("--nu", type=float, default=0.3)
    parser.add_argument("--R", type=float, default=5.0)
    args = parser.parse_args()
    print(
        "| method | r | contact cells | F | a (Hertz, from F) | (a_h − a)/h | p_max/p₀ − 1 | iterations "
        "| transmission residual | converged |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for directory in args.runs:
        print(row(directory, args.E, args.nu, args.R))


if __name__ == "__main__":
    main()
