"""``python -m livesweep`` is the ``livesweep`` command."""

import sys

from livesweep.cli import main

sys.exit(main())
