"""kdsl.backends."""
