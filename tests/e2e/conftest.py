"""Browser tests run under ``make e2e`` (PHENOROVER_E2E=1), not in ``make test``: they
need Debian's chromium and the ``e2e`` extra, and take a minute or two."""

import os

if os.environ.get("PHENOROVER_E2E") != "1":
    collect_ignore_glob = ["test_*.py"]
