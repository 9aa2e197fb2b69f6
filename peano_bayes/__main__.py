"""``python -m peano_bayes``: the same command line as ``peano-bayes``."""

import sys

from peano_bayes.app.cli import main

sys.exit(main())
