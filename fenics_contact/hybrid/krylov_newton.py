"""Matrix-free interface Newton: Newton–GMRES on F(g) = g − T(g), for an Ω₁ solved by CG + AMG.

With Ω₁ solved iteratively its interface response T₁ is not formed: it would cost n_γ Ω₁ solves and
O(n_γ²) memory, and in 3D n_γ = O(h⁻²).  Each Newton step solves its interface equation

    (I − P₂P₁) d₁₂ = −F₁₂ − P₂F₂₁,   d₂₁ = P₁d₁₂ − F₂₁,
    P₁ = a⊙T₁ + b,   P₂ = a⊙Y₂ + b   (T(g) = (a⊙y₂ + b g₂₁, a⊙y₁ + b g₁₂), primal a = 2α, b = −1)

by a minimal-residual Krylov method (GMRES, ``KrylovInterface.direction``), each product one Ω₁ solve (its AMG
set-up reused) and one back-solve with Ω₂'s factorization of its Jacobian at its current active set (Y₂: Ω₂'s
linearized trace response).  It is preconditioned from the right by I − P₂P̃₁, P̃₁ the Robin map of a cheap Ω₁
model (a band next to γ and the AMG's coarse functions, ``hybrid.krylov_band``;
``InterfaceNewtonOptions.krylov_layers``, ``krylov_coarse``).

Ω₁ is linear, so what its solves give is kept and combined instead of solved again:

* every product keeps its Ω₁ data z, its Robin map P₁z and its Ω₁ state J₁⁻¹C z.  d₁₂ is a combination Σ cᵢzᵢ of the
  products' data, so P₁d₁₂ (hence d₂₁) and the Ω₁ state of every trial g + t d are the same combinations: the
  right-hand side costs one Ω₂ back-solve, the line search's trials and the accepted iterate no Ω₁ solve;
* the products of earlier Newton steps and load steps (at most ``RECYCLE``) stay in the minimal-residual space of the
  next step: their images under the new operator, z − P₂(P₁z), cost one Ω₂ back-solve each (P₁ does not change, P₂
  only with Ω₂'s active set);
* a combined state is checked against Ω₁'s equations (one product with J₁) and its error's trace estimated by one
  application of the AMG (``KrylovInterface.error_trace``): where it would move the transmission residual by more
  than a tenth of what the step is to reach (η_k r_k), a solve for its residual corrects it, from that state.

The Newton is inexact: GMRES stops at the relative residual η_k = min(``ETA_MAX``, r_k) (r_k the transmission
residual of the current pair), so the last steps are solved as accurately as the tolerance asks, but not below a
tenth of the pair's round-off floor (η_k ≥ 0.1 ρ_floor / r_k, ``hybrid.certificate``): there the products' CG errors,
not the interface equation, hold the GMRES residual.  A backtracking
line search on ‖F‖ globalizes it.  Every trial is an application of T (the Ω₂ semismooth Newton, warm-started).  A
pair whose transmission residual is below the tolerance is certified with Ω₁'s residual there solved for to Ω₁'s own
tolerance (as a Newton step of the subproblem would): the transmission residual of that pair certifies the result,
as for the other strategies.  Its floor (``hybrid.certificate``) adds to the certificate's rounding the effect of
that state's remaining error (its residual after the solve, one AMG application, as above); a certified pair within
``certificate.FLOOR_MARGIN`` of its floor that a step did not halve ends the iteration converged at the floor
(``IterationHistory.status`` ``"floor"``, a warning naming the tolerance that ends below it): at contrast 10⁶ with
Ω₁'s CG to 10⁻¹² that floor is 1–6·10⁻¹⁰, and a tolerance below it ends there in a few steps instead of 50 steps
not converged.  The first pair of a solve is solved the same way, from Ω₁'s state (a load path: the
last load step's).  The products' CG keeps Ω₁'s tolerance: on the 3D channel cube at contrast 10⁶ the coefficients
of the combinations multiply a product's error by orders of magnitude, and looser products there made the Newton
diverge.
"""

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from fenics_contact.fem.amg import AMGSolver, amg_coarse_space
from fenics_contact.hybrid.certificate import FLOOR_MARGIN, at_floor, relative
from fenics_contact.hybrid.krylov_band import BandPreconditioner
from fenics_contact.hybrid.options import IterationOptions
from fenics_contact.hybrid.response import PrimalPart
from fenics_contact.hybrid.step import IterationHistory, evaluate

