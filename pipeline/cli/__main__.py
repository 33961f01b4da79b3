"""`python -m pipeline.cli VERB ...` is `r2s VERB ...` (the tests and benchmarks run it so)."""

import sys

from pipeline.cli import main

sys.exit(main())
