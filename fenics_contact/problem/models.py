"""The built-in test models as data (the paper's test set-up): Young's modulus map, ν, load.

The paper's Figure 5.1 is not available, so the two heterogeneity maps are
documented stand-ins on Ω = (0,1)², every feature aligned with the 1/32 grid
(so h = 1/32, 1/64, 1/128 resolve them exactly) and kept in x ≤ 27/32 < 7/8, so
that the contact strip Ω₂ = (1−H, 1)×(0,1) is homogeneous for every H ≤ 1/8:

* **Test model 1 — channels.** Eight horizontal high-modulus channels of width
  1/32, one in every horizontal band of height 1/8, alternately starting at
  x = 1/32 and x = 5/32 and all ending at x = 27/32: long thin inclusions that
  cross many coarse cells (the classical hard case for multiscale methods).
* **Test model 2 — inclusions.** A field of 40 square inclusions (sides 1/32 and
  1/16) on a staggered lattice, positions listed in ``_INCLUSIONS``.

E = ``E_high`` (10³) inside the pattern and ``E_low`` (1) elsewhere; ν = 0.35.
Models 4 and 5 are the 3D ones: ``problem.models3d`` (the unit cube with stiff channels through γ to Γ_C) and
``problem.composite3d`` (a block with stiff fibres, two crossing γ into the strip).

Models 1 and 2 follow the paper's set-up (homogeneous strip, loads next to Γ_C).
A user's problem generally has neither, so a third model is built to be hard:

* **Test model 3 — heterogeneous strip.** Three high-modulus channels of width
  1/32 run from x = 3/32 through γ and the strip Ω₂ up to Γ_C (stiff material
  presses on the obstacle); three inclusions are cut by γ for H = 1/4, 1/8 and
  1/16 (γ at x = 24/32, 28/32, 30/32); the load acts on x ≥ 1/2, so mostly inside
  Ω₁ (f₁ = 1 pushes the lower half y < 1/2 onto the obstacle, f₁ = −1 pulls the
  band y > 3/4 away). Every feature lies on the 1/32 grid.

Loads f = (f₁, 0), f₁ piecewise constant in bands of the column x ≥ 15/16 next
to Γ_C (inside the strip Ω₂ for every H ≥ 1/16, so that Ω₁ is driven only
through γ, as in the paper's multiscale tests): model 1 pushes the lower half
towards the obstacle (f₁ = 8) and pulls the upper half away (f₁ = −8), giving
contact on about y ∈ [0, 0.5]; model 2 pushes the band 3/8 ≤ y ≤ 5/8 (f₁ = 16)
and pulls the rest (f₁ = −8), giving contact on about y ∈ [0.4, 0.6]. The
total force per unit height is that of a unit load on x ≥ 1/2.
"""

import warnings

import numpy as np
import numpy.typing as npt

from fenics_contact.errors import InputError
from fenics_contact.problem.composite3d import fibre_block_3d
from fenics_contact.problem.models3d import channels_3d
from fenics_contact.problem.problem import ContactProblem, ScalarField, VectorField, constant_field

__all__ = [
    "MODELS_3D",
    "constant_field",
    "get_model",
    "model_1",
    "model_2",
    "model_3",
    "paper_phase_model",
    "pixel_field",
]


#: the built-in models of the unit cube (tetrahedra); 1, 2 and 3 are of the unit square
MODELS_3D = (4, 5)


