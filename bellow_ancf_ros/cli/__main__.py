"""``python -m bellow_ancf_ros.cli``: the ``bellow-ancf`` command."""

import sys

from . import main

sys.exit(main())
