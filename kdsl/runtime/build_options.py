"""Warp's option types and mode enums: ``ModuleBuildOptions``, ``DeterministicMode``,
``JaxModulePreloadMode`` and the ``DeviceLike`` annotation.

What each one does in kdsl (docs/runtime.md, "Build options and modes"):

- ``ModuleBuildOptions`` is the value of the ``extra_build_options`` module option.
  ``extra_build_dependencies`` is honoured: the files' contents are hashed into the
  module's compile options, so editing one rebuilds the module's kernels (as in Warp).
  Include directories and preambles are C++ text for Warp's C++/CUDA builds; kdsl's
  cpu backend emits LLVM IR and its cuda backend generates all of its CUDA C from the
  IR, so setting non-empty ones is refused (``KdslCapabilityError``) rather than
  ignored.
- ``DeterministicMode`` names Warp's ``deterministic`` module option values. kdsl has
  no ordered-atomics mode (Warp records atomic contributions and reduces them in a
  fixed order): float atomics on the cpu (threads) and cuda backends may sum in any
  order. So ``NOT_GUARANTEED`` (or None, False) is accepted and anything stronger
  raises ``WarpDeterminismError`` (``KdslDeterminismError``) when set, as Warp raises
  it where it cannot provide the guarantee. (The interp backend runs threads in order
  and is deterministic.)
- ``JaxModulePreloadMode``: kdsl's ``jax_kernel``/``jax_callable`` always preload
  on every local JAX device (``ALL_DEVICES``).
"""

from __future__ import annotations

import enum
import hashlib
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kdsl.errors import (
    KdslCapabilityError,
    KdslDeterminismError,
    KdslTypeError,
    KdslValueError,
)
from kdsl.runtime.device import Device

#: What Warp accepts where it takes a device: a ``Device``, a name ("cpu", "cuda:0") or None.
DeviceLike = Device | str | None


class DeterministicMode(enum.IntEnum):
    """Warp's deterministic execution modes for atomics (``deterministic`` module option)."""

    NOT_GUARANTEED = 0
    """Atomics in whatever order the hardware runs them."""
    RUN_TO_RUN = 1
    """Bit-exact results from run to run on the same device."""
    GPU_TO_GPU = 2
    """Bit-exact results across GPU architectures."""


class JaxModulePreloadMode(enum.IntEnum):
    """When a JAX-wrapped kernel's module is compiled (kdsl always uses ``ALL_DEVICES``)."""

    NONE = 0
    CURRENT_DEVICE = 1
    ALL_DEVICES = 2


def _paths(what: str, values: Sequence[str | os.PathLike[str]] | None, kind: str) -> list[Path]:
    if values is None:
        return []
    if isinstance(values, str | os.PathLike):
        raise KdslTypeError(f"ModuleBuildOptions: {what} takes a list of paths, not one path")
    out = []
    for v in values:
        p = Path(v)
        if not p.is_absolute():
            raise KdslValueError(f"ModuleBuildOptions: {what} entries must be absolute, not {v}")
        ok = p.is_dir() if kind == "directory" else p.is_file()
        if not ok:
            raise KdslValueError(f"ModuleBuildOptions: {what}: {v} is not an existing {kind}")
        out.append(p)
    return out


