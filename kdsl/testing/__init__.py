"""kdsl.testing: the conformance suite every backend must pass, shipped in the package.

Plugin authors run it against their backend with::

    kdsl conformance --backend NAME
    # or, equivalently
    pytest --pyargs kdsl.testing -p kdsl.testing.plugin --kdsl-backend=NAME

``kdsl.testing.cases`` holds the cases (kernel, inputs, NumPy float64 reference),
``kdsl.testing.conformance`` runs one case on one backend and device.
"""

from kdsl.testing.case import Case
from kdsl.testing.conformance import Target, check_case, run_case, targets

__all__ = ["Case", "Target", "check_case", "run_case", "targets"]
