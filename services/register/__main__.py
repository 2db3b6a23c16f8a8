import sys

from services.register.cli import main

sys.exit(main())
