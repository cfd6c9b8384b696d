"""Public names of the standard library, star-imported into ``kdsl``."""

from kdsl.stdlib.linalg import *  # noqa: F403
from kdsl.stdlib.noise import *  # noqa: F403
from kdsl.stdlib.quat import *  # noqa: F403
from kdsl.stdlib.random import *  # noqa: F403
from kdsl.stdlib.spatial import *  # noqa: F403
from kdsl.stdlib.special import *  # noqa: F403
from kdsl.stdlib.transform import *  # noqa: F403
