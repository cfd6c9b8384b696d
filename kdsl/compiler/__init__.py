"""The compiler: the only place that builds pipelines, keys the kernel cache and calls
a backend's stages (see ``driver``). It sits above the frontend and the backends and
below the runtime, which asks it for compiled kernels.
"""

from kdsl.backends.facts import register_fact_store
from kdsl.compiler import cache as kernel_cache
from kdsl.compiler import python_scope
from kdsl.compiler.adjoint import adjoint_module
from kdsl.compiler.driver import compile_kernel, load_support, lower, prepare_module
from kdsl.compiler.pipelines import check_pipeline
from kdsl.compiler.records import CompileRecord, record_compiles
from kdsl.types import register_python_scope

# Builtins, standard-library functions and composite operators called from Python
# evaluate through the interp backend (see ``python_scope``).
register_python_scope(python_scope.call)
# Backends keep slow facts about their toolchain (NVRTC's version) in the kernel cache.
register_fact_store(kernel_cache.stored_fact)

__all__ = [
    "CompileRecord",
    "adjoint_module",
    "check_pipeline",
    "compile_kernel",
    "load_support",
    "lower",
    "prepare_module",
    "record_compiles",
]
