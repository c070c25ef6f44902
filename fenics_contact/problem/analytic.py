"""Analytic contact solutions and the problems that have them (the docs' verification page).

* **Bar**: ν = 0, Young's modulus E, clamped at x = 0 only (top and bottom traction
  free), body force (f₁, 0), a wall flush with x = 1.  Pushing (f₁ > 0) gives full
  contact, pulling (f₁ < 0) none.  With the penalty the law at x = 1 is
  u(1) = −δσ(1) (primal, in contact) or u(1) = −σ(1)⁺/ε (mixed), so the penalized
  solutions are known in closed form too:

      σ(x) = σ₁ + f₁(1 − x),   u(x) = (σ₁ + f₁) x/E − f₁x²/(2E),
      σ₁ = −f₁/(2(1 + Eδ)) (primal, push), 0 (primal, pull),
           −f₁/2 (mixed, push),  −f₁/(2(1 + E/ε)) (mixed, pull; tensile).

* **Layered patch**: ν = 0, E piecewise constant in x, clamped at x = 0, no load,
  traction-free top and bottom, a plane obstacle moved into the body by d₀ at
  x = 1: σ_xx = −p uniform, u_x(x) = −p ∫₀ˣ dx/E, p = d₀/(C + δ) (primal),
  p = d₀/C (mixed and exact), C = ∫₀¹ dx/E.  P1 and Arnold–Winther reproduce it
  to round-off.
* **Hertz** (plane strain): a rigid cylinder of radius R on a half-space,
  force F per unit thickness: E* = E/(1 − ν²), a = 2√(RF/(πE*)),
  p(x) = p₀√(1 − x²/a²), p₀ = 2F/(πa).  ``hertz_errors`` compares a computed
  contact profile with it, F read off the profile.
* **Two-body Hertz** (plane strain, frictionless): two cylinders of radii R₁, R₂ (R = ∞: a flat block) and
  moduli (E₁, ν₁), (E₂, ν₂) are the one-body case with 1/R* = 1/R₁ + 1/R₂ and
  1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂ (``hertz_pair``): ``hertz_errors(profile, radius=R*, E=E*, nu=0)``.
* **Cattaneo–Mindlin** (plane strain, Coulomb μ, no normal–tangential coupling: an incompressible body on a
  rigid base): the Hertz contact of the normal force P then a tangential force Q < μP sticks on |x| < c,
  c = a√(1 − Q/(μP)), with the shear q(x) = μp₀[√(1 − x²/a²) − (c/a)√(1 − x²/c²)]; moved back from Q* to Q
  (Mindlin–Deresiewicz) it slips back on c′ < |x| < a, c′ = a√(1 − (Q* − Q)/(2μP)), with
  q = μp₀[−√(1 − x²/a²) + 2(c′/a)√(1 − x²/c′²) − (c/a)√(1 − x²/c²)], c of Q* (``cattaneo_mindlin``).
* **Hertz** (3D): a rigid sphere of radius R on a half-space, total force F: a = (3FR/(4E*))^(1/3),
  p(r) = p₀√(1 − r²/a²), p₀ = 3F/(2πa²), at the depth d = a²/R.  ``hertz_sphere_model`` is the
  quarter block of ``meshes3d.hertz_quarter_block`` under it (symmetry planes on rollers), ``hertz_sphere_errors``
  compares a computed contact profile with it, F read off the profile: the area-equivalent contact radius
  √(A/π) (A the contact area of the whole block), the centre pressure and the L² error of the profile.

The P1 locking measurement (u = curl ψ on the clamped square) is ``fem.locking``.
"""

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.meshes3d import hertz_quarter_block
from fenics_contact.problem.obstacles import Circle, Plane, Sphere
from fenics_contact.problem.problem import ContactProblem

__all__ = [
    "CattaneoMindlin",
    "cattaneo_mindlin",
    "BarSolution",
    "bar_model",
    "bar_solution",
    "layered_model",
    "layered_pressure",
    "layered_displacement",
    "hertz_model",
    "hertz_force_for",
    "HertzErrors",
    "hertz_errors",
    "hertz_pair",
    "hertz_sphere_model",
    "hertz_sphere_penalty",
    "HertzSphereErrors",
    "hertz_sphere_errors",
]


class BarSolution(NamedTuple):
    """σ_xx(x) and u_x(x) of the bar (σ_xy = σ_yy = u_y = 0), and the stress at x = 1."""

    sigma_xx: Callable[[np.ndarray], np.ndarray]
    u_x: Callable[[np.ndarray], np.ndarray]
    sigma_end: float


