"""The Γ_C unknowns ordered along the boundary (``hybrid.fronts.contact_chains``, the chains of the local front
resolution): shuffled points of a bent boundary with a copied corner vertex come back in boundary order with
their arc lengths; a separate piece is its own chain; a piece that is not a curve is left out.  (The local
front resolution itself: ``test_interface_newton_local.py``.)
"""

import numpy as np

from fenics_contact.hybrid.fronts import contact_chains


def test_contact_chains_orders_points_along_the_boundary():
    rng = np.random.default_rng(0)
    # an L: up the side x = 1 (y = 0 … 1, uneven spacing), its corner vertex copied, then along y = 1 leftwards
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.1, 12))])
    side = np.c_[np.ones_like(ys), ys]
    top = np.c_[1.0 - np.cumsum(np.full(6, 0.07)), np.full(6, ys[-1])]
    bent = np.vstack([side, side[-1:], top])
    # a separate piece far away, and a "piece" with a branch (a node with three neighbours)
    far = np.c_[np.full(5, 5.0), np.linspace(0.0, 0.3, 5)]
    branch = np.array([[9.0, 0.0], [9.0, 0.07], [9.0, 0.14], [9.07, 0.07], [8.93, 0.07]])
    points = np.vstack([bent, far, branch])
    perm = rng.permutation(len(points))
    chains = contact_chains(points[perm])
    assert len(chains) == 2  # the branch is left out
    arcs = {}
    for idx, pos in chains:
        original = perm[idx]
        if original[0] > original[-1]:
            original, pos = original[::-1], pos[-1] - pos[::-1]
        arcs[len(original)] = (original, pos)
    order, pos = arcs[len(bent)]
    assert np.array_equal(order[: len(side) - 1], np.arange(len(side) - 1))  # up the side, the corner's two copies
    assert set(order[len(side) - 1 : len(side) + 1]) == {len(side) - 1, len(side)}
    assert np.array_equal(order[-6:], np.arange(len(side) + 1, len(bent)))
    steps = np.linalg.norm(np.diff(bent[order], axis=0), axis=1)
    assert np.allclose(np.diff(pos), steps) and pos[0] == 0.0
    assert np.array_equal(arcs[len(far)][0], np.arange(len(bent), len(bent) + len(far)))
    assert contact_chains(points[:2]) == [] and contact_chains(np.zeros((4, 2))) == []
