"""kdsl.testing."""
