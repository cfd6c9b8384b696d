"""Repository-wide test settings.

Under CI (``CI`` set) Hypothesis runs derandomized, so a landing is decided by the
code and not by the luck of a random search; locally it searches freshly each run.
"""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
