"""Rigid obstacles: a signed distance d(x) (> 0 outside the obstacle) and the contact direction ν(x).

Small-deformation frictionless contact with a rigid obstacle (the docs' theory page, 'Gap and obstacles') reads

    u·ν ≤ g  on Γ_C,   g(x) = d(x),   ν(x) = −∇d(x)/|∇d(x)|,

ν the unit vector from a body point towards the obstacle (for an obstacle
flush with a straight Γ_C it is the body's outward normal n).  The primal
penalty acts on (u·ν − g)⁺ at the Γ_C vertices, the mixed one on u·n = g at the
Gauss–Lobatto nodes (``fem.primal``, ``fem.mixed``).  Obstacles:

* ``Plane(point, normal)``: the half-plane {(x − point)·normal ≤ 0}; ``normal``
  is the obstacle's outward unit normal (pointing towards the body).
* ``Circle(centre, radius)``: a rigid disc (in 3D the cylinder along z);
  d = |x − c| − R, undefined at the centre.
* ``Sphere(centre, radius)``: a rigid ball (the 3D indenter); d = |x − c| − R,
  undefined at the centre.
* ``SignedDistance(distance, normal=None)``: any callable d; ``normal`` (the
  obstacle's outward normal ∇d/|∇d|) by central differences when not given.
  A callable may return NaN where its gap is undefined: a contact node there
  is refused (InputError).

``obstacle.translated(t)`` moves an obstacle rigidly by the vector t (its
first-order effect on the gap is g − t·ν); ``indented(depth,
direction)`` moves it by depth·direction (unit direction).

Points are numpy arrays of shape (3, N) or (2, N) (DOLFINx convention); gaps
come back with shape (N,), directions ν with shape (k, N), k the obstacle's own
dimension: 2 for ``Circle`` and for a ``Plane`` given by 2-vectors (or 3-vectors
with z = 0), 3 for ``Sphere`` and a ``Plane`` with a z component.  A planar
obstacle is the same obstacle extruded along z in 3D (its ν has ν_z = 0);
``evaluate_obstacle`` gives ν with as many components as the problem's dimension.
"""

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fenics_contact.errors import InputError

__all__ = [
    "Obstacle",
    "Plane",
    "Circle",
    "Sphere",
    "SignedDistance",
    "Translated",
    "evaluate_obstacle",
    "check_obstacle_side",
]


def _as_vector(value: npt.ArrayLike, name: str, *, unit: bool = False, dim: int | None = None) -> np.ndarray:
    """A finite 2- or 3-vector (a 3-vector with z = 0 is cut to 2: the planar one); ``dim`` = 3: padded to 3."""
    v = np.asarray(value, dtype=np.float64).ravel()
    if v.size == 3 and v[2] == 0.0 and dim != 3:
        v = v[:2]
    if v.size not in (2, 3) or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be a finite 2D or 3D vector, got {value!r}")
    if dim == 3 and v.size == 2:
        v = np.append(v, 0.0)
    if unit:
        norm = float(np.linalg.norm(v))
        if norm == 0.0:
            raise InputError(f"{name} must be non-zero")
        v = v / norm
    return v


def _xy(x: np.ndarray, k: int = 2) -> np.ndarray:
    """The first k coordinates of the points x (k, N), zero-padded when x has fewer rows."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] >= k:
        return x[:k]
    return np.vstack([x, np.zeros((k - x.shape[0], x.shape[1]))])


def _padded(v: np.ndarray, k: int) -> np.ndarray:
    return np.concatenate([v, np.zeros(k - v.size)]) if v.size < k else v


class Obstacle(ABC):
    """A rigid obstacle: signed distance d (> 0 outside) and outward normal ∇d/|∇d|."""

    @abstractmethod
    def distance(self, x: np.ndarray) -> np.ndarray:
        """d(x), shape (N,): > 0 outside the obstacle (NaN where undefined)."""

    @abstractmethod
    def outward_normal(self, x: np.ndarray) -> np.ndarray:
        """∇d/|∇d| at x, shape (k, N): the obstacle's outward unit normal (NaN where undefined)."""

    def gap(self, x: np.ndarray) -> np.ndarray:
        """g(x) = d(x): the initial gap along ν."""
        return self.distance(x)

    def direction(self, x: np.ndarray) -> np.ndarray:
        """ν(x) = −∇d/|∇d|, shape (k, N): the unit direction from a body point towards the obstacle."""
        return -self.outward_normal(x)

    def translated(self, t: npt.ArrayLike) -> "Obstacle":
        """The obstacle moved rigidly by the vector t."""
        return Translated(self, _as_vector(t, "the translation"))

    def indented(self, depth: float, direction: npt.ArrayLike) -> "Obstacle":
        """The obstacle moved by ``depth`` along the unit vector ``direction`` (into the body)."""
        if not np.isfinite(depth):
            raise InputError(f"the indentation depth must be finite, got {depth!r}")
        return self.translated(float(depth) * _as_vector(direction, "the indentation direction", unit=True))