__all__ = ["KrylovInterface", "krylov_newton_iterate", "ETA_MAX", "GMRES_RESTART", "RECYCLE"]

log = logging.getLogger(__name__)

#: the largest relative GMRES tolerance of a Newton step (the first steps, far from the fixed point)
ETA_MAX = 1e-2
#: directions in one minimal-residual space (the recycled and the step's own; at the limit the iterate becomes the
#: one direction of a new space: a restart; each holds an Ω₁ state, so a step holds at most this many Ω₁ vectors);
#: products per Newton step are capped at ``GMRES_PRODUCTS``
GMRES_RESTART = 200
GMRES_PRODUCTS = 2000
#: the directions kept for the next Newton steps and load steps (the newest; each holds an Ω₁ state: memory
#: ``RECYCLE`` Ω₁ vectors)
RECYCLE = 40
#: a direction whose image under the step's operator is this fraction of its norm or less within the span of the
#: others' is left out (dependent)
DEPENDENT = 1e-10
#: ... and a recycled direction whose image is this fraction or less (its coefficient would multiply its CG error)
RECYCLED_FLOOR = 1e-2
#: a Newton step from within this many times the tolerance that does not halve the residual solves every later
#: trial's Ω₁ to Ω₁'s own tolerance
FLOOR_WINDOW = 100.0
#: the smallest reduction of an Ω₁ state's residual asked of a solve for its correction
SMALLEST_FRACTION = 1e-12
#: trial step lengths 1, ½, … of the backtracking line search (each trial one application of T)
BACKTRACKS = 6
#: the smallest GMRES tolerance (below it the inexact Ω₁ solves dominate the products' error)
ETA_MIN = 1e-13


@dataclass(slots=True)
class _Direction:
    """One Ω₁ product: its data z (global interface values, 0 where no data act), its Robin map P₁z (global) and its
    Ω₁ state J₁⁻¹C z (local)."""

    z: np.ndarray
    p1: np.ndarray
    state: np.ndarray


