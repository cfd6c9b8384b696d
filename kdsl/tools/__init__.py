"""Developer tools behind the ``kdsl`` command line (``kdsl opt``...)."""