def _uniform_load(f1: float):
    return lambda x: np.vstack([np.full(x.shape[1], float(f1)), np.zeros(x.shape[1])])


def bar_model(f1: float, *, E: float = 1.0) -> ContactProblem:
    """The bar: ν = 0, E, body force (f₁, 0); use it on ``unit_square(n, N, clamped=("left",))``."""
    return ContactProblem(
        name="bar", youngs_modulus=E, poisson_ratio=0.0, load=_uniform_load(f1), description=f"bar, E={E:g}, f1={f1:g}"
    )


def bar_solution(f1: float, *, E: float = 1.0, delta: float = 0.0, epsilon: float | None = None) -> BarSolution:
    """The bar's solution: exact (default), primal-penalized (``delta``) or mixed-penalized (``epsilon``)."""
    if delta and epsilon is not None:
        raise InputError("give delta (primal) or epsilon (mixed), not both")
    if f1 > 0:  # push: full contact
        sigma_end = -f1 / 2.0 if epsilon is not None else -f1 / (2.0 * (1.0 + E * delta))
    elif epsilon is not None:  # pull, mixed penalty: tensile σ₁ = ε|u(1)|
        sigma_end = -f1 / (2.0 * (1.0 + E / epsilon))
    else:
        sigma_end = 0.0
    return BarSolution(
        lambda x: sigma_end + f1 * (1.0 - x[0]),
        lambda x: ((sigma_end + f1) * x[0] - 0.5 * f1 * x[0] ** 2) / E,
        sigma_end,
    )


def _check_layers(bounds, moduli) -> tuple[np.ndarray, np.ndarray]:
    bounds = np.asarray(bounds, dtype=np.float64)
    moduli = np.asarray(moduli, dtype=np.float64)
    if bounds.size != moduli.size + 1 or bounds[0] != 0.0 or bounds[-1] != 1.0 or np.any(np.diff(bounds) <= 0):
        raise InputError(f"layer bounds must rise from 0 to 1 with one more entry than the moduli; got {bounds}")
    if np.any(moduli <= 0):
        raise InputError(f"layer moduli must be > 0, got {moduli}")
    return bounds, moduli


def layered_model(bounds, moduli, *, depth: float) -> ContactProblem:
    """Layers E = moduli[i] on bounds[i] < x < bounds[i+1], ν = 0, no load, plane obstacle moved in by ``depth``."""
    bounds, moduli = _check_layers(bounds, moduli)

    def E(x: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(bounds, x[0], side="right") - 1, 0, moduli.size - 1)
        return moduli[i]

    wall = Plane((1.0, 0.0), (-1.0, 0.0)).indented(depth, (-1.0, 0.0))
    return ContactProblem(
        name="layers",
        youngs_modulus=E,
        poisson_ratio=0.0,
        obstacle=wall,
        description=f"layered patch, E={moduli.tolist()}, d0={depth:g}",
    )


def layered_pressure(bounds, moduli, depth: float, *, delta: float = 0.0) -> float:
    """p = d₀/(C + δ), C = Σ Lᵢ/Eᵢ (δ = 0: exact and mixed)."""
    bounds, moduli = _check_layers(bounds, moduli)
    return depth / (float(np.sum(np.diff(bounds) / moduli)) + delta)


def layered_displacement(bounds, moduli, pressure: float) -> Callable[[np.ndarray], np.ndarray]:
    """u_x(x) = −p ∫₀ˣ dx/E (piecewise linear)."""
    bounds, moduli = _check_layers(bounds, moduli)
    compliance = np.concatenate([[0.0], np.cumsum(np.diff(bounds) / moduli)])
    return lambda x: -pressure * np.interp(x[0], bounds, compliance)


def hertz_model(*, radius: float = 1.0, E: float = 1.0, nu: float = 0.3, depth: float) -> ContactProblem:
    """A rigid cylinder of radius R touching the top face y = 0 at x = 0, moved down by ``depth``."""
    cylinder = Circle((0.0, radius), radius).indented(depth, (0.0, -1.0))
    return ContactProblem(
        name="hertz",
        youngs_modulus=E,
        poisson_ratio=nu,
        obstacle=cylinder,
        description=f"Hertz, R={radius:g}, E={E:g}, nu={nu:g}, d={depth:g}",
    )


def hertz_force_for(a: float, *, radius: float = 1.0, E: float = 1.0, nu: float = 0.3) -> float:
    """F = π a² E*/(4R): the force per unit thickness that gives the half-width a."""
    return np.pi * a**2 * E / (1.0 - nu**2) / (4.0 * radius)


