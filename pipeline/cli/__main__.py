"""``python -m pipeline.cli``: the console script, Ctrl-C handling included."""

import sys

from pipeline.entry import main

sys.exit(main())
