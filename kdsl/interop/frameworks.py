"""What the PyTorch, Paddle and JAX adapters share, parameterized by the framework's names.

A ``Framework`` holds how messages spell a framework (``"torch"``, ``"Paddle"``,
``"JAX"``) and its module name, which is also its column of kdsl's scalar table
(``ScalarType.torch``, ``.paddle``, ``.jax``). Its methods are the conversions whose
logic is the same for every framework: loading the module lazily, a CUDA ordinal to
a kdsl device, dtype names to kdsl scalars and back, the checks on an array handed
to a framework, and a tensor's gradient attached to a kdsl array.
"""

from __future__ import annotations

import functools
import importlib
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from kdsl.errors import KdslError
from kdsl.interop.dtypes import (
    InteropDeviceError,
    framework_name,
    kdsl_scalar,
    public_scalar,
    scalar_from_name,
)
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, get_device

#: ``view(tensor, dtype)``: a framework tensor seen as a kdsl buffer, its IR type, its device.
TensorView = Callable[[Any, Any], tuple[Any, T.Type, Device]]


@dataclass(frozen=True)
class Framework:
    """A framework's names, and the conversions that only differ by them."""

    label: str
    """How messages name the framework: ``"torch"``, ``"Paddle"``, ``"JAX"``."""
    module: str
    """Its module, also the name of its column of the scalar table (``ScalarType.torch``)."""
    submodules: tuple[str, ...] = ()
    """Submodules to import with it (``paddle.utils.dlpack``, not loaded by ``import paddle``)."""

    def load(self) -> Any:
        """The framework's module, imported only when a conversion runs."""
        mod = sys.modules.get(self.module)  # the per-call path: no import machinery
        if mod is not None and all(name in sys.modules for name in self.submodules):
            return mod
        mod = importlib.import_module(self.module)
        for name in self.submodules:
            importlib.import_module(name)
        return mod

    def loaded(self) -> Any:
        """The module if something has imported it already, else None (never imports it)."""
        return sys.modules.get(self.module)

    def cuda_device(self, index: int, source: Any) -> Device:
        """The kdsl device ``cuda:index``; ``source`` (the framework's own device) names it."""
        try:
            return get_device(f"cuda:{index}")
        except KdslError as e:
            raise InteropDeviceError(f"{self.label} device {source}: {e.message}") from None

    def no_device(self, what: str) -> InteropDeviceError:
        """The error for a framework device ``what`` (``"torch device 'mps'"``) kdsl lacks."""
        return InteropDeviceError(
            f"{what} has no kdsl equivalent (kdsl runs on 'cpu' and 'cuda:N')"
        )

    def device_string(self, warp_device: Any, gpu: str) -> str:
        """The framework's device string of a kdsl device: ``"cpu"`` or ``f"{gpu}:N"``."""
        dev = get_device(warp_device)
        return "cpu" if dev.is_cpu else f"{gpu}:{dev.ordinal}"

    def scalar(self, dtype: Any) -> T.ScalarType:
        """The kdsl scalar of a dtype whose ``str`` ends in its NumPy name (``torch.float32``)."""
        return scalar_from_name(framework_name(dtype), f"{self.label} dtype {dtype}")

    def dtype_from(self, dtype: Any) -> type:
        """The kdsl scalar class of a framework dtype; bfloat16 and complex raise ``TypeError``."""
        return public_scalar(self.scalar(dtype))

    def dtype_to(self, warp_dtype: Any, namespace: Any) -> Any:
        """The framework's dtype of a kdsl scalar type, looked up in ``namespace``."""
        return getattr(namespace, getattr(kdsl_scalar(warp_dtype, self.label), self.module))

    def twin(self, t: T.ScalarType) -> T.ScalarType:
        """``t``, or the signed scalar of its width where the framework lacks ``t`` (uint32)."""
        return _twin(t, self.module, self.label)

    def check_export(self, a: Any, fn: str) -> None:
        """Refuse what ``fn`` (``"to_torch"``) cannot hand over: a non-array or a generic one."""
        if not isinstance(a, array):
            raise KdslError(f"{fn}() takes a kdsl array, not {type(a).__name__}")
        if a._t is None:
            raise KdslError(f"{fn}(): the array has no dtype (array(dtype=Any))")


@functools.lru_cache(maxsize=64)
def _twin(t: T.ScalarType, module: str, label: str) -> T.ScalarType:
    return scalar_from_name(getattr(t, module), label)


def attach_grad(a: array, grad: Any, view: TensorView) -> array:
    """Make ``grad`` (a kdsl array, or a tensor seen through ``view``) ``a``'s gradient."""
    if isinstance(grad, array):
        a.grad = grad
    else:
        gbuf, gt, gdev = view(grad, a._t)
        a.grad = array._wrap(gbuf, gt, gdev)
    a.requires_grad = True  # grad is set: nothing is allocated
    return a
