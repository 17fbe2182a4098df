"""The forward model: one vertex, boundary data, the marching as CasADi graphs and in plain
NumPy, the pattern and its folded states, side lengths."""
