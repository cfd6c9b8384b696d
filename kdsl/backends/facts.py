"""Facts about a backend's toolchain that are slow to learn, kept across processes.

Some facts cost a backend more than the cache hit they serve: asking NVRTC its
version and architectures loads ``libnvrtc`` (160-300 ms), yet a kernel whose cubin
is in the cache needs only the answer. A backend names such a fact after what
decides it (a fingerprint of the library file) and asks ``stored_fact`` for it; the
compiler, which owns the kernel cache, registers the store once
(``register_fact_store``), so a fact is learnt once per toolchain, not per process.
Without a store (the backends used alone) the fact is learnt every time.
"""

from __future__ import annotations

from collections.abc import Callable

#: ``store(name, learn)``: the bytes stored under ``name``, learnt by ``learn()`` once.
FactStore = Callable[[str, Callable[[], bytes]], bytes]

_store: list[FactStore] = []


def register_fact_store(store: FactStore) -> None:
    """Make ``store`` the place facts are kept (the compiler's kernel cache)."""
    _store[:] = [store]


def stored_fact(name: str, learn: Callable[[], bytes]) -> bytes:
    """The fact ``name``: from the store when one is registered, else ``learn()``.

    ``name`` must change whenever the answer may (name it after a fingerprint of
    what decides it), since a stored fact is never learnt again.
    """
    return _store[0](name, learn) if _store else learn()
