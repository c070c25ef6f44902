"""CEM-GMsFEM in Ω₁ (primal and mixed), the offline cache, and Algorithms 3 and 4."""