@dataclass(frozen=True, slots=True)
class Plane(Obstacle):
    """The half-space {(x − point)·normal ≤ 0}; ``normal``: its outward unit normal (towards the body).

    2-vectors (or 3-vectors with z = 0 in both) give the planar half-plane, extruded along z in 3D.
    """

    point: tuple[float, ...]
    normal: tuple[float, ...]

    def __post_init__(self) -> None:
        p, n = _as_vector(self.point, "Plane point"), _as_vector(self.normal, "Plane normal", unit=True)
        k = max(p.size, n.size)
        object.__setattr__(self, "point", tuple(map(float, _padded(p, k))))
        object.__setattr__(self, "normal", tuple(map(float, _padded(n, k))))

    def distance(self, x: np.ndarray) -> np.ndarray:
        p, n = np.asarray(self.point), np.asarray(self.normal)
        return np.einsum("i,in->n", n, _xy(x, p.size) - p[:, None])

    def outward_normal(self, x: np.ndarray) -> np.ndarray:
        return np.repeat(np.asarray(self.normal)[:, None], np.shape(x)[1], axis=1)


class _Round(Obstacle):
    """d = |x − centre| − radius in the dimension of ``centre`` (a disc or a ball); undefined within 1e−8·radius
    of the centre. Subclasses are frozen dataclasses with the fields ``centre`` and ``radius``."""

    __slots__ = ()

    def _offset(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = _xy(x, len(self.centre)) - np.asarray(self.centre)[:, None]
        return r, np.linalg.norm(r, axis=0)

    def distance(self, x: np.ndarray) -> np.ndarray:
        r, rho = self._offset(x)
        return np.where(rho > 1e-8 * self.radius, rho - self.radius, np.nan)

    def outward_normal(self, x: np.ndarray) -> np.ndarray:
        r, rho = self._offset(x)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(rho > 1e-8 * self.radius, r / rho, np.nan)


@dataclass(frozen=True, slots=True)
class Circle(_Round):
    """A rigid disc (a cylinder in plane strain): d = |x − centre| − radius; undefined within 1e−8·radius of the
    centre."""

    centre: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", tuple(map(float, _as_vector(self.centre, "Circle centre"))))
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"the circle radius must be > 0, got {self.radius!r}")
        object.__setattr__(self, "radius", float(self.radius))


@dataclass(frozen=True, slots=True)
class Sphere(_Round):
    """A rigid ball: d = |x − centre| − radius (x in 3D); undefined within 1e−8·radius of the centre."""

    centre: tuple[float, float, float]
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", tuple(map(float, _as_vector(self.centre, "Sphere centre", dim=3))))
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"the sphere radius must be > 0, got {self.radius!r}")
        object.__setattr__(self, "radius", float(self.radius))


