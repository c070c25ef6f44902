"""The interface problem of the Newton method and its condensation onto the Γ_C unknowns.

Every algorithm exchanges Robin data g = (g₁₂, g₂₁) on γ through traces y_i (u_i on γ for the primal
methods, σ_in_i for the mixed ones):

    T(g) = (a ⊙ y₂(g₂₁) + b g₂₁,  a ⊙ y₁(g₁₂) + b g₁₂)       (primal a = 2α, b = −1; mixed a = −2β, b = 1).

``InterfaceProblem`` holds what the Newton method needs: Ω₁'s affine response y₁ = T₁ g₁₂ + t₁, Ω₂'s
affine pieces (``response.AffinePart``) and this update.  Ω₂ is linear except for the penalty on Γ_C:
with the contact values s = Q x (u_c at the Γ_C nodes, or σ_c at the Gauss–Lobatto nodes) and the
penalty force λ = D s⁺ (D = w/δ or w/ε),

    J₀ x = b₂ + C₂ g₂₁ − Qᵀ λ,   y₂ = N₂ x,

where J₀ is the Ω₂ operator with no contact node active.  Eliminating x and g (everything but λ enters
linearly) leaves an equation on the Γ_C unknowns alone (``CondensedInterface``),

    s = s_L − M D s⁺,

with M (n_c × n_c, the contact compliance of the glued problem) and the load term s_L.  Offline: J₀ is
back-solved for the n_γ data and n_c contact columns (Yc, Sc, Yq, Sq) and the interface matrix
K = I − P₁P₂ (P₁ = a⊙T₁ + b, P₂ = a⊙Yc + b) factorized; online: one J₀ back-solve and one Ω₁ load solve
give s_L.  With Algorithm 1 the condensation is exact.

A load path's steps reuse the condensation while Γ_C's normals stay (a moved plane, a changed gap): the load
term's dense solve is kept while the load responses are, Gq and Yq are formed once the condensation serves a
second step, and a warm-started step's contact Newton starts from the last step's active set, which a small load
increment mostly keeps (one dense solve on it confirms it).

The contact rows are Q = Σ_k diag(ν_k) E_kᵀ (ν the normals, E_k the unit vectors of displacement component
k at the Γ_C nodes).  Where Ω₂ gives its responses per component (``PrimalPart.component_responses``), the
condensation is formed per component once (G_k = K⁻¹P₁(a ⊙ N J₀⁻¹E_k), M_kl = E_kᵀJ₀⁻¹E_l + E_kᵀJ₀⁻¹C G_l)
and a load step whose obstacle moved the normals recombines M = Σ_kl diag(ν_k) M_kl diag(ν_l) by sums: the
step then costs s_L and the contact Newton.
"""

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from fenics_contact.errors import ConvergenceError
from fenics_contact.hybrid.contact_newton import ContactNewtonHistory, contact_solve
from fenics_contact.hybrid.fronts import contact_chains
from fenics_contact.hybrid.options import InterfaceNewtonOptions
from fenics_contact.hybrid.response import AffinePart

__all__ = ["InterfaceProblem", "CondensedInterface"]

#: a trace row whose entries are all below this fraction of the largest entry is zero (round-off)
ROUND_OFF = 1.0e4 * np.finfo(np.float64).eps


