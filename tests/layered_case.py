"""The layered patch test as a case file: E from a 16-pixel map (1 | 10³ | 10 across [0, 1], ν = 0), the left side
clamped, a plane moved in by 0.01, 0.02, 0.03 in load steps; Algorithm 3 at m = 2 when run with it."""

from pathlib import Path

import numpy as np

#: E on the 16 columns of [0, 1]: 1 | 10³ | 10
LAYERS = np.array([1.0] * 6 + [1e3] * 7 + [10.0] * 3)
LAYERED = """
[mesh]
builtin = "unit-square"
h = 16
H = 4
clamped = ["left"]
[material]
E = {pixels = "layers.csv"}
nu = 0.0
[obstacle]
shape = "plane"
point = [1.0, 0.0]
normal = [-1.0, 0.0]
indentation = [0.01, 0.02, 0.03]
[run]
tol = 1e-10
[multiscale]
layers = 2
"""


def write_layered_case(directory: Path) -> Path:
    """The case file and its pixel map written into ``directory``; the case file's path."""
    np.savetxt(directory / "layers.csv", LAYERS[None, :], delimiter=",")
    (directory / "layered.toml").write_text(LAYERED)
    return directory / "layered.toml"
