"""``python -m fabplan.cli ARGS``: the `fabplan` command."""

import sys

from .command_line import main

if __name__ == "__main__":
    sys.exit(main())
