"""The hybrid iteration: interface bookkeeping, the shared loop and its updates, Algorithms 1 and 2."""
