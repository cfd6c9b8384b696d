"""kdsl.frontend."""
