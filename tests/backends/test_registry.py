"""Backend discovery through entry points: laziness, duplicates, broken plugins."""

import importlib.metadata
import subprocess
import sys
import types

import pytest

from kdsl.backends import registry
from kdsl.backends.base import Backend, CompiledKernel
from kdsl.backends.registry import (
    BackendRegistryError,
    available_backends,
    get_backend,
    load_failures,
    register_backend,
)

EP = importlib.metadata.EntryPoint
INTERP = EP("interp", "kdsl.backends.interp:BACKEND", "kdsl.backends")


class FakeBackend(Backend):
    name = "fake"
    version = "7"
    capabilities = frozenset({"fp64"})

    def devices(self):
        return ["cpu"]

    def load(self, job):
        return CompiledKernel(self.name, job.symbol, job.module)

    def launch(self, compiled, dims, args, stream=None):
        pass


@pytest.fixture
def entry_points(monkeypatch):
    """Replace the installed entry points with a list the test controls."""
    eps: list = []

    def fake(group=None):
        assert group == "kdsl.backends"
        return list(eps)

    monkeypatch.setattr(importlib.metadata, "entry_points", fake)
    # The source-checkout fallback would add cpu/interp; these tests own the list.
    monkeypatch.setattr(registry, "BUILTIN_BACKENDS", {})
    registry.reset_registry()
    yield eps
    registry.reset_registry()


@pytest.fixture
def fake_module(monkeypatch):
    mod = types.ModuleType("fake_kdsl_plugin")
    mod.BACKEND = FakeBackend()
    mod.Cls = FakeBackend
    mod.NOT_A_BACKEND = 42
    monkeypatch.setitem(sys.modules, "fake_kdsl_plugin", mod)
    return mod


def test_installed_interp_is_discovered():
    registry.reset_registry()
    assert "interp" in available_backends()
    assert get_backend("interp").name == "interp"


def test_plugin_instance_and_class_load(entry_points, fake_module):
    entry_points.append(EP("fake", "fake_kdsl_plugin:BACKEND", "kdsl.backends"))
    assert get_backend("fake") is fake_module.BACKEND
    registry.reset_registry()
    entry_points[:] = [EP("fake", "fake_kdsl_plugin:Cls", "kdsl.backends")]
    assert isinstance(get_backend("fake"), FakeBackend)


def test_broken_plugin_warns_and_is_listed(entry_points, fake_module):
    entry_points += [INTERP, EP("broken", "no_such_module_kdsl:BACKEND", "kdsl.backends")]
    with pytest.warns(RuntimeWarning, match=r"plugin 'broken' \(no_such_module_kdsl:BACKEND\)"):
        names = available_backends()
    assert names == ["interp"]
    assert "ModuleNotFoundError" in load_failures()["broken"]
    with pytest.raises(BackendRegistryError, match="'broken' failed to load"):
        get_backend("broken")


def test_plugin_that_is_not_a_backend_is_a_failure(entry_points, fake_module):
    entry_points.append(EP("odd", "fake_kdsl_plugin:NOT_A_BACKEND", "kdsl.backends"))
    with pytest.warns(RuntimeWarning, match="not a kdsl Backend"):
        assert available_backends() == []
    assert "odd" in load_failures()


def test_plugin_name_must_match_entry_point(entry_points, fake_module):
    entry_points.append(EP("other", "fake_kdsl_plugin:BACKEND", "kdsl.backends"))
    with pytest.warns(RuntimeWarning, match="names itself 'fake'"):
        assert available_backends() == []


def test_duplicate_entry_points_name_both_sources(entry_points):
    entry_points += [INTERP, EP("interp", "other_pkg.backend:BACKEND", "kdsl.backends")]
    with pytest.raises(BackendRegistryError) as info:
        get_backend("interp")
    msg = str(info.value)
    assert "kdsl.backends.interp:BACKEND" in msg and "other_pkg.backend:BACKEND" in msg
    with pytest.raises(BackendRegistryError):  # still an error on the next use
        available_backends()


def test_same_entry_point_twice_is_not_a_clash(entry_points):
    entry_points += [INTERP, INTERP]
    assert available_backends() == ["interp"]


def test_register_backend_and_duplicates(entry_points, fake_module):
    entry_points.append(INTERP)
    b = FakeBackend()
    assert register_backend(b) is b
    assert get_backend("fake") is b
    assert register_backend(b) is b  # registering the same object again is harmless
    with pytest.raises(BackendRegistryError, match="two kdsl backends are named 'fake'"):
        register_backend(FakeBackend())
    dup = FakeBackend()
    dup.name = "interp"
    with pytest.raises(BackendRegistryError, match=r"kdsl\.backends\.interp:BACKEND"):
        register_backend(dup)
    with pytest.raises(TypeError):
        register_backend(object())


def test_unknown_backend_lists_known_ones(entry_points):
    entry_points.append(INTERP)
    with pytest.raises(BackendRegistryError, match=r"no kdsl backend is named 'nope'.*'interp'"):
        get_backend("nope")


def test_import_kdsl_imports_no_backend():
    # base, registry and facts are the backend-neutral modules the compiler uses
    # (facts: the store of toolchain facts the compiler registers, no toolchain import).
    code = (
        "import sys, kdsl; "
        "bad = [m for m in sys.modules if m.startswith('kdsl.backends.') and "
        "m not in ('kdsl.backends.base', 'kdsl.backends.registry', 'kdsl.backends.facts')]; "
        "assert not bad, bad; assert 'llvmlite' not in sys.modules; assert 'cupy' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_default_pipeline_is_the_standard_one():
    from kdsl import passes

    assert FakeBackend().pipeline == passes.DEFAULT_PIPELINE


def test_builtins_found_without_installed_metadata(monkeypatch):
    """A source checkout on PYTHONPATH has no entry points; built-ins still load."""
    import importlib.metadata

    from kdsl.backends import registry

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: [])
    registry.reset_registry()
    try:
        assert {"cpu", "interp"} <= set(registry.available_backends())
        assert registry.get_backend("interp").name == "interp"
    finally:
        monkeypatch.undo()
        registry.reset_registry()
