"""``python -m fenics_contact``: the ``fenics-contact`` console script (``fenics_contact.launch.main``)."""

import sys

from fenics_contact.launch import main

if __name__ == "__main__":
    sys.exit(main())