class HertzErrors(NamedTuple):
    """A computed Hertz contact against the analytic one for its own force F."""

    force: float  #: F = −∫ σ_c ds
    a: float  #: 2√(RF/(πE*))
    p0: float  #: 2F/(πa)
    half_width: float  #: half the extent of the computed contact zone
    half_width_cells: float  #: (half_width − a)/h_contact
    peak_error: float  #: max p_h / p₀ − 1
    l2_error: float  #: ‖p_h − p‖_L²(Γ_C) / ‖p‖_L²(Γ_C)


def hertz_errors(profile, *, radius: float, E: float, nu: float, h_contact: float, centre: float = 0.0) -> HertzErrors:
    """Half-width, peak pressure and pressure-profile errors of a Hertz contact profile (``fem.contact.ContactProfile``;
    F read off it)."""
    if profile.weights is None or profile.points is None:
        raise InputError("hertz_errors needs a contact profile with points and weights")
    F = profile.force
    if not F > 0:
        raise InputError(f"no compressive contact force (F = {F:.3e}): the cylinder does not touch")
    E_star = E / (1.0 - nu**2)
    a = 2.0 * np.sqrt(radius * F / (np.pi * E_star))
    p0 = 2.0 * F / (np.pi * a)
    x = profile.points[:, 0] - centre
    p = -profile.sigma_c
    exact = p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
    active = profile.active
    half = 0.5 * float(x[active].max() - x[active].min()) if active.any() else 0.0
    w = profile.weights
    l2 = float(np.sqrt(np.sum(w * (p - exact) ** 2) / np.sum(w * exact**2)))
    return HertzErrors(F, a, p0, half, (half - a) / h_contact, float(p.max() / p0 - 1.0), l2)


class CattaneoMindlin(NamedTuple):
    """The Cattaneo–Mindlin shear traction of a cylinder (module docstring) at the points x."""

    a: float  #: the Hertz half-width 2√(RP/(πE*))
    p0: float  #: the Hertz peak pressure 2P/(πa)
    c: float  #: the stick half-width of the loading to Q (of Q* when unloaded): a√(1 − Q/(μP)), 0 when sliding
    c_back: float | None  #: where the reverse slip ends after unloading to Q, a√(1 − (Q* − Q)/(2μP)); None loading
    shear: np.ndarray  #: q(x), the shear traction in the direction of Q


def cattaneo_mindlin(
    x: np.ndarray,
    *,
    normal: float,
    tangential: float,
    mu: float,
    radius: float,
    E: float = 1.0,
    nu: float,
    peak: float | None = None,
) -> CattaneoMindlin:
    """The shear traction at the points x of a cylinder of ``radius`` pressed with ``normal`` force P, then
    loaded to ``tangential`` force Q, or (``peak`` = Q*) loaded to Q* and moved back to Q (Mindlin–Deresiewicz)."""

    a = 2.0 * np.sqrt(radius * normal / (np.pi * E / (1.0 - nu**2)))
    p0 = 2.0 * normal / (np.pi * a)

    def term(r: float) -> np.ndarray:
        return (r / a) * np.sqrt(np.maximum(1.0 - (x / r) ** 2, 0.0)) if r > 0.0 else np.zeros_like(x)

    if peak is None:
        c = a * np.sqrt(max(1.0 - tangential / (mu * normal), 0.0))
        return CattaneoMindlin(a, p0, c, None, mu * p0 * (term(a) - term(c)))
    c = a * np.sqrt(max(1.0 - peak / (mu * normal), 0.0))
    c_back = a * np.sqrt(max(1.0 - (peak - tangential) / (2.0 * mu * normal), 0.0))
    return CattaneoMindlin(a, p0, c, c_back, mu * p0 * (-term(a) + 2.0 * term(c_back) - term(c)))


def hertz_pair(
    radii: tuple[float, float], moduli: tuple[float, float], poisson: tuple[float, float]
) -> tuple[float, float]:
    """(R*, E*) of two bodies in plane-strain Hertz contact: 1/R* = 1/R₁ + 1/R₂ (R = inf: flat),
    1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂."""
    radii, moduli, poisson = (np.asarray(v, dtype=np.float64) for v in (radii, moduli, poisson))
    if radii.shape != (2,) or moduli.shape != (2,) or poisson.shape != (2,):
        raise InputError("hertz_pair takes two radii, two moduli and two Poisson ratios")
    if np.any(radii <= 0) or np.all(np.isinf(radii)) or np.any(moduli <= 0) or np.any(np.abs(poisson) >= 1):
        raise InputError(
            f"hertz_pair needs radii > 0 (not both flat), E > 0, |nu| < 1; got {radii}, {moduli}, {poisson}"
        )
    return float(1.0 / np.sum(1.0 / radii)), float(1.0 / np.sum((1.0 - poisson**2) / moduli))


