import sys

from fxflex.cli import main

sys.exit(main())
