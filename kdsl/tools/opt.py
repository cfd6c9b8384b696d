"""``kdsl opt``: parse IR text, run a pass pipeline, print the result.

The CLI wires ``kdsl opt FILE.kir -p PIPELINE`` to ``run_opt``; the FileCheck tests
call it directly.
"""

from __future__ import annotations

import io

from kdsl.ir import parse_module, print_module
from kdsl.passes import PassManager


def run_opt(
    text: str,
    pipeline: str,
    *,
    file: str = "<ir>",
    print_after_all: bool = False,
    time_passes: bool = False,
    debuginfo: bool = False,
    verify_each: bool = True,
) -> str:
    """Parse ``text``, run ``pipeline`` and return the printed module.

    IR dumps (``print_after_all``) and the timing report (``time_passes``) come
    first, then the final IR. If the pipeline ran the ``features`` analysis, its
    summary follows as ``// features:`` comment lines (the output still parses).
    The special pass name ``roundtrip`` is not needed: an empty pipeline gives
    print(parse(text)).
    """
    module = parse_module(text, file=file)
    log = io.StringIO()
    manager = PassManager(
        pipeline,
        verify_each=verify_each,
        print_after_all=print_after_all,
        time_passes=time_passes,
        out=log,
        debuginfo=debuginfo,
    )
    manager.run(module)
    out = log.getvalue() + print_module(module, debuginfo=debuginfo)
    features = getattr(module, "features", None)
    if features is not None:
        out += "".join(f"// features: {line}\n" for line in features.summary().splitlines())
    return out
