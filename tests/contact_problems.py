"""Contact problems of the contact-Newton tests (``test_interface_newton_local``): random condensed ones, the strip."""

import numpy as np
import pytest

from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.primal import default_penalty
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, PrimalHybridStep
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model


def random_contact_problem(rng: np.random.Generator, n: int = 80):
    """(s_L, M, D, points): a line of n nodes, M the compliance of an elastic string on a foundation with stiff
    stretches (near-rigid punches) on a stiffer foundation (SPD), a penalty 1e3–1e9 times stiffer, a load pushing in
    and pulling out; the unknowns in a random order (the chains come from the coordinates)."""
    x = np.linspace(0.0, 1.0, n)
    stiff, ground = np.ones(n - 1), np.ones(n)
    for _ in range(rng.integers(1, 4)):
        a, width, c = rng.integers(0, n - 8), rng.integers(3, 8), 10.0 ** rng.uniform(2, 6)
        stiff[a : a + width] = c
        ground[a : a + width + 1] = 10.0 ** rng.uniform(1, 3)
    K = np.diag(np.r_[stiff, 0.0] + np.r_[0.0, stiff]) - np.diag(stiff, 1) - np.diag(stiff, -1)
    K = K * (n - 1) + np.diag(ground) / (n - 1)  # string + foundation: SPD
    M = np.linalg.inv(K)
    s_load = M @ np.sin(rng.uniform(2, 12) * x + rng.uniform(0, 6)) * rng.uniform(0.5, 2)
    D = np.full(n, 10.0 ** rng.uniform(3, 9)) * np.r_[0.5, np.ones(n - 2), 0.5]
    perm = rng.permutation(n)
    return s_load[perm], M[np.ix_(perm, perm)], D[perm], np.c_[x, np.zeros(n)][perm]


@pytest.fixture(scope="module")
def channel_strip():
    """Algorithm 1 on model 3 at contrast 1e6, h = 1/128, H = 1/16 (1.6 s): the stiff channel at y ∈ [5/32, 6/32]
    has five Γ_C nodes, and the plain contact Newton frees them one per step (h ≤ 1/64: at most three)."""
    cm = unit_square(128, 16)
    step = PrimalHybridStep(
        get_model(3, E_high=1e6).on(cm),
        alpha=DEFAULT_ALPHA,
        delta=default_penalty(cm.h, 1e6),
        newton=NewtonOptions(rtol=1e-6),
    )
    step.prepare()
    return step
