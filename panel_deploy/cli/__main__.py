"""``python -m panel_deploy.cli``: the ``panel-deploy`` command."""

import sys

from . import main

sys.exit(main())
