"""``python -m fenics_contact``: the ``fenics-contact`` console script (``fenics_contact.launch.main``)."""

import sys

from fenics_contact.launch import main

sys.exit(main())