def __getattr__(name: str):
    if name == "TestModel":
        warnings.warn(
            "fenics_contact.problem.models.TestModel is deprecated: it is ContactProblem "
            "(fenics_contact.problem.problem), whose fields it had",
            DeprecationWarning,
            stacklevel=2,
        )
        return ContactProblem
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def pixel_field(values: npt.ArrayLike, extent=(0.0, 1.0, 0.0, 1.0)) -> ScalarField:
    """A piecewise-constant field from a pixel array ``values[row, col]``.

    Row 0 is the bottom row (y = extent[2]); column 0 is the left (x = extent[0]).
    Points outside the extent take the nearest pixel.
    """
    try:
        values = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"a pixel field needs a 2D array of numbers: {err}") from None
    if values.ndim != 2 or values.size == 0:
        raise InputError(f"a pixel field needs a non-empty 2D array, got shape {values.shape}")
    x0, x1, y0, y1 = extent
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"invalid pixel extent {extent}")
    ny, nx = values.shape

    def field(x: np.ndarray) -> np.ndarray:
        i = np.clip(np.floor((x[0] - x0) / (x1 - x0) * nx).astype(int), 0, nx - 1)
        j = np.clip(np.floor((x[1] - y0) / (y1 - y0) * ny).astype(int), 0, ny - 1)
        return values[j, i]

    return field


def _boxes_field(boxes: np.ndarray, inside: float, outside: float) -> ScalarField:
    """inside on the union of axis-aligned boxes [x0,x1]×[y0,y1], outside elsewhere."""

    def field(x: np.ndarray) -> np.ndarray:
        hit = np.zeros(x.shape[1], dtype=bool)
        for x0, x1, y0, y1 in boxes:
            hit |= (x[0] > x0) & (x[0] < x1) & (x[1] > y0) & (x[1] < y1)
        return np.where(hit, inside, outside)

    return field


def band_load(bands: list[tuple[float, float, float, float, float]]) -> VectorField:
    """f = (f₁, 0) with f₁ = value on each box (x0, x1, y0, y1, value), 0 elsewhere."""

    def load(x: np.ndarray) -> np.ndarray:
        f = np.zeros((2, x.shape[1]))
        for x0, x1, y0, y1, value in bands:
            inside = (x[0] > x0) & (x[0] < x1) & (x[1] > y0) & (x[1] < y1)
            f[0, inside] = value
        return f

    return load


#: the load bands of models 1 and 2 moved into Ω₁ (x ∈ [1/2, 15/16]), the same pattern of pushing and pulling
#: (for ``band_load``): the source-correction checks of Algorithms 3 and 4 (tests and benchmarks)
LOADS_IN_OMEGA1 = {
    1: [(0.5, 15 / 16, 0.0, 0.5, 1.0), (0.5, 15 / 16, 0.5, 1.0, -1.0)],
    2: [(0.5, 15 / 16, 0.0, 0.375, -1.0), (0.5, 15 / 16, 0.375, 0.625, 2.0), (0.5, 15 / 16, 0.625, 1.0, -1.0)],
}

_S = 1.0 / 32.0
_X_LOAD = 15.0 / 16.0  #: loads act on x >= 15/16 (inside Ω₂ for H >= 1/16)
_F = 0.5 / (1.0 - _X_LOAD)  #: band magnitude: the force of a unit load on x >= 1/2
_CHANNELS = np.array([[(1 if k % 2 == 0 else 5) * _S, 27 * _S, (4 * k + 2) * _S, (4 * k + 3) * _S] for k in range(8)])


def _inclusion_boxes() -> np.ndarray:
    """40 square inclusions on a staggered lattice of the 1/32 grid, in x ≤ 27/32."""
    boxes = []
    for j in range(8):  # rows: y in [j/8, (j+1)/8)
        for i in range(5):  # columns: x in [0, 27/32]
            big = (i + j) % 3 == 0
            side = 2 if big else 1
            ix = 1 + 5 * i + (j % 2) * 2  # staggered, <= 1 + 20 + 2 = 23 -> x1 <= 25/32
            iy = 4 * j + 1 + (i % 2)
            boxes.append([ix * _S, (ix + side) * _S, iy * _S, (iy + side) * _S])
    return np.array(boxes)


_INCLUSIONS = _inclusion_boxes()


def model_1(*, E_high: float = 1.0e3, E_low: float = 1.0, nu: float = 0.35, load_scale: float = 1.0) -> ContactProblem:
    """Test model 1: thin high-modulus channels; contact on about y ∈ [0, 0.5]."""
    bands = [(_X_LOAD, 1.0, 0.0, 0.5, _F * load_scale), (_X_LOAD, 1.0, 0.5, 1.0, -_F * load_scale)]
    return ContactProblem(
        name="model1",
        youngs_modulus=_boxes_field(_CHANNELS, E_high, E_low),
        poisson_ratio=constant_field(nu),
        load=band_load(bands),
        description=f"channels, E={E_high:g}/{E_low:g}, nu={nu:g}",
    )