class KrylovInterface:
    """The interface equation of the Newton step, matrix-free: P₁ v by one Ω₁ solve, P₂ v by one Ω₂
    back-solve with the factorization Ω₂ holds; vectors are global interface values (identical on all ranks).

    ``layers`` (None: no preconditioner) and ``coarse``: GMRES preconditioned from the right by the Robin response
    of a cheap Ω₁ model, the band of Ω₁ within ``layers`` couplings of γ and the coarse functions ``coarse`` levels
    below the finest of Ω₁'s AMG (0: none) beyond it (``hybrid.krylov_band``; on one process, else none).
    ``recycle``: the products kept for the next steps (0: none)."""

    def __init__(
        self,
        omega1: PrimalPart,
        omega2: PrimalPart,
        a: np.ndarray,
        b: float,
        *,
        layers: int | None = None,
        coarse: int = 0,
        recycle: int = RECYCLE,
    ) -> None:
        self.omega1, self.omega2, self.a, self.b = omega1, omega2, a, b
        self.free = np.flatnonzero(omega1.data_free() | omega2.data_free())  #: values whose data act (not γ ∩ Γ_D)
        self.products = 0  #: Ω₁ products of the Newton steps (each one Ω₁ solve and one Ω₂ back-solve)
        self.recycled = 0  #: products of earlier steps reused in a step's minimal-residual space (no Ω₁ solve)
        self.corrections = 0  #: Ω₁ solves correcting the combined state of a Newton step's direction
        self.layers, self.coarse, self.recycle = layers, coarse, recycle
        self._band: BandPreconditioner | None = None
        self._band_for: tuple | None = None  # (layers, coarse) of ``_band``
        self._kept: list[_Direction] = []  # the products kept for the next steps
        self._kept_for = None  # Ω₁'s operator they were solved with (its solver, operators set)
        self._pending: np.ndarray | None = None  # the Ω₁ state of the next application of T (``take_omega1_state``)
        self._vecs = None  # (b, x): Ω₁'s right-hand side and solution

    @property
    def preconditioner(self) -> BandPreconditioner | None:
        """The preconditioner of ``layers`` and ``coarse`` (built at its first use, kept while they stay; None:
        unpreconditioned GMRES)."""
        if self.layers is None or self.omega1.comm.size > 1:
            return None
        if self._band is None or self._band_for != (self.layers, self.coarse):
            if self._band is not None:
                self._band.destroy()
            solver = self.omega1.sub.solver
            P = amg_coarse_space(solver, self.coarse) if self.coarse and isinstance(solver, AMGSolver) else None
            self._band = BandPreconditioner(self.omega1, self.omega2, self.a, self.b, layers=self.layers, coarse=P)
            self._band_for = (self.layers, self.coarse)
        return self._band

    def solve_omega1(
        self, rhs: np.ndarray, *, rtol: float | None = None, guess: np.ndarray | None = None
    ) -> np.ndarray:
        """Ω₁'s state for its right-hand side ``rhs`` (local): one solve with Ω₁'s solver (AMG: to ``rtol``, by default
        its own, started from ``guess`` when given)."""
        solver = self.omega1.sub.solver
        b, x = self._work()
        b.getArray()[:] = rhs
        if isinstance(solver, AMGSolver):
            if guess is not None:
                x.getArray()[:] = guess
            solver.solve(b, x, rtol=rtol, guess=guess is not None)
        else:
            solver.solve(b, x)
        return x.getArray(readonly=True).copy()

    def omega1_residual(self, state: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, float]:
        """(rhs − J₁ state (local), its norm relative to ‖rhs‖): one product with Ω₁'s operator (0 for a vanishing
        rhs and residual, inf for a vanishing rhs only)."""
        b, x = self._work()
        x.getArray()[:] = state
        r = b.duplicate()
        try:
            self.omega1.sub.A.mult(x, r)
            b.getArray()[:] = rhs
            r.aypx(-1.0, b)
            size, off = b.norm(), r.norm()
            out = r.getArray(readonly=True).copy()
        finally:
            r.destroy()
        return out, (off / size if size > 0 else (0.0 if off == 0 else np.inf))

    def error_trace(self, residual: np.ndarray) -> np.ndarray:
        """N B r: the trace on γ (global) of the error of an Ω₁ state of residual r (local), B r one application of Ω₁'s
        AMG (one V-cycle: the error within the factor of its convergence rate; a direct Ω₁: the error)."""
        solver = self.omega1.sub.solver
        if not isinstance(solver, AMGSolver):
            return self.trace(self.solve_omega1(residual))
        b, x = self._work()
        b.getArray()[:] = residual
        solver.ksp.getPC().apply(b, x)
        return self.trace(x.getArray(readonly=True))

    def trace(self, state: np.ndarray) -> np.ndarray:
        """N x: Ω₁'s trace on γ (global) of its state x (local)."""
        return self.omega1.trace_rows(np.asarray(state)[:, None])[:, 0]

    def _work(self):
        """(b, x): vectors of Ω₁'s layout for its solves (made once)."""
        if self._vecs is None:
            self._vecs = (self.omega1.sub.b.duplicate(), self.omega1.sub.b.duplicate())
        return self._vecs

    def omega1_data_rhs(self, d: np.ndarray) -> np.ndarray:
        """C d: Ω₁'s right-hand side (local) of the Robin data d (global), no load."""
        part = self.omega1
        r = np.zeros(part.nown)
        r[part.data_at] = part.data_w * d[part.data_index]
        return r

    def set_omega1_state(self, state: np.ndarray, data: np.ndarray) -> None:
        """Ω₁'s state (local) for the next application of T at Ω₁'s data ``data`` (this rank's g₁₂), which then
        solves no Ω₁ (``take_omega1_state``)."""
        self._pending = (np.array(state, dtype=float), np.array(data, dtype=float))

    def take_omega1_state(self, data: np.ndarray) -> np.ndarray | None:
        """The state ``set_omega1_state`` set for the data ``data`` (this rank's g₁₂), once (None: none set for these
        data, Ω₁ is to be solved)."""
        pending, self._pending = self._pending, None
        if pending is None or not np.array_equal(pending[1], data):
            return None
        return pending[0]

    @staticmethod
    def _response(part: PrimalPart, d: np.ndarray, solver=None) -> np.ndarray:
        """N J⁻¹ C d: the trace on γ of the part's solve with Robin data d (global), no load."""
        r = np.zeros(part.nown)
        r[part.data_at] = part.data_w * d[part.data_index]
        x = part.solve(r, solver)
        return part.trace_rows(x[:, None])[:, 0]

    def _product(self, z: np.ndarray) -> _Direction:
        """P₁z by one Ω₁ solve, its state kept."""
        state = self.solve_omega1(self.omega1_data_rhs(z))
        return _Direction(z, self.a * self.trace(state) + self.b * z, state)

    def P1(self, v: np.ndarray) -> np.ndarray:
        return self._product(v).p1

    def P2(self, v: np.ndarray) -> np.ndarray:
        return self.a * self._response(self.omega2, v, self.omega2.sub.solver) + self.b * v

    def _recyclable(self) -> list[_Direction]:
        """The kept products, dropped when Ω₁'s operator changed since they were solved."""
        solver = self.omega1.sub.solver
        key = (id(solver), getattr(solver, "factorizations", None))
        if key != self._kept_for:
            self._kept, self._kept_for = [], key
        return list(self._kept)

    def direction(
        self, F12: np.ndarray, F21: np.ndarray, eta: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, bool]:
        """(d₁₂, d₂₁, the Ω₁ state of the data d₁₂ (local, no load), Ω₁ products, whether the residual reached η) of
        the Newton step at F = (F₁₂, F₂₁): the minimal residual of its interface equation over the kept products and
        the new ones (right-preconditioned Arnoldi, ``_MinimalResidual``)."""
        f, n, comm = self.free, self.a.size, self.omega1.comm
        band = self.preconditioner
        rhs = (-F12 - self.P2(F21))[f]
        target = eta * float(np.linalg.norm(rhs))
        space = _MinimalResidual(rhs)
        # the earlier products, under this step's P₂ (with the preconditioner: unpreconditioned, a hundred products per
        # step, the kept ones held the Newton at 1e-7 on the channel cube at contrast 1e6, without them it converged)
        recycle = self.recycle if band is not None else 0
        for d in self._recyclable() if recycle else ():
            space.add(d, d.z[f] - self.P2(d.p1)[f], RECYCLED_FLOOR)
        self.recycled += len(space.directions)
        products = 0
        v = space.residual
        while comm.bcast(space.norm > target, root=0) and products < GMRES_PRODUCTS:
            if len(space.directions) >= GMRES_RESTART:
                space = space.restarted(n, self.omega1.nown)
            nv = float(np.linalg.norm(v))
            if nv == 0.0:
                break
            z = np.zeros(n)
            z[f] = v / nv if band is None else band.solve(v / nv)
            d = self._product(z)
            products += 1
            v = space.add(d, z[f] - self.P2(d.p1)[f])  # Arnoldi: the next from the newest image
            if v is None:  # (an invariant space: the minimal residual is final)
                break
        c = comm.bcast(space.coefficients(), root=0)
        kept = space.directions
        d12 = sum((ci * d.z for ci, d in zip(c, kept)), np.zeros(n))
        state = sum((ci * d.state for ci, d in zip(c, kept)), np.zeros(self.omega1.nown))
        self._kept = kept[-recycle:] if recycle else []
        self.products += products
        # the coefficients multiply the products' CG errors: the combined state is checked against its equations, its
        # error's effect on P₁d₁₂ estimated, and corrected by a solve where it passes a tenth of the step's tolerance
        off, residual = self.omega1_residual(state, self.omega1_data_rhs(d12))
        if residual > 0.0 and isinstance(self.omega1.sub.solver, AMGSolver):
            effect = float(np.linalg.norm((self.a * self.error_trace(off))[f]))
            if effect > 0.1 * target:
                fraction = float(np.clip(0.05 * target / effect, SMALLEST_FRACTION, 0.5))
                state = state + self.solve_omega1(off, rtol=fraction)
                self.corrections += 1
        d21 = self.a * self.trace(state) + self.b * d12 - F21
        return d12, d21, state, products, bool(space.norm <= target)

    def destroy(self) -> None:
        if self._band is not None:
            self._band.destroy()
        for vec in self._vecs or ():
            vec.destroy()


