"""`python -m hamr_bench` is the same as the `hamr-bench` command."""

import sys

from hamr_bench.cli import main

sys.exit(main())
