"""The hybrid iteration: interface bookkeeping, the shared loop and its updates (plain, Anderson, interface
Newton), the convergence certificate, Algorithms 1 and 2."""