@dataclass(frozen=True, slots=True)
class SignedDistance(Obstacle):
    """Any signed distance callable d(x) (> 0 outside), with its outward normal or by central differences.

    ``step`` is the finite-difference step (a length) used when ``normal`` is None; None (the default): at each
    point x, 10⁻⁶·max(‖x‖∞, |d(x)|), relative to the coordinates so the same in any unit of length (10⁻⁶ where
    both vanish); ``dim`` the
    dimension of d: 2 (d of x, y: a planar obstacle, extruded along z in 3D) or 3 (d of x, y, z, the
    differences taken along all three).  ``normal`` maps x (3, N) to (dim, N).
    """

    function: Callable[[np.ndarray], np.ndarray]
    normal: Callable[[np.ndarray], np.ndarray] | None = None
    step: float | None = None
    dim: int = 2

    def __post_init__(self) -> None:
        if not callable(self.function):
            raise InputError("SignedDistance needs a callable d(x)")
        if self.normal is not None and not callable(self.normal):
            raise InputError("the normal of a SignedDistance must be a callable x -> (dim, N) or None")
        if self.step is not None and not (np.isfinite(self.step) and self.step > 0):
            raise InputError(f"the finite-difference step must be > 0, got {self.step!r}")
        if self.dim not in (2, 3) or isinstance(self.dim, bool):
            raise InputError(f"the dimension of a SignedDistance must be 2 or 3, got {self.dim!r}")

    def _call(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape[0] == 2:
            x = np.vstack([x, np.zeros((1, x.shape[1]))])
        return np.asarray(self.function(x), dtype=np.float64).reshape(-1)

    def distance(self, x: np.ndarray) -> np.ndarray:
        return self._call(x)

    def outward_normal(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if self.normal is not None:
            xx = x if x.shape[0] == 3 else np.vstack([x, np.zeros((1, x.shape[1]))])
            n = np.asarray(self.normal(xx), dtype=np.float64).reshape(self.dim, -1)
        else:
            x = _xy(x, self.dim) if x.shape[0] < self.dim else x
            n = np.empty((self.dim, x.shape[1]))
            step = self.step
            if step is None:  # relative to the point's coordinates and distance: any unit of length
                with np.errstate(invalid="ignore"):
                    size = np.fmax(np.max(np.abs(x), axis=0, initial=0.0), np.abs(self._call(x)))
                step = 1e-6 * np.where(np.isfinite(size) & (size > 0), size, 1.0)
            for i in range(self.dim):
                e = np.zeros((x.shape[0], np.size(step)))
                e[i] = step
                n[i] = (self._call(x + e) - self._call(x - e)) / (2.0 * step)
        with np.errstate(invalid="ignore", divide="ignore"):
            return n / np.linalg.norm(n, axis=0)


@dataclass(frozen=True, slots=True)
class Translated(Obstacle):
    """``base`` moved rigidly by the vector ``shift``: d(x) = d_base(x − shift)."""

    base: Obstacle
    shift: tuple[float, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "shift", tuple(map(float, _as_vector(self.shift, "the translation"))))

    def _back(self, x: np.ndarray) -> np.ndarray:
        shift = np.asarray(self.shift)
        y = np.array(_xy(x, max(np.shape(x)[0], shift.size)), dtype=np.float64, copy=True)
        y[: shift.size] -= shift[:, None]
        return y

    def distance(self, x: np.ndarray) -> np.ndarray:
        return self.base.distance(self._back(x))

    def outward_normal(self, x: np.ndarray) -> np.ndarray:
        return self.base.outward_normal(self._back(x))

    def translated(self, t: npt.ArrayLike) -> Obstacle:
        t = _as_vector(t, "the translation")
        k = max(t.size, len(self.shift))
        return Translated(self.base, tuple(_padded(np.asarray(self.shift), k) + _padded(t, k)))


def check_obstacle_side(obstacle: Obstacle, nu: np.ndarray, normals: np.ndarray, gap: np.ndarray, *, comm=None) -> None:
    """InputError if the obstacle's direction ν points into the body at most of the contact nodes nearest it.

    ``nu`` (N, d), ``gap`` (N,): ν and the gap from ``evaluate_obstacle`` at the Γ_C nodes; ``normals`` (N, d):
    the body's outward unit normals there (d the dimension; extra columns of ``normals`` are ignored).  The
    obstacle lies outside the body, so ν (from the body towards the
    obstacle) points out of it, ν·n > 0, where the two touch.  Among the nodes nearest the obstacle (gap within
    a tenth of the gaps' spread of the smallest: all of a flat Γ_C facing a plane, the apex of a curved Γ_C under
    a small indenter, not the parts of a curved Γ_C that face away), ν·n < 0 at more than half means the obstacle
    is on the wrong side: a flipped plane normal (a plane's normal points from the obstacle into the body), a
    circle centred inside the body.  Solved, it would be a huge indentation pushing the wrong way.  With ``comm``
    the counts are summed over the ranks.
    """
    nu = np.asarray(nu, dtype=np.float64)
    dim = nu.shape[1] if nu.ndim == 2 else 2
    nu = nu.reshape(-1, dim)
    normals = np.asarray(normals, dtype=np.float64)[:, :dim].reshape(-1, dim)
    gap = np.asarray(gap, dtype=np.float64).reshape(-1)
    low = float(gap.min(initial=np.inf))
    high = float(gap.max(initial=-np.inf))
    if comm is not None:
        low, high = comm.allreduce(low, op=MPI.MIN), comm.allreduce(high, op=MPI.MAX)
    near = gap <= low + 0.1 * (high - low) + 1e-12 * max(abs(low), abs(high), 1e-300)
    cosine = np.einsum("ij,ij->i", nu[near], normals[near])
    counts = np.array([np.count_nonzero(cosine < -0.1), cosine.size], dtype=np.int64)
    if comm is not None:
        counts = comm.allreduce(counts)
    inward, total = (int(c) for c in counts)
    if total and inward > total / 2:
        raise InputError(
            f"the obstacle is on the wrong side of Gamma_C: its direction towards the obstacle points into the body "
            f"at {inward} of the {total} contact nodes nearest it ({obstacle!r}). A plane's normal points from the "
            "obstacle into the body (the wall at x = 1 of a body on x < 1 has normal [-1, 0]); a circle's centre "
            "lies outside the body"
        )


def evaluate_obstacle(
    obstacle: Obstacle, points: np.ndarray, *, dim: int = 2, comm=None
) -> tuple[np.ndarray, np.ndarray]:
    """Gap g (N,) and direction ν (N, dim) at contact nodes ``points`` (N, ≥ dim); InputError if undefined.

    The first ``dim`` coordinates of the points are the obstacle's input.  A planar obstacle (ν with two
    components) in 3D is the obstacle extruded along z: ν_z = 0.  The gap is undefined where d or ν is not
    finite or ν is not a unit vector in ``dim`` dimensions (a signed distance returning NaN, the centre of a
    circle, a zero gradient, a 3D obstacle whose ν leaves the plane of a 2D problem).
    With ``comm`` the check is collective: every rank raises if any rank has a bad node.
    """
    if dim not in (2, 3):
        raise InputError(f"the dimension of the contact nodes must be 2 or 3, got {dim!r}")
    points = np.asarray(points, dtype=np.float64).reshape(-1, points.shape[-1] if np.ndim(points) == 2 else 2)
    n = points.shape[0]
    x = np.zeros((dim, n))
    k = min(dim, points.shape[1])
    x[:k] = points[:, :k].T
    g = np.asarray(obstacle.gap(x), dtype=np.float64).reshape(-1) if n else np.zeros(0)
    nu = np.asarray(obstacle.direction(x), dtype=np.float64) if n else np.zeros((dim, 0))
    rows = (nu.size // n if nu.size % n == 0 else 0) if n else dim
    if g.shape != (n,) or rows not in (2, 3):
        raise InputError(
            f"the obstacle returned gaps of shape {g.shape} and normals of shape {nu.shape} "
            f"for {n} points (expected ({n},) and ({dim}, {n}))"
        )
    nu = nu.reshape(rows, n).T
    if rows < dim:
        nu = np.hstack([nu, np.zeros((n, dim - rows))])
    elif rows > dim:
        nu = nu[:, :dim]
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(g) & np.all(np.isfinite(nu), axis=1) & (np.abs(np.linalg.norm(nu, axis=1) - 1.0) < 1e-6))
    where = points[bad][:3, :dim].tolist()
    count = int(np.count_nonzero(bad))
    if comm is not None:
        count = comm.allreduce(count)
        where = [p for part in comm.allgather(where) for p in part][:3]
    if count:
        raise InputError(
            f"the obstacle's gap is undefined at {count} contact node(s) of Gamma_C, e.g. at {where} "
            "(a signed distance returning NaN or a zero gradient, or a node at the centre of a circle): "
            "move the obstacle or restrict Gamma_C to where the gap is defined"
        )
    return g, nu
