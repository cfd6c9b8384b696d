"""kdsl.passes."""
