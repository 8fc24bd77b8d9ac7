"""``python -m pilworld`` runs the command line."""

import sys

from pilworld.cli.main import main

sys.exit(main())
