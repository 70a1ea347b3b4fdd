"""`python -m hydrotact.cli`: the `hydrotact` command."""

import sys

from . import main

sys.exit(main())
