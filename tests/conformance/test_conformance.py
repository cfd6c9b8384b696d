"""Runs the packaged conformance suite (kdsl/testing) on every registered backend."""

from kdsl.testing.test_conformance import pytest_generate_tests, test_case

__all__ = ["pytest_generate_tests", "test_case"]