class _MinimalResidual:
    """min ‖y − Σ cᵢ A zᵢ‖ over the directions added (GMRES in the form of GCR: the images A zᵢ orthonormalized by
    modified Gram–Schmidt, twice, A Z = Q R), the residual kept."""

    def __init__(self, y: np.ndarray) -> None:
        self.y = y
        self.residual = y.copy()
        self.directions: list[_Direction] = []
        self._Q: list[np.ndarray] = []
        self._R: list[np.ndarray] = []  # columns of R
        self._t: list[float] = []  # Qᵀ y

    @property
    def norm(self) -> float:
        return float(np.linalg.norm(self.residual))

    def add(self, direction: _Direction, image: np.ndarray, floor: float = DEPENDENT) -> np.ndarray | None:
        """Add a direction and its image A z (free values); returns the image's new orthonormal vector, or None when
        it lies in the span of the others (``DEPENDENT``: the direction is left out)."""
        q = image.copy()
        h = np.zeros(len(self._Q) + 1)
        for _ in range(2):
            for k, qk in enumerate(self._Q):
                s = float(qk @ q)
                h[k] += s
                q -= s * qk
        beta = float(np.linalg.norm(q))
        if beta <= floor * float(np.linalg.norm(image)) or beta == 0.0:
            return None
        q /= beta
        h[-1] = beta
        self._Q.append(q)
        self._R.append(h)
        self.directions.append(direction)
        t = float(q @ self.residual)
        self._t.append(t)
        self.residual -= t * q
        return q

    def coefficients(self) -> np.ndarray:
        """c of the minimal residual (R c = Qᵀ y).

        Where the products' CG errors hold the residual above the step's tolerance (at the transmission residual's
        round-off floor: a stiff inclusion of contrast 10⁶ cut by γ at tol 10⁻¹⁰), the Arnoldi goes on with images
        ever more dependent, R's diagonal falls to 10⁻⁹ of its first entry and the back-substitution overflows; c is
        then the least-squares solution with R's singular values below ``DEPENDENT`` of its largest left out."""
        m = len(self._R)
        if m == 0:
            return np.zeros(0)
        R = np.zeros((m, m))
        for j, col in enumerate(self._R):
            R[: col.size, j] = col
        t = np.array(self._t)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            c = sla.solve_triangular(R, t, lower=False)
        if np.all(np.isfinite(c)) and float(np.max(np.abs(c))) * float(np.max(np.abs(R))) < 1.0 / DEPENDENT * max(
            float(np.linalg.norm(t)), np.finfo(float).tiny
        ):
            return c
        return np.linalg.lstsq(R, t, rcond=DEPENDENT)[0]

    def restarted(self, n: int, nown: int) -> "_MinimalResidual":
        """A space of one direction, the current minimizer (its image y − residual)."""
        c = self.coefficients()
        d = _Direction(
            sum((ci * d.z for ci, d in zip(c, self.directions)), np.zeros(n)),
            sum((ci * d.p1 for ci, d in zip(c, self.directions)), np.zeros(n)),
            sum((ci * d.state for ci, d in zip(c, self.directions)), np.zeros(nown)),
        )
        space = _MinimalResidual(self.y)
        space.add(d, self.y - self.residual)
        return space


