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
from kdsl.stdlib.texture import *  # noqa: F403
from kdsl.stdlib.transform import *  # noqa: F403
from kdsl.stdlib.volume import *  # noqa: F403

# isort: split
# The functions the frontend lowers quaternion and transform syntax to (q * q, t.p, ...).
from kdsl.frontend.builtins_texture import LIBRARY as _TEXTURE_LIBRARY
from kdsl.frontend.builtins_volume import LIBRARY as _VOLUME_LIBRARY
from kdsl.frontend.library import REQUIRED, register_library, register_query_iterator
from kdsl.stdlib import bvh as _bvh
from kdsl.stdlib import hash_grid as _hash_grid
from kdsl.stdlib import mesh as _mesh
from kdsl.stdlib import quat as _quat
from kdsl.stdlib import texture as _texture
from kdsl.stdlib import transform as _transform
from kdsl.stdlib import volume as _volume

register_library({n: getattr(_quat, n, None) or getattr(_transform, n) for n in REQUIRED})
# The generic implementations of the dtype-taking volume builtins.
register_library({n: getattr(_volume, n) for n in _VOLUME_LIBRARY})
# The samplers ``texture_sample`` calls, one per texture dimension.
register_library({n: getattr(_texture, n) for n in _TEXTURE_LIBRARY.values()})
# ``for index in query:`` over geometry queries, as in Warp.
register_query_iterator(_bvh.BvhQuery, _bvh.bvh_query_next)
register_query_iterator(_hash_grid.HashGridQuery, _hash_grid.hash_grid_query_next)
register_query_iterator(_mesh.MeshQueryAABB, _mesh.mesh_query_aabb_next)
