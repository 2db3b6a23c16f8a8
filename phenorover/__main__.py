import sys

from phenorover.cli import main

sys.exit(main())
