"""``python -m kdsl.testing.fuzz --minutes N [--backends interp,cpu,cuda] [--seed S]``."""

import sys

from kdsl.testing.fuzz.run import main

sys.exit(main())
