"""``python -m contactdyn``: the ``contactdyn`` command (:func:`contactdyn.cli.main`)."""

import sys

from .cli import main

sys.exit(main())
