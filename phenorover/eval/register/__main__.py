import sys

from phenorover.eval.register.cli import main

sys.exit(main())
