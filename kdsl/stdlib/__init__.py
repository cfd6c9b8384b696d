"""kdsl's standard library: kernel-language functions written in kdsl itself.

Everything a backend need not lower as a primitive (quaternion and transform
algebra, spatial algebra, matrix decompositions, random numbers, noise) is
``@kdsl.func`` code here, compiled by every backend like user code and only when
a kernel calls it. ``kdsl.stdlib.api`` gathers the public names.
"""
