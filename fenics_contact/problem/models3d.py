"""The built-in 3D test model: the unit cube with stiff channels through γ to Γ_C (the 3D analogue of model 3).

* **Body and boundary** (``channels_3d_mesh``: ``meshes3d.unit_cube``): Ω = (0, 1)³, Γ_C the face x = 1
  (a flush rigid wall), Γ_D the faces x = 0 and y = 0 (clamped), symmetry planes (rollers, u_z = 0) on
  z = 0 and z = 1, the face y = 1 traction free. Ω₂ is the layer x > 1 − ``strip`` (default ¼), γ the
  plane between.
* **Materials** (``channels_3d``): three high-modulus channels of square section ¼ × ¼ run along x from
  x = ¼ through γ and Ω₂ up to Γ_C (stiff material presses on the wall), at (y, z) ∈ [¼, ½] × [0, ¼],
  [½, ¾] × [½, ¾] and [0, ¼] × [¾, 1]: E = ``E_high`` there (contrast up to 1e6), ``E_low`` elsewhere,
  ν = 0.35. Every feature lies on the grid of ¼, so h = 1/8, 1/12, 1/16, 1/24 resolve it exactly.
* **Load** (in Ω₁): f = (f₁, 0, 0) on the slab ½ < x < ¾, f₁ = 1 for y < ½ (pushes onto the wall) and
  f₁ = −1 for y > ¾ (pulls away); nothing acts in Ω₂ for a strip of width up to ¼.
"""

import numpy as np
from mpi4py import MPI

from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.meshes3d import unit_cube
from fenics_contact.problem.problem import ContactProblem, ScalarField, VectorField, constant_field

__all__ = ["CHANNELS_3D", "CLAMPED_3D", "MODEL_3D", "ROLLERS_3D", "channels_3d", "channels_3d_mesh", "slab_load"]

#: the number of the 3D channel model among the built-in models (``models.get_model``, ``--model``)
MODEL_3D = 4

#: the sections (y0, y1, z0, z1) of the stiff channels, each running along x from ``_X_CHANNEL`` to Γ_C (x = 1)
CHANNELS_3D = ((0.25, 0.5, 0.0, 0.25), (0.5, 0.75, 0.5, 0.75), (0.0, 0.25, 0.75, 1.0))
#: the clamped faces (Γ_D) of the model's cube
CLAMPED_3D = ("xmin", "ymin")
#: the symmetry planes (axis, value) of the model: u_z = 0 on z = 0 and z = 1
ROLLERS_3D = ((2, 0.0), (2, 1.0))
_X_CHANNEL = 0.25
_LOAD_SLAB = (0.5, 0.75)  #: the load acts on x in this range: inside Ω₁ for a strip up to ¼ wide


def _channels(E_high: float, E_low: float) -> ScalarField:
    def field(x: np.ndarray) -> np.ndarray:
        inside = np.zeros(x.shape[1], dtype=bool)
        for y0, y1, z0, z1 in CHANNELS_3D:
            inside |= (x[0] > _X_CHANNEL) & (x[1] > y0) & (x[1] < y1) & (x[2] > z0) & (x[2] < z1)
        return np.where(inside, E_high, E_low)

    return field


def slab_load(scale: float, slab: tuple[float, float] = _LOAD_SLAB) -> VectorField:
    """The 3D models' body force: ±``scale`` along x on the slab ``slab[0] < x < slab[1]``, +x where y < ½ and −x
    where y > ¾ (a load in Ω₁ that bends the block without a net force on Γ_C)."""

    def load(x: np.ndarray) -> np.ndarray:
        f = np.zeros((3, x.shape[1]))
        inside = (x[0] > slab[0]) & (x[0] < slab[1])
        f[0, inside & (x[1] < 0.5)] = scale
        f[0, inside & (x[1] > 0.75)] = -scale
        return f

    return load


def channels_3d(
    *, E_high: float = 1.0e3, E_low: float = 1.0, nu: float = 0.35, load_scale: float = 1.0
) -> ContactProblem:
    """The 3D channel model (module docstring): stiff channels through γ to Γ_C, the load in Ω₁, rollers on
    z = 0 and z = 1; put it on ``channels_3d_mesh(n)``."""
    return ContactProblem(
        name="model4",
        youngs_modulus=_channels(float(E_high), float(E_low)),
        poisson_ratio=constant_field(nu),
        load=slab_load(float(load_scale)),
        boundary=BoundaryConditions(rollers=ROLLERS_3D),
        description=f"3D channels to the contact face, E={E_high:g}/{E_low:g}, nu={nu:g}",
    )


def channels_3d_mesh(
    n: int, *, strip: float | None = None, H: float | None = None, comm: MPI.Comm = MPI.COMM_WORLD
) -> ContactMesh:
    """The unit cube of the 3D channel model, h = 1/n: Γ_C the face x = 1, Γ_D the faces ``CLAMPED_3D``, Ω₂ the
    layer x > 1 − ``strip`` (default ¼, snapped to the grid); ``H`` the coarse grid of cubes of side H
    (``primal-ms``; None: no coarse grid)."""
    return unit_cube(n, clamped=CLAMPED_3D, strip=strip, H=H, comm=comm)
