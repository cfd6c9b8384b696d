"""kdsl's extensions to Warp's kernel language: kernel builtins Warp has no spelling for.

Everything at the top level of ``kdsl`` follows Warp's API (``import kdsl as wp`` ports
a Warp program); a builtin that Warp lacks lives here instead, so that it never
shadows a name Warp may add and a reader sees at the call that the code is kdsl's
(``wp.ext.empty(...)``). docs/language.md ("kdsl extensions") lists them.

- ``empty(shape, dtype=float)``: in a kernel or ``@kdsl.func``, a thread-local array
  whose contents are undefined until written (``zeros`` without the fill; IR:
  ``kd.local_array`` with ``fill = "none"``).
"""

from kdsl.frontend.builtins_local import LOCAL_EMPTY

#: ``ext.empty(shape, dtype=float)``: see the module docstring.
empty = LOCAL_EMPTY

__all__ = ["empty"]