@dataclass(slots=True)
class InterfaceProblem:
    """What the Newton method needs from a step: Ω₁ response, Ω₂ pieces, the update y ↦ a⊙y + b g.

    ``gather``/``local`` map one half of the step's data (g₁₂ or g₂₁, local owned values) to the
    global numbering and back; ``condensed`` caches the offline condensation.
    """

    omega1: object
    omega2: AffinePart
    a: np.ndarray
    b: float
    gather: object
    local: object
    options: InterfaceNewtonOptions
    condensed: "CondensedInterface | None" = None
    free: np.ndarray = None  #: interface values whose data act on a subdomain (others stay 0: γ ∩ Γ_D)

    def __post_init__(self) -> None:
        if self.free is None:
            self.free = self.omega2.data_free() | (np.abs(self.omega1.T).sum(axis=0) > 0.0)

    def halves(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global (g₁₂, g₂₁) from the step's local data."""
        n = g.size // 2
        return self.gather(g[:n]), self.gather(g[n:])

    def data(self, g12: np.ndarray, g21: np.ndarray) -> np.ndarray:
        """The step's local data from global halves."""
        return np.concatenate([self.local(g12), self.local(g21)])

    def unknowns(self, D2: np.ndarray) -> np.ndarray:
        """The data values the Newton system solves for: the free ones, less those whose trace no data moves on
        either side (rows of T₁ and of ∂y₂/∂g₂₁ = D2 zero to round-off).

        At such a value p (a mixed method's γ ending on a traction-free side: the AW vertex stress there has
        σn·t = 0, so the tangential trace σ_xy vanishes in both subdomains) the update only swaps the data,
        g₁₂(p) ← g₂₁(p) and back, and the rows of both halves of the Jacobian, e_p − e_p and −e_p + e_p, are
        dependent: I − P₁P₂ is singular.  The subdomains see the data only through ∫_γ g·τn over the traces
        τn, which lack that value, so the data with g(p) held are already the whole trace space: solving for the
        others loses nothing (the pair, and the fixed point, are the same), and the system on them is regular.
        """
        f = np.flatnonzero(self.free)
        T1, tiny = self.omega1.T, ROUND_OFF
        still = np.linalg.norm(T1[f], axis=1) <= tiny * max(np.abs(T1).max(), 1e-300)
        still &= np.linalg.norm(D2[f], axis=1) <= tiny * max(np.abs(D2).max(), 1e-300)
        return f[~still]

    def step_direction(self, F12: np.ndarray, F21: np.ndarray, D2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Newton direction of F(g) = g − T(g) with ∂y₂/∂g₂₁ = D2: (I − P₁P₂) d₂₁ = −F₂₁ − P₁F₁₂, d₁₂ = P₂d₂₁ − F₁₂,
        on the ``unknowns`` (the other components of d zero)."""
        f = self.unknowns(D2)
        a, eye = self.a[f], np.eye(f.size)
        P1 = a[:, None] * self.omega1.T[np.ix_(f, f)] + self.b * eye
        P2 = a[:, None] * D2[np.ix_(f, f)] + self.b * eye
        d12, d21 = np.zeros(self.a.size), np.zeros(self.a.size)
        d21[f] = sla.solve(eye - P1 @ P2, -F21[f] - P1 @ F12[f])
        d12[f] = P2 @ d21[f] - F12[f]
        return d12, d21


class CondensedInterface:
    """Offline condensation of the glued linear problem onto the Γ_C unknowns: s = s_L − M λ."""

    def __init__(self, problem: InterfaceProblem, previous: "CondensedInterface | None" = None) -> None:
        """``previous``: the condensation of the same problem before its contact normals moved (an obstacle
        step): its interface matrix K and the Γ_C chains are kept when the data response Yc is unchanged, and
        so are its per-component pieces when Ω₂ gives its responses per displacement component
        (``PrimalPart.component_responses``): the normals then enter by sums only, no solve."""
        om2 = problem.omega2
        self.problem = problem
        components = om2.component_responses() if hasattr(om2, "component_responses") else None
        self.components = components
        self._nu = None  # the normals the per-component pieces are combined with
        if components is None:
            self.Yc, self._Sc, self._Yq, self._Sq = om2.responses(contact=True, chunk=problem.options.chunk)
        else:
            self.Yc = components[0]
        kept = previous is not None and previous.problem is problem and previous.Yc is self.Yc
        # the data at the other values stay zero (``unknowns`` of the same Ω₁ response and Yc: the previous ones)
        f = self.f = previous.f if kept else problem.unknowns(self.Yc)
        a, b, eye = problem.a[f], problem.b, np.eye(f.size)
        same = (
            previous is not None
            and np.array_equal(previous.f, f)
            and (previous.Yc is self.Yc or np.array_equal(previous.Yc, self.Yc))
        )
        if same:  # K = I − P₁P₂ depends on Ω₁ and Yc only (not on the normals)
            self.P1, self.lu = previous.P1, previous.lu
        else:
            self.P1 = a[:, None] * problem.omega1.T[np.ix_(f, f)] + b * eye
            P2 = a[:, None] * self.Yc[np.ix_(f, f)] + b * eye
            self.lu = sla.lu_factor(eye - self.P1 @ P2)
        if components is None:
            self._Gq = self._data_response(self.Yq)  # ∂g₂₁/∂λ = −Gq
            self.M = self.Sq + self.Sc @ self.Gq
        else:
            self._combine(components, previous if same and previous.components is components else None)
        self._chains = previous._chains if same else None  # the contact points stay
        #: the contact Newton's first set: the active set of the last solve of ``previous`` (a load path's last
        #: step, the obstacle moved), else None ({s_L > 0}); ``last``: this condensation's last active set
        start = getattr(previous, "last", None)
        self.start = start if start is not None and start.size == self.D.size else None
        self.last = None
        self._load = None  # (t₁, y₂₀, g₂₁ at λ = 0, its contact values): ``load_terms``
        self._factors: dict = {}  # the contact Newton's LU factors of its last set (a warm start's first set)
        if problem.options.front_window:
            self.chains  # noqa: B018 -- formed offline (collective: all ranks' points), not in the timed solve

    def _data_response(self, Yq: np.ndarray) -> np.ndarray:
        """K⁻¹ P₁ (a ⊙ Yq) on the free data values (zero elsewhere)."""
        p, f = self.problem, self.f
        G = np.zeros((p.a.size, Yq.shape[1]))
        G[f] = sla.lu_solve(self.lu, self.P1 @ (p.a[f][:, None] * Yq[f]))
        return G

    def _combine(self, components: tuple, previous: "CondensedInterface | None") -> None:
        """Sc and M for the current normals ν from the per-component pieces: with Yq = Σ_k Yq_k diag(ν_k),
        Gq = Σ_k G_k diag(ν_k) (G_k = K⁻¹P₁(a ⊙ Yq_k)) and M = Σ_kl diag(ν_k) (Sq_kl + Sc_k G_l) diag(ν_l); G_k and
        M_kl are formed once per J₀ (kept from ``previous``); Yq, Sq and Gq only when asked (``times``: their
        products with λ from the pieces; Sc too, its products with the data ``contact_of``).  M is summed in place,
        one column block diag(ν_k) M_kl at a time (no temporary per term)."""
        _, Sc, Yq, Sq = components
        if previous is not None:
            self._G, self._M = previous._G, previous._M
        else:
            self._G = [self._data_response(y) for y in Yq]
            self._M = [[Sq[k][l] + Sc[k] @ self._G[l] for l in range(len(Yq))] for k in range(len(Yq))]
        nu = self._nu = self.problem.omega2.contact_normals()
        bs = nu.shape[1]
        self._Yq = self._Sq = self._Gq = self._Sc = None
        n = nu.shape[0]
        self.M, col, work = np.zeros((n, n)), np.empty((n, n)), np.empty((n, n))
        for l in range(bs):  # M += (Σ_k diag(ν_k) M_kl) diag(ν_l)
            np.multiply(self._M[0][l], nu[:, 0, None], out=col)
            for k in range(1, bs):
                col += np.multiply(self._M[k][l], nu[:, k, None], out=work)
            col *= nu[None, :, l]
            self.M += col

    def _by_normals(self, pieces: list) -> np.ndarray:
        """Σ_k pieces[k] diag(ν_k)."""
        return sum(pieces[k] * self._nu[None, :, k] for k in range(self._nu.shape[1]))

    @property
    def Sc(self) -> np.ndarray:
        """Q J₀⁻¹C: the contact values of the data columns."""
        if self._Sc is None:
            pieces = self.components[1]
            self._Sc = sum(self._nu[:, k, None] * pieces[k] for k in range(self._nu.shape[1]))
        return self._Sc

    def contact_of(self, g: np.ndarray) -> np.ndarray:
        """Sc g: by the per-component pieces, Σ_k ν_k ⊙ (Sc_k g), when they are held and Sc was not formed."""
        if self._nu is None or self._Sc is not None:
            return self.Sc @ g
        pieces = self.components[1]
        return sum(self._nu[:, k] * (pieces[k] @ g) for k in range(self._nu.shape[1]))

    @property
    def Yq(self) -> np.ndarray:
        """N J₀⁻¹Qᵀ: the traces on γ of the contact columns."""
        if self._Yq is None:
            self._Yq = self._by_normals(self.components[2])
        return self._Yq

    @property
    def Gq(self) -> np.ndarray:
        """K⁻¹P₁(a ⊙ Yq): ∂g₂₁/∂λ = −Gq."""
        if self._Gq is None:
            self._Gq = self._by_normals(self._G)
        return self._Gq

    @property
    def Sq(self) -> np.ndarray:
        """Q J₀⁻¹Qᵀ: the contact values of the contact columns."""
        if self._Sq is None:
            nu = self._nu
            self._Sq = sum(
                nu[:, k, None] * self.components[3][k][l] * nu[None, :, l]
                for k in range(nu.shape[1])
                for l in range(nu.shape[1])
            )
        return self._Sq

    def form_products(self) -> None:
        """Gq and Yq formed from the per-component pieces (a later solve on the same normals, a load path whose
        obstacle does not turn them): every solve after takes ``times`` as one product each instead of one per
        component (forming costs about as much as two solves' products)."""
        if self._nu is not None:
            self.Gq, self.Yq  # noqa: B018 -- (kept by the properties)

    def times(self, name: str, lam: np.ndarray) -> np.ndarray:
        """``name`` ("Yq" or "Gq") times λ: by the per-component pieces, Σ_k X_k (ν_k ⊙ λ), when they are held and
        the product was not formed."""
        if self._nu is None or getattr(self, f"_{name}") is not None:
            return getattr(self, name) @ lam
        pieces = self.components[2] if name == "Yq" else self._G
        return sum(pieces[k] @ (self._nu[:, k] * lam) for k in range(self._nu.shape[1]))

    def load_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Online: (s_L, g₂₁ at λ = 0, y₂₀) from one Ω₂ back-solve and the Ω₁ load response.  g₂₁ at λ = 0 and its
        contact values Sc g₂₁ are kept while both load responses are (a load path that moves the obstacle without
        turning its normals changes only the gap in s₀₀): the dense solve and product are then not repeated."""
        p, f = self.problem, self.f
        t1 = p.omega1.load()
        y20, s00 = p.omega2.load_response()
        kept = self._load
        if kept is None or not (np.array_equal(kept[0], t1) and np.array_equal(kept[1], y20)):
            g21 = np.zeros(p.a.size)
            g21[f] = sla.lu_solve(self.lu, self.P1 @ (p.a[f] * y20[f]) + p.a[f] * t1[f])
            g21.flags.writeable = False
            self._load = kept = (np.array(t1, copy=True), np.array(y20, copy=True), g21, self.contact_of(g21))
        return s00 + kept[3], kept[2], y20

    def jacobian(self, active: np.ndarray) -> np.ndarray:
        """∂y₂/∂g₂₁ for the Ω₂ active set (Woodbury on J₀: no factorization)."""
        A = np.flatnonzero(active)
        if A.size == 0:
            return self.Yc
        DA = self.D[A]
        S = np.eye(A.size) + self.Sq[np.ix_(A, A)] * DA[None, :]
        return self.Yc - (self.Yq[:, A] * DA[None, :]) @ np.linalg.solve(S, self.Sc[A])

    @property
    def D(self) -> np.ndarray:
        return self.problem.omega2.D

    @property
    def chains(self) -> list:
        """The Γ_C unknowns ordered along the boundary (``contact_chains``; the local front resolution's), built on
        first use (collective: the contact points are gathered from all ranks)."""
        if self._chains is None:
            self._chains = contact_chains(self.problem.omega2.contact_points()) if self.M.size else []
        return self._chains

    def lowest_eigenvalue(self) -> float:
        """Smallest eigenvalue of ½(M + Mᵀ): > 0 when the glued problem is an elastic (positive definite) one.

        Always so with a fine Ω₁ (M is then the symmetric compliance of the monolithic problem on Γ_C); a
        multiscale Ω₁ whose interface response is not a Robin map of an elastic body can make it negative.
        """
        if not self.M.size:
            return np.inf
        return float(np.linalg.eigvalsh(0.5 * (self.M + self.M.T))[0])

    def solve(
        self, options: InterfaceNewtonOptions, name: str, *, warm: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, "ContactNewtonHistory"]:
        """Contact Newton, then (g₁₂, g₂₁, λ) global.  ``warm`` (a load step warm-started from the last one): the
        contact Newton starts from the active set of this condensation's last solve, where there is one (a load
        step moves the contact set by a few rows, so the last set is mostly the new one: fewer dense solves than
        from {s_L > 0}); otherwise from ``start``."""
        p = self.problem
        s_load, g21_0, y20 = self.load_terms()
        start = self.last if warm and self.last is not None else self.start
        if self.last is not None:
            self.form_products()
        try:
            chains = self.chains if options.front_window else None
            _, lam, hist = contact_solve(s_load, self.M, self.D, options, name, chains, start, self._factors)
        except ConvergenceError as err:
            lowest = self.lowest_eigenvalue()
            if lowest < 0.0:
                raise ConvergenceError(
                    f"{name}: the glued problem is not positive definite (the symmetric part of its condensed "
                    f"contact compliance has the eigenvalue {lowest:.2e} < 0), so its contact problem need not "
                    "have a solution: Ω₁'s interface response is not that of an elastic body at this transmission "
                    "coefficient (a multiscale Ω₁ whose approximation error the Robin coefficient amplifies). Use a "
                    "smaller α or β (Algorithm 3's default alpha='Emin*h^-1/2'), or more oversampling layers"
                ) from err
            raise
        self.last = lam > 0.0
        g21 = g21_0 - self.times("Gq", lam)
        y2 = y20 + self.Yc @ g21 - self.times("Yq", lam)
        g12 = np.where(p.free, p.a * y2 + p.b * g21, 0.0)
        return g12, g21, lam, hist
