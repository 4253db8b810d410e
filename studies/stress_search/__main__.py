"""`python -m studies.stress_search [--run]`: this study's committed commands (README.md, "Commands"), printed or run."""

import sys

from studies.commands import main

if __name__ == "__main__":
    sys.exit(main("stress_search"))
