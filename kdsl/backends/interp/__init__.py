"""kdsl.backends/interp."""
