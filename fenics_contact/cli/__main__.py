"""``python -m fenics_contact.cli``: the command line without the start-up guard of ``fenics_contact.launch``."""

import sys

from fenics_contact.cli.command import main

if __name__ == "__main__":
    sys.exit(main())
