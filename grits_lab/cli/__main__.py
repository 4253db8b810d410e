"""`python -m grits_lab.cli`: the same as the `grits-lab` command."""

import sys

from grits_lab.cli import main

sys.exit(main())
