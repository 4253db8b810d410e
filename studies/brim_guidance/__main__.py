"""`python -m studies.brim_guidance [--run]`: this study's committed commands (README.md, "Commands"), printed or run."""

import sys

from studies.commands import main

if __name__ == "__main__":
    sys.exit(main("brim_guidance"))
