"""kdsl: a Python kernel DSL for GPU and CPU simulation and graphics code.

Its public API follows NVIDIA Warp's, so ``import kdsl as wp`` ports a Warp program.
Each subsystem lists its public names in its own ``api`` module; this file only
gathers them. Importing kdsl imports no GPU, torch or jax package.
"""

from kdsl import config, errors
from kdsl.errors import (
    KdslAttributeError,
    KdslCapabilityError,
    KdslDeterminismError,
    KdslError,
    KdslIndexError,
    KdslKeyError,
    KdslLaunchError,
    KdslNameError,
    KdslRuntimeError,
    KdslSyntaxError,
    KdslTypeError,
    KdslValueError,
    KdslVerifyError,
    WarpCodegenAttributeError,
    WarpCodegenError,
    WarpCodegenIndexError,
    WarpCodegenKeyError,
    WarpCodegenTypeError,
    WarpCodegenValueError,
    WarpDeterminismError,
)
from kdsl.frontend.api import *
from kdsl.interop.api import *
from kdsl.runtime.api import *
from kdsl.runtime.api_platform import *
from kdsl.types import *
from kdsl.types import (
    bool,  # noqa: A004 - Warp's name
    class_of,
    dtype_from_numpy,
    dtype_to_numpy,
    type_of,
)

# isort: split
# Last: the standard library is kdsl code and uses the names above.
from kdsl.stdlib.api import *

# isort: split
# ``kdsl.autograd`` and ``kdsl.utils`` (Warp's ``warp.autograd``, ``warp.utils``) are built
# on the runtime above; ``kdsl.ext`` holds kdsl's own kernel builtins (Warp has none such).
from kdsl import autograd, ext, utils
from kdsl.geometry import *
from kdsl.texture import *
from kdsl.utils.map import map  # noqa: A004 - Warp's name
from kdsl.utils.transforms import transform_expand

__version__ = "0.1.0"
