"""Finite elements: pure UFL forms, the Arnold–Winther space, semismooth Newton, primal and mixed subproblems."""
