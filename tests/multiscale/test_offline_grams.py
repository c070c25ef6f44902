"""The primal CEM offline cache stores the Gram matrices ZᵀKZ, ZᵀMZ of Z = [Ψ, N, N_f] with the bases.

A run on cached data takes them from the file: they equal those of the built run bit for bit (ZᵀMZ also the
products of the loaded bases formed again, ``cem.gram_matrices``, bit for bit; ZᵀKZ, which the build takes from
the patch equations, those products to round-off), and the online solves of the built and the loaded Ω₁ agree
bit for bit.  The cache key changes with the cache format (a file of another layout is never read).
"""

import numpy as np

from fenics_contact.multiscale import cem
from fenics_contact.multiscale.cem import cache as cem_cache
from fenics_contact.problem import models
from fenics_contact.problem.geometry import unit_square


def test_cached_gram_matrices_are_those_of_the_bases(tmp_path, monkeypatch):
    cm = unit_square(16, 4)
    problem = models.get_model(3).on(cm)
    options = cem.CEMOptions(layers=1, nbasis=2)

    def build():
        return cem.build_omega1_multiscale(problem, cem=options, cache_dir=tmp_path)[0]

    built, loaded = build(), build()
    assert (built.cache_status, loaded.cache_status) == ("built", "loaded")
    assert loaded.space.grams is not None
    assert np.array_equal(loaded.solver.GK, built.solver.GK) and np.array_equal(loaded.solver.GM, built.solver.GM)
    GK, GM = cem.gram_matrices(loaded.ops, loaded.grid, loaded.space)  # (a loaded space: products of the bases)
    assert np.array_equal(loaded.solver.GM, GM)
    assert np.max(np.abs(loaded.solver.GK - GK)) < 1e-12 * np.max(np.abs(GK))
    g = np.linspace(-1.0, 1.0, built.ops.gamma.size)
    assert np.array_equal(built.solver.solve(g), loaded.solver.solve(g))
    key = cem.offline_key(built.ops, built.grid, options, h=cm.h)
    monkeypatch.setattr(cem_cache, "CACHE_FORMAT", cem.CACHE_FORMAT + 1)
    assert cem.offline_key(built.ops, built.grid, options, h=cm.h) != key