class ModuleBuildOptions:
    """Extra build options of a module (``set_module_options({"extra_build_options": o})``).

    Checked as Warp checks them: paths absolute and existing, preambles strings.
    """

    def __init__(
        self,
        *,
        extra_cuda_include_dirs: Sequence[str | os.PathLike[str]] | None = None,
        extra_cpu_include_dirs: Sequence[str | os.PathLike[str]] | None = None,
        extra_cuda_preamble: str = "",
        extra_cpu_preamble: str = "",
        extra_build_dependencies: Sequence[str | os.PathLike[str]] | None = None,
    ) -> None:
        for name, text in (("extra_cuda_preamble", extra_cuda_preamble),
                           ("extra_cpu_preamble", extra_cpu_preamble)):  # fmt: skip
            if not isinstance(text, str):
                raise KdslTypeError(f"ModuleBuildOptions: {name} must be a str, "
                                    f"not {type(text).__name__}")  # fmt: skip
        self.extra_cuda_include_dirs = _paths("extra_cuda_include_dirs", extra_cuda_include_dirs,
                                              "directory")  # fmt: skip
        self.extra_cpu_include_dirs = _paths("extra_cpu_include_dirs", extra_cpu_include_dirs,
                                             "directory")  # fmt: skip
        self.extra_cuda_preamble = extra_cuda_preamble
        self.extra_cpu_preamble = extra_cpu_preamble
        self.extra_build_dependencies = _paths("extra_build_dependencies",
                                               extra_build_dependencies, "file")  # fmt: skip

    def merged(self, other: ModuleBuildOptions) -> ModuleBuildOptions:
        """A new options object: lists concatenated (``self`` first), preambles joined."""
        if not isinstance(other, ModuleBuildOptions):
            raise KdslTypeError(f"ModuleBuildOptions.merged takes ModuleBuildOptions, "
                                f"not {type(other).__name__}")  # fmt: skip

        def join(a: str, b: str) -> str:
            return a + ("\n" if a and b else "") + b

        return ModuleBuildOptions(
            extra_cuda_include_dirs=self.extra_cuda_include_dirs + other.extra_cuda_include_dirs,
            extra_cpu_include_dirs=self.extra_cpu_include_dirs + other.extra_cpu_include_dirs,
            extra_cuda_preamble=join(self.extra_cuda_preamble, other.extra_cuda_preamble),
            extra_cpu_preamble=join(self.extra_cpu_preamble, other.extra_cpu_preamble),
            extra_build_dependencies=self.extra_build_dependencies + other.extra_build_dependencies,
        )

    def native_code(self) -> list[str]:
        """The options set that would inject C++ text into a native build (named)."""
        return [k for k in ("extra_cuda_include_dirs", "extra_cpu_include_dirs",
                            "extra_cuda_preamble", "extra_cpu_preamble") if getattr(self, k)]  # fmt: skip

    def dependency_digest(self) -> str:
        """sha256 over the contents of ``extra_build_dependencies`` (read now)."""
        h = hashlib.sha256()
        for p in self.extra_build_dependencies:
            h.update(str(p).encode() + b"\0")
            try:
                h.update(p.read_bytes())
            except OSError as e:
                raise KdslValueError(
                    f"ModuleBuildOptions: cannot read build dependency {p}: {e}"
                ) from None
            h.update(b"\0")
        return h.hexdigest()

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in vars(self).items() if v)
        return f"ModuleBuildOptions({fields})"


def check_build_options(options: Any) -> None:
    """Check the ``extra_build_options`` module option: None or a ``ModuleBuildOptions``
    without C++ text, which kdsl has no place for (its cpu backend emits LLVM IR, its
    cuda backend generates all of its CUDA C from the IR)."""
    if options is None:
        return
    if not isinstance(options, ModuleBuildOptions):
        raise KdslTypeError(f"set_module_options: 'extra_build_options' must be a "
                            f"kdsl.ModuleBuildOptions or None, not {type(options).__name__}")  # fmt: skip
    names = options.native_code()
    if names:
        raise KdslCapabilityError(
            f"set_module_options: extra_build_options sets {', '.join(names)}: C++ text for "
            f"Warp's native builds. kdsl's cpu backend emits LLVM IR and its cuda backend "
            f"generates all of its CUDA C from the IR, so there is nowhere to put it "
            f"(extra_build_dependencies are supported)"
        )


def check_deterministic(value: Any) -> None:
    """Check the ``deterministic`` module option (see the module docstring)."""
    if value is None or value is False or value == DeterministicMode.NOT_GUARANTEED:
        return
    if value is True or value in (DeterministicMode.RUN_TO_RUN, DeterministicMode.GPU_TO_GPU):
        raise KdslDeterminismError(
            f"set_module_options: deterministic={value!r}: kdsl has no ordered-atomics mode "
            f"(float atomics on the cpu and cuda backends may sum in any order); only "
            f"DeterministicMode.NOT_GUARANTEED is available (the interp backend is "
            f"deterministic)"
        )
    raise KdslTypeError(f"set_module_options: 'deterministic' must be a kdsl.DeterministicMode, "
                        f"not {value!r}")  # fmt: skip