def krylov_newton_iterate(
    step, options: IterationOptions, *, name: str, monitor=None, initial: np.ndarray | None = None
) -> IterationHistory:
    """Newton–GMRES on g = T(g) (``step.krylov_interface()``: a ``KrylovInterface``, whose Ω₁ state the step's
    application of T takes when one is set); each record is one application of T, its ``info["gmres"]`` the Ω₁
    products of the step that led to it, ``info["omega1"]`` how its Ω₁ state came: ``"combined"`` (no solve),
    ``"solved"`` (the combination corrected by a solve to the step's accuracy) or ``"certified"`` (corrected by a solve
    to Ω₁'s own tolerance: the first pair and the last)."""
    nopt = options.newton
    history = IterationHistory()
    t_off = time.perf_counter()
    kry = step.krylov_interface()
    kry.layers, kry.coarse = nopt.krylov_layers, nopt.krylov_coarse
    history.time_offline_s = time.perf_counter() - t_off
    start = time.perf_counter()
    comm = step.comm
    iface = step.interface
    n = iface.size
    omega1 = kry.omega1
    solver = omega1.sub.solver
    tight = solver.options.rtol if isinstance(solver, AMGSolver) else 0.0  # (a direct Ω₁: every state solved)

    def halves(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return iface.gather(g[:n]), iface.gather(g[n:])

    def fnorm(g: np.ndarray, Tg: np.ndarray) -> float:
        return float(np.linalg.norm(np.concatenate([a - b for a, b in zip(halves(g), halves(Tg))])))

    weights, alpha = iface.gather(iface.weights), 0.5 * kry.a

    def certificate_change(e: np.ndarray, state: np.ndarray, g: np.ndarray) -> float:
        """How much an error e of Ω₁'s trace (global) moves the transmission residual of the pair: the jump by
        ‖e‖_γ/‖u₁‖_γ, the balance by ‖α e‖_γ/‖t₁‖_γ (the certificate's norms, Ω₁'s of its sizes)."""
        u = kry.trace(state)
        t = iface.gather(g[:n]) - alpha * u

        def norm(v: np.ndarray) -> float:
            return float(np.sqrt(weights @ v**2))

        return max(relative(norm(e), norm(u)), relative(norm(alpha * e), norm(t)))

    def pair(g: np.ndarray, state: np.ndarray, target: float | None) -> tuple[np.ndarray, object, np.ndarray]:
        """T(g), its record and Ω₁'s state: ``state`` (a combination of solved states) when its error moves the
        transmission residual by ``target`` or less (``KrylovInterface.error_trace``), else corrected by a solve for
        its residual to the fraction that brings it there; ``target`` None: that solve to Ω₁'s own tolerance."""
        rhs = omega1.rhs(iface.gather(g[:n]), np.zeros(0))
        off, residual = kry.omega1_residual(state, rhs)
        how = "combined"
        if target is None or tight == 0.0:
            state, how = state + kry.solve_omega1(off), "certified"
        elif residual > 0.0:
            effect = certificate_change(kry.error_trace(off), state, g)
            if effect > target:
                fraction = float(np.clip(0.5 * target / effect, SMALLEST_FRACTION, 0.5))
                # (a fraction at Ω₁'s own tolerance or below: the solve of the certified pair)
                fraction, how = (tight, "certified") if fraction <= tight else (fraction, "solved")
                state = state + kry.solve_omega1(off, rtol=fraction)
        kry.set_omega1_state(state, g[:n])
        Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
        rec.info["omega1"] = how
        if how == "certified" and tight > 0.0:  # the floor: the certificate's rounding and Ω₁'s solve error
            rest, _ = kry.omega1_residual(state, rhs)
            rec.info["floor"] += certificate_change(kry.error_trace(rest), state, g)
        return Tg, rec, state

    def certified(rec) -> bool:
        """The pair glues (below tol, or at its round-off floor), Ω₁'s state the correction of its residual solved
        to Ω₁'s tolerance."""
        return bool((rec.residual < options.tol or history.at_floor) and rec.info["omega1"] == "certified")

    g = step.initial_data() if initial is None else np.array(initial, dtype=float)
    Tg, rec, u1 = pair(g, omega1.state(), None)
    # every trial's Ω₁ solved to Ω₁'s own tolerance once a step within FLOOR_WINDOW × tol of the tolerance fails to
    # halve the residual: there the combined states' errors hold the residual (a stiff inclusion of contrast 10⁶ cut
    # by γ at tol 10⁻¹⁰ hovered at 1–3·10⁻¹⁰ for 50 steps with combined states)
    exact = False
    steps_left = nopt.max_steps
    while not certified(rec) and steps_left > 0 and history.iterations < options.max_iterations:
        if rec.residual < options.tol:  # glued: certify, Ω₁'s residual there solved for
            Tg, rec, u1 = pair(g, u1, None)
            continue
        F12, F21 = (a - b for a, b in zip(halves(g), halves(Tg)))
        norm0 = float(np.linalg.norm(np.concatenate([F12, F21])))
        # (no lower than a tenth of the floor: below it the products' errors hold GMRES, not the interface equation)
        eta = float(np.clip(max(min(ETA_MAX, rec.residual), 0.1 * rec.info["floor"] / rec.residual), ETA_MIN, ETA_MAX))
        d12, d21, du1, products, reached = kry.direction(F12, F21, eta)
        d12, d21 = comm.bcast((d12, d21), root=0)
        steps_left -= 1
        history.newton_steps += 1
        if not reached:
            log.warning("%s: GMRES stopped at %d products above its tolerance %.1e", name, products, eta)
        # the trials' Ω₁: the combination, checked against its equations to the accuracy the step's result needs
        target = 0.1 * eta * rec.residual  # (the step's forcing: the trials' Ω₁ may move it by a tenth of it)
        g0, rec0, u10, t = g, rec, u1, 1.0
        while True:  # backtracking; Ω₁ is affine in its data: its trial state is the combination
            g = g0 + t * np.concatenate([iface.local(d12), iface.local(d21)])
            Tg, rec, u1 = pair(g, u10 + t * du1, None if exact else target)
            rec.info["gmres"] = products
            rec.info["step_length"] = t
            accepted = (
                rec.residual < options.tol
                or fnorm(g, Tg) <= (1.0 - 1e-4 * t) * norm0
                or rec.residual < 0.5 * rec0.residual
            )
            if accepted or history.iterations >= options.max_iterations or t <= 0.5 ** (BACKTRACKS - 1):
                break
            t *= 0.5
        if rec.info["omega1"] == "certified" and rec.residual >= options.tol:
            history.at_floor = at_floor(rec.residual, rec.info["floor"], rec0.residual)
        if not exact and rec.residual > 0.5 * rec0.residual and rec0.residual < FLOOR_WINDOW * options.tol:
            exact, kry.recycle = True, 0
        log.info(
            "%s: Newton–GMRES step %d, %d products (η %.1e), step length %g, residual %.3e (Ω₁ %s)",
            name,
            history.newton_steps,
            products,
            eta,
            t,
            rec.residual,
            rec.info["omega1"],
        )
    history.converged = certified(rec)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    log.info(
        "%s: %s, %d Newton–GMRES steps, %d products (%d recycled), %d applications of T, transmission residual %.3e, "
        "online %.3f s",
        name,
        "converged" if history.converged else "NOT converged",
        history.newton_steps,
        kry.products,
        kry.recycled,
        history.iterations,
        rec.residual,
        history.time_s,
    )
    if comm.rank == 0 and not history.converged:
        log.warning("%s: the Newton–GMRES interface iteration did not reach the tolerance %g", name, options.tol)
    if comm.rank == 0 and history.at_floor:
        log.warning(
            "%s: converged at the round-off floor %.1e of the transmission residual (residual %.1e above tol %.1e; "
            "status 'floor'): the pair glues as far as Ω₁'s CG and the certificate's rounding resolve it; ask a tol of "
            "%.0e or more, or solve Ω₁ directly (solver='direct')",
            name,
            rec.info["floor"],
            rec.residual,
            options.tol,
            FLOOR_MARGIN * rec.info["floor"],
        )
    return history
