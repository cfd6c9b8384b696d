"""kdsl.runtime."""
