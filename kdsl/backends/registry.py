"""Backend discovery and lookup.

Backends come from the ``kdsl.backends`` entry-point group: the name is the
backend's name, the value points at a ``Backend`` instance (or a subclass, which
is instantiated). Built-ins are listed in kdsl's own ``pyproject.toml`` the same
way. Discovery is lazy: the entry points are read on first use, and each backend
module is imported only when that backend is asked for, so ``import kdsl``
imports no backend.

A plugin that fails to load is reported with ``warnings.warn`` and listed in
``load_failures()``; two plugins with one name are an error naming both.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from kdsl.backends.base import Backend
from kdsl.errors import KdslError

GROUP = "kdsl.backends"

#: kdsl's own backends, as pyproject.toml declares them. Used only for names the
#: entry points lack: running from a source checkout that was never pip-installed
#: (``PYTHONPATH=.``) has no entry-point metadata, and must still find them.
BUILTIN_BACKENDS = {
    "cpu": "kdsl.backends.cpu:BACKEND",
    "cuda": "kdsl.backends.cuda:BACKEND",
    "interp": "kdsl.backends.interp:BACKEND",
}


class BackendRegistryError(KdslError):
    """Two backends claim one name, or a name is not a registered backend."""


class _Registry:
    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.discovered = False
        self.pending: dict[str, Any] = {}  # name -> entry point not loaded yet
        self.sources: dict[str, str] = {}  # name -> where it came from
        self.loaded: dict[str, Backend] = {}
        self.failures: dict[str, str] = {}

    def discover(self) -> None:
        if self.discovered:
            return
        import importlib.metadata  # here, not at the top: it is slow to import

        self.discovered = True
        for ep in importlib.metadata.entry_points(group=GROUP):
            source = f"entry point {ep.name} = {ep.value}"
            if ep.name in self.sources:
                if self.sources[ep.name] == source:
                    continue  # the same distribution seen twice on sys.path
                first = self.sources[ep.name]
                self.discovered = False  # so every later use reports the clash too
                self.reset_pending()
                raise BackendRegistryError(
                    f"two kdsl backends are named {ep.name!r}: {first} "
                    f"and {source}; uninstall one of them"
                )
            self.sources[ep.name] = source
            self.pending[ep.name] = ep
        for name, value in BUILTIN_BACKENDS.items():
            if name not in self.sources:
                self.sources[name] = f"built-in {value} (kdsl is not pip-installed)"
                self.pending[name] = importlib.metadata.EntryPoint(name, value, GROUP)

    def reset_pending(self) -> None:
        self.pending.clear()
        self.sources = {n: s for n, s in self.sources.items() if n in self.loaded}

    def load(self, name: str) -> Backend | None:
        if name in self.loaded:
            return self.loaded[name]
        if not self.discovered and name in BUILTIN_BACKENDS and name not in self.failures:
            # A built-in loads without reading every installed distribution's metadata
            # (importing importlib.metadata and scanning costs tens of milliseconds, a
            # large part of a warm start). A plugin clashing with its name is still
            # reported, by the first full discovery (listing backends, an unknown name).
            value = BUILTIN_BACKENDS[name]
            self.sources.setdefault(name, f"entry point {name} = {value}")
            return self._instantiate(name, value, lambda: _load_reference(value))
        self.discover()
        if name in self.loaded:
            return self.loaded[name]
        ep = self.pending.pop(name, None)
        if ep is None:
            return None
        return self._instantiate(name, ep.value, ep.load)

    def _instantiate(self, name: str, value: str, load: Any) -> Backend | None:
        """The backend ``load()`` gives, checked and recorded; None (and a warning) on failure."""
        try:
            obj = load()
            backend = obj() if isinstance(obj, type) and issubclass(obj, Backend) else obj
            if not isinstance(backend, Backend):
                raise TypeError(f"{value} is a {type(obj).__name__}, not a kdsl Backend")
            if backend.name != name:
                raise ValueError(f"it is registered as {name!r} but names itself {backend.name!r}")
        except Exception as e:  # any plugin bug must not take kdsl down
            msg = f"{type(e).__name__}: {e}"
            self.failures[name] = msg
            warnings.warn(
                f"kdsl backend plugin {name!r} ({value}) failed to load: {msg}",
                RuntimeWarning,
                stacklevel=4,
            )
            return None
        self.loaded[name] = backend
        return backend


_REGISTRY = _Registry()


def register_backend(backend: Backend, source: str | None = None) -> Backend:
    """Register ``backend`` by its ``name``; a name already taken is an error."""
    if not isinstance(backend, Backend):
        raise TypeError(f"register_backend expects a kdsl Backend, got {type(backend).__name__}")
    _REGISTRY.discover()
    name = backend.name
    if _REGISTRY.loaded.get(name) is backend:
        return backend
    if name in _REGISTRY.sources:
        raise BackendRegistryError(
            f"two kdsl backends are named {name!r}: {_REGISTRY.sources[name]} and "
            f"{source or _describe(backend)}"
        )
    _REGISTRY.sources[name] = source or _describe(backend)
    _REGISTRY.loaded[name] = backend
    return backend


def unregister_backend(name: str) -> None:
    """Forget the backend ``name`` (for tests and plugin reloads)."""
    _REGISTRY.discover()
    _REGISTRY.loaded.pop(name, None)
    _REGISTRY.pending.pop(name, None)
    _REGISTRY.sources.pop(name, None)


def get_backend(name: str) -> Backend:
    """The backend registered as ``name``; raises ``BackendRegistryError`` if none loads."""
    backend = _REGISTRY.load(name)
    if backend is not None:
        return backend
    if name in _REGISTRY.failures:
        raise BackendRegistryError(
            f"kdsl backend {name!r} failed to load: {_REGISTRY.failures[name]}"
        )
    known = ", ".join(repr(n) for n in sorted(_REGISTRY.sources)) or "none"
    raise BackendRegistryError(f"no kdsl backend is named {name!r} (registered: {known})")


def is_registered(name: str) -> bool:
    """True when some backend claims ``name`` (without importing it)."""
    if not _REGISTRY.discovered and name in BUILTIN_BACKENDS:
        return name not in _REGISTRY.failures
    _REGISTRY.discover()
    return name in _REGISTRY.sources and name not in _REGISTRY.failures


def available_backends() -> list[str]:
    """Names of the backends that load, sorted. Loads every discovered plugin."""
    _REGISTRY.discover()
    for name in list(_REGISTRY.pending):
        _REGISTRY.load(name)
    return sorted(_REGISTRY.loaded)


def load_failures() -> dict[str, str]:
    """Plugins that failed to load: name -> error message."""
    return dict(_REGISTRY.failures)


def reset_registry() -> None:
    """Forget everything and rediscover on next use (for tests)."""
    _REGISTRY.reset()


def _load_reference(value: str) -> Any:
    """The object an entry-point value ``"package.module:attr"`` names."""
    module, _, attr = value.partition(":")
    obj: Any = importlib.import_module(module)
    for part in filter(None, attr.split(".")):
        obj = getattr(obj, part)
    return obj


def _describe(backend: Backend) -> str:
    cls = type(backend)
    return f"register_backend({cls.__module__}.{cls.__qualname__})"
