"""`python -m studies.protocol [--run]`: this study's committed commands (README.md, "Commands"), printed or run."""

import sys

from studies.commands import main

if __name__ == "__main__":
    sys.exit(main("protocol"))