def hertz_sphere_model(
    a: float,
    h_contact: float,
    *,
    radius: float | None = None,
    E: float = 1.0,
    nu: float = 0.3,
    size: float = 20.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> ContactProblem:
    """A rigid sphere of radius R (default 10a: a/R = 0.1) pressed d = a²/R into the quarter block of
    ``meshes3d.hertz_quarter_block(a, h_contact, size=size)``, symmetry planes x = 0 and y = 0 on rollers, the bottom
    clamped: Hertz's contact radius a at that depth."""
    R = 10.0 * a if radius is None else float(radius)
    if not (np.isfinite(R) and R > a):
        raise InputError(f"the sphere's radius must be finite and larger than the contact radius a, got {radius!r}")
    sphere = Sphere((0.0, 0.0, R), R).indented(a * a / R, (0.0, 0.0, -1.0))
    return ContactProblem(
        name="hertz-sphere",
        youngs_modulus=E,
        poisson_ratio=nu,
        obstacle=sphere,
        mesh=hertz_quarter_block(a, h_contact, size=size, comm=comm),
        boundary=BoundaryConditions(rollers=((0, 0.0), (1, 0.0))),
        description=f"Hertz sphere, a={a:g}, R={R:g}, h={h_contact:g}, E={E:g}, nu={nu:g}",
    )


def hertz_sphere_penalty(h_contact: float, *, E: float = 1.0, nu: float = 0.3, factor: float = 1e-3) -> float:
    """δ = factor · h_c / E*, E* = E/(1 − ν²): the penalty's compliance δ·p small beside the contact cells'."""
    return factor * h_contact * (1.0 - nu**2) / E


class HertzSphereErrors(NamedTuple):
    """A computed 3D Hertz contact against the analytic one for its own force F."""

    force: float  #: F = −symmetry·∫ σ_c ds
    a: float  #: (3FR/(4E*))^(1/3)
    p0: float  #: 3F/(2πa²)
    radius: float  #: the area-equivalent contact radius √(A/π), A = symmetry·(contact area of the model)
    radius_cells: float  #: (radius − a)/h_contact
    centre_error: float  #: p_h(centre)/p₀ − 1, p_h at the contact node nearest the centre
    l2_error: float  #: ‖p_h − p‖_L²(Γ_C) / ‖p‖_L²(Γ_C) (nodal quadrature)
    peak_error: float  #: max p_h / p₀ − 1 (P1 overshoots by a few per cent near the centre)


def hertz_sphere_errors(
    profile,
    *,
    radius: float,
    E: float,
    nu: float,
    h_contact: float,
    symmetry: int = 4,
    centre: tuple[float, float] = (0.0, 0.0),
) -> HertzSphereErrors:
    """Contact radius, centre pressure and pressure-profile errors of a 3D Hertz contact profile
    (``fem.contact.ContactProfile`` on a horizontal Γ_C; F read off it).  ``symmetry``: the copies of the model
    that make the whole block (4 for a quarter); ``centre``: (x, y) of the first contact point."""
    if profile.weights is None or profile.points is None:
        raise InputError("hertz_sphere_errors needs a contact profile with points and weights")
    F = symmetry * profile.force
    if not F > 0:
        raise InputError(f"no compressive contact force (F = {F:.3e}): the sphere does not touch")
    E_star = E / (1.0 - nu**2)
    a = (3.0 * F * radius / (4.0 * E_star)) ** (1.0 / 3.0)
    p0 = 3.0 * F / (2.0 * np.pi * a**2)
    r = np.hypot(profile.points[:, 0] - centre[0], profile.points[:, 1] - centre[1])
    p = -profile.sigma_c
    exact = p0 * np.sqrt(np.maximum(1.0 - (r / a) ** 2, 0.0))
    w = profile.weights
    area = symmetry * float(np.sum(w[profile.active]))
    equivalent = float(np.sqrt(area / np.pi))
    l2 = float(np.sqrt(np.sum(w * (p - exact) ** 2) / np.sum(w * exact**2)))
    return HertzSphereErrors(
        F,
        a,
        p0,
        equivalent,
        (equivalent - a) / h_contact,
        float(p[np.argmin(r)] / p0 - 1.0),
        l2,
        float(p.max() / p0 - 1.0),
    )
