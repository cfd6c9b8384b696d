"""``kdsl.utils``: parallel primitives over kdsl arrays, with Warp's names and signatures.

``array_scan``, ``radix_sort_pairs``, ``segmented_sort_pairs``, ``runlength_encode``,
``array_sum`` and ``array_inner`` run on the array's device: CuPy (CUB) on a CUDA
device, NumPy over the host's cores on the CPU (see ``buffers``). Bad arguments raise
``UtilsError``, a ``KdslError`` that is also a ``RuntimeError`` as Warp's errors are.
"""

from kdsl.utils.buffers import UtilsError
from kdsl.utils.reduce import array_inner, array_sum
from kdsl.utils.runs import runlength_encode
from kdsl.utils.scan import array_scan
from kdsl.utils.sort import radix_order, radix_sort_pairs, segmented_sort_pairs

__all__ = [
    "UtilsError", "array_inner", "array_scan", "array_sum", "radix_order", "radix_sort_pairs",
    "runlength_encode", "segmented_sort_pairs",
]  # fmt: skip
