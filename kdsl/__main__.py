"""``python -m kdsl``: the kdsl command line."""

from kdsl.cli import main

raise SystemExit(main())
