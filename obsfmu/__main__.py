"""``python -m obsfmu``: the command line."""

import sys

from obsfmu.fmus.cli.main import main

sys.exit(main())
