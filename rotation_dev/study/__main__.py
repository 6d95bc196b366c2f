"""``python -m rotation_dev.study``: run the accuracy study (see :mod:`.cli`)."""
import sys

from .cli import main

sys.exit(main())
