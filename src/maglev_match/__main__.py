"""`python -m maglev_match` runs the command line."""

import sys

from maglev_match.cli import main

sys.exit(main())
