"""The marching cubes case tables, as Python data (Warp 1.19's layout and numbering).

A cube's corners are numbered as in Lorensen and Cline / Paul Bourke ("Polygonising a
scalar field", 1994): corner ``c`` sits at ``CUBE_CORNER_OFFSETS[c]`` from the cell's
lowest node, and bit ``c`` of a cell's case code is set when that corner's value is at
or above the threshold. Edge ``e`` joins the corners ``EDGE_TO_CORNERS[e]``.
``TRIANGLES[case]`` lists the edges whose vertices make the case's triangles, three per
triangle: Bourke's public-domain table, the one Warp uses, so triangles and their
winding are Warp's. ``CASE_TO_TRI_RANGE`` and ``TRI_LOCAL_INDICES`` are the same table
flattened as Warp 1.19 exposes it (``IsoSurfaceMarchingCubes.CASE_TO_TRI_RANGE``...).
"""

from __future__ import annotations

from itertools import accumulate

#: The ``(x, y, z)`` offset of each of a cell's 8 corners from its lowest node.
CUBE_CORNER_OFFSETS: tuple[tuple[int, int, int], ...] = (
    (0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
    (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1),
)  # fmt: skip

#: The two corners each of a cell's 12 edges joins (lower corner first).
EDGE_TO_CORNERS: tuple[tuple[int, int], ...] = (
    (0, 1), (1, 2), (3, 2), (0, 3),
    (4, 5), (5, 6), (7, 6), (4, 7),
    (0, 4), (1, 5), (2, 6), (3, 7),
)  # fmt: skip

# Bourke's table, four cases a line: "case: triangles | triangles | ...", a triangle as
# three hexadecimal edge numbers, "-" for a case without triangles.
_TRIANGLE_TEXT = """
  0: - | 083 | 019 | 183 981
  4: 12a | 083 12a | 92a 029 | 283 2a8 a98
  8: 3b2 | 0b2 8b0 | 190 23b | 1b2 19b 98b
 12: 3a1 ba3 | 0a1 08a 8ba | 390 3b9 ba9 | 98a a8b
 16: 478 | 430 734 | 019 847 | 419 471 731
 20: 12a 847 | 347 304 12a | 92a 902 847 | 2a9 297 273 794
 24: 847 3b2 | b47 b24 204 | 901 847 23b | 47b 94b 9b2 921
 28: 3a1 3ba 784 | 1ba 14b 104 7b4 | 478 90b 9ba b03 | 47b 4b9 9ba
 32: 954 | 954 083 | 054 150 | 854 835 315
 36: 12a 954 | 308 12a 495 | 52a 542 402 | 2a5 325 354 348
 40: 954 23b | 0b2 08b 495 | 054 015 23b | 215 258 28b 485
 44: a3b a13 954 | 495 081 8a1 8ba | 540 50b 5ba b03 | 548 58a a8b
 48: 978 579 | 930 953 573 | 078 017 157 | 153 357
 52: 978 957 a12 | a12 950 530 573 | 802 825 857 a52 | 2a5 253 357
 56: 795 789 3b2 | 957 972 920 27b | 23b 018 178 157 | b21 b17 715
 60: 958 857 a13 a3b | 570 509 7b0 10a ba0 | ba0 b03 a50 807 570 | ba5 7b5
 64: a65 | 083 5a6 | 901 5a6 | 183 198 5a6
 68: 165 261 | 165 126 308 | 965 906 026 | 598 582 526 328
 72: 23b a65 | b08 b20 a65 | 019 23b 5a6 | 5a6 192 9b2 98b
 76: 63b 653 513 | 08b 0b5 051 5b6 | 3b6 036 065 059 | 659 69b b98
 80: 5a6 478 | 430 473 65a | 190 5a6 847 | a65 197 173 794
 84: 612 651 478 | 125 526 304 347 | 847 905 065 026 | 739 794 329 596 269
 88: 3b2 784 a65 | 5a6 472 420 27b | 019 478 23b 5a6 | 921 9b2 94b 7b4 5a6
 92: 847 3b5 351 5b6 | 51b 5b6 10b 7b4 04b | 059 065 036 b63 847 | 659 69b 479 7b9
 96: a49 64a | 4a6 49a 083 | a01 a60 640 | 831 816 864 61a
100: 149 124 264 | 308 129 249 264 | 024 426 | 832 824 426
104: a49 a64 b23 | 082 28b 49a 4a6 | 3b2 016 064 61a | 641 61a 481 21b 8b1
108: 964 936 913 b63 | 8b1 810 b61 914 641 | 3b6 360 064 | 648 b68
112: 7a6 78a 89a | 073 0a7 09a 67a | a67 1a7 178 180 | a67 a71 173
116: 126 168 189 867 | 269 291 679 093 739 | 780 706 602 | 732 672
120: 23b a68 a89 867 | 207 27b 097 67a 9a7 | 180 178 1a7 67a 23b | b21 b17 a61 671
124: 896 867 916 b63 136 | 091 b67 | 780 706 3b0 b60 | 7b6
128: 76b | 308 b76 | 019 b76 | 819 831 b76
132: a12 6b7 | 12a 308 6b7 | 290 2a9 6b7 | 6b7 2a3 a83 a98
136: 723 627 | 708 760 620 | 276 237 019 | 162 186 198 876
140: a76 a17 137 | a76 17a 187 108 | 037 07a 0a9 6a7 | 76a 7a8 8a9
144: 684 b86 | 36b 306 046 | 86b 846 901 | 946 963 931 b36
148: 684 6b8 2a1 | 12a 30b 06b 046 | 4b8 46b 029 2a9 | a93 a32 943 b36 463
152: 823 842 462 | 042 462 | 190 234 246 438 | 194 142 246
156: 813 861 846 6a1 | a10 a06 604 | 463 438 6a3 039 a93 | a94 6a4
160: 495 76b | 083 495 b76 | 501 540 76b | b76 834 354 315
164: 954 a12 76b | 6b7 12a 083 495 | 76b 54a 42a 402 | 348 354 325 a52 b76
168: 723 762 549 | 954 086 062 687 | 362 376 150 540 | 628 687 218 485 158
172: 954 a16 176 137 | 16a 176 107 870 954 | 40a 4a5 03a 6a7 37a | 76a 7a8 54a 48a
176: 695 6b9 b89 | 36b 063 056 095 | 0b8 05b 015 56b | 6b3 635 531
180: 12a 95b 9b8 b56 | 0b3 06b 096 569 12a | b85 b56 805 a52 025 | 6b3 635 2a3 a53
184: 589 528 562 382 | 956 960 062 | 158 180 568 382 628 | 156 216
188: 136 16a 386 569 896 | a10 a06 950 560 | 038 56a | a56
192: b5a 75b | b5a b75 830 | 5b7 5ab 190 | a75 ab7 981 831
196: b12 b71 751 | 083 127 175 72b | 975 927 902 2b7 | 752 72b 592 328 982
200: 25a 235 375 | 820 852 875 a25 | 901 5a3 537 3a2 | 982 921 872 a25 752
204: 135 375 | 087 071 175 | 903 935 537 | 987 597
208: 584 5a8 ab8 | 504 5b0 5ab b30 | 019 84a 8ab a45 | ab4 a45 b34 941 314
212: 251 285 2b8 458 | 04b 0b3 45b 2b1 51b | 025 059 2b5 458 b85 | 945 2b3
216: 25a 352 345 384 | 5a2 524 420 | 3a2 35a 385 458 019 | 5a2 524 192 942
220: 845 853 351 | 045 105 | 845 853 905 035 | 945
224: 4b7 49b 9ab | 083 497 9b7 9ab | 1ab 1b4 140 74b | 314 348 1a4 74b ab4
228: 4b7 9b4 92b 912 | 974 9b7 91b 2b1 083 | b74 b42 240 | b74 b42 834 324
232: 29a 279 237 749 | 9a7 974 a27 870 207 | 37a 3a2 74a 1a0 40a | 1a2 874
236: 491 417 713 | 491 417 081 871 | 403 743 | 487
240: 9a8 ab8 | 309 39b b9a | 01a 0a8 8ab | 31a b3a
244: 12b 1b9 9b8 | 309 39b 129 2b9 | 02b 80b | 32b
248: 238 28a a89 | 9a2 092 | 238 28a 018 1a8 | 1a2
252: 138 918 | 091 | 038 | -
"""


def _parse_cases(text: str) -> tuple[tuple[int, ...], ...]:
    cases: list[tuple[int, ...]] = []
    for line in text.strip().splitlines():
        for case in line.split(":", 1)[1].split("|"):
            cases.append(tuple(int(e, 16) for tri in case.split() if tri != "-" for e in tri))
    return tuple(cases)


#: The edges of each case's triangles, three per triangle.
TRIANGLES: tuple[tuple[int, ...], ...] = _parse_cases(_TRIANGLE_TEXT)

#: ``TRI_LOCAL_INDICES[CASE_TO_TRI_RANGE[c] : CASE_TO_TRI_RANGE[c + 1]]`` is ``TRIANGLES[c]``.
CASE_TO_TRI_RANGE: tuple[int, ...] = (0, *accumulate(len(t) for t in TRIANGLES))

#: Every case's triangle edges, one after another (2460 entries: 820 triangles).
TRI_LOCAL_INDICES: tuple[int, ...] = tuple(e for t in TRIANGLES for e in t)


def edge_node_and_axis(edge: int) -> tuple[int, int, int, int]:
    """``(dx, dy, dz, axis)``: the node an edge starts at, as an offset from the cell's
    lowest node, and the axis it runs along (0, 1, 2 for x, y, z)."""
    a, b = (CUBE_CORNER_OFFSETS[c] for c in EDGE_TO_CORNERS[edge])
    axis = next(d for d in range(3) if a[d] != b[d])
    return (*a, axis)
