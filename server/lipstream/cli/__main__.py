"""``python -m lipstream.cli``: the ``lipstream`` command."""

import sys

from . import main

sys.exit(main())
