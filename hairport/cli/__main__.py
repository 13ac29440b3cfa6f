"""``python -m hairport.cli``."""

import sys

from hairport.cli import main

sys.exit(main())
