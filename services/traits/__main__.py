import sys

from services.traits.cli import main

sys.exit(main())