def model_2(*, E_high: float = 1.0e3, E_low: float = 1.0, nu: float = 0.35, load_scale: float = 1.0) -> ContactProblem:
    """Test model 2: a field of inclusions; contact on about y ∈ [0.4, 0.6]."""
    bands = [
        (_X_LOAD, 1.0, 0.0, 0.375, -_F * load_scale),
        (_X_LOAD, 1.0, 0.375, 0.625, 2.0 * _F * load_scale),
        (_X_LOAD, 1.0, 0.625, 1.0, -_F * load_scale),
    ]
    return ContactProblem(
        name="model2",
        youngs_modulus=_boxes_field(_INCLUSIONS, E_high, E_low),
        poisson_ratio=constant_field(nu),
        load=band_load(bands),
        description=f"inclusions, E={E_high:g}/{E_low:g}, nu={nu:g}",
    )


#: model 3: channels from x = 3/32 through γ up to Γ_C, and inclusions cut by γ at x = 24/32, 28/32, 30/32
_STRIP_PATTERN = np.array(
    [[3 * _S, 1.0, 5 * _S, 6 * _S], [3 * _S, 1.0, 13 * _S, 14 * _S], [3 * _S, 1.0, 21 * _S, 22 * _S]]
    + [[27 * _S, 31 * _S, 9 * _S, 11 * _S], [23 * _S, 25 * _S, 17 * _S, 19 * _S], [29 * _S, 31 * _S, 26 * _S, 28 * _S]]
)


def model_3(*, E_high: float = 1.0e3, E_low: float = 1.0, nu: float = 0.35, load_scale: float = 1.0) -> ContactProblem:
    """Test model 3: heterogeneous strip (channels through γ up to Γ_C, γ cutting inclusions), loads in Ω₁."""
    bands = [(0.5, 1.0, 0.0, 0.5, load_scale), (0.5, 1.0, 0.75, 1.0, -load_scale)]
    return ContactProblem(
        name="model3",
        youngs_modulus=_boxes_field(_STRIP_PATTERN, E_high, E_low),
        poisson_ratio=constant_field(nu),
        load=band_load(bands),
        description=f"heterogeneous strip, E={E_high:g}/{E_low:g}, nu={nu:g}",
    )


def paper_phase_model(number: int, *, E_ratio: float, nu_pattern: float, nu_rest: float) -> ContactProblem:
    """The paper's §5.4 parameterization of test model ``number`` (its Tables 5.4–5.7).

    E = ``E_ratio`` and ν = ``nu_pattern`` in the pattern (channels / inclusions, the paper's
    "yellow" E₁, ν₁), E = 1 and ν = ``nu_rest`` elsewhere (its "blue" E₂, ν₂; Ω₂ lies there).
    """
    base = get_model(number, E_high=E_ratio, E_low=1.0)
    boxes = _CHANNELS if number == 1 else _INCLUSIONS
    return base.with_(
        poisson_ratio=_boxes_field(boxes, nu_pattern, nu_rest),
        description=f"{base.description.split(',')[0]}, E1/E2={E_ratio:g}, nu1={nu_pattern:g}, nu2={nu_rest:g}",
    )


def get_model(number: int, **kwargs) -> ContactProblem:
    """The built-in test model 1, 2 or 3 (the unit square), 4 (``models3d.channels_3d``: the unit cube) or 5
    (``composite3d.fibre_block_3d``: the fibre block)."""
    builders = {1: model_1, 2: model_2, 3: model_3, 4: channels_3d, 5: fibre_block_3d}
    if number not in builders:
        raise InputError(f"unknown test model {number!r}; the built-in models are 1, 2, 3, and 4 and 5 (3D)")
    return builders[number](**kwargs)
