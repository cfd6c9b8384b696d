"""Public names of the standard library, star-imported into ``kdsl``."""

from kdsl.stdlib.algorithms import *  # noqa: F403
from kdsl.stdlib.bvh import *  # noqa: F403
from kdsl.stdlib.dense import *  # noqa: F403
from kdsl.stdlib.hash_grid import *  # noqa: F403
from kdsl.stdlib.linalg import *  # noqa: F403
from kdsl.stdlib.mesh import *  # noqa: F403
from kdsl.stdlib.noise import *  # noqa: F403
from kdsl.stdlib.quat import *  # noqa: F403
from kdsl.stdlib.random import *  # noqa: F403
from kdsl.stdlib.spatial import *  # noqa: F403
from kdsl.stdlib.special import *  # noqa: F403
from kdsl.stdlib.transform import *  # noqa: F403

# isort: split
# The functions the frontend lowers quaternion and transform syntax to (q * q, t.p, ...).
from kdsl.frontend.library import REQUIRED, register_library
from kdsl.stdlib import quat as _quat
from kdsl.stdlib import transform as _transform

register_library({n: getattr(_quat, n, None) or getattr(_transform, n) for n in REQUIRED})
