"""The viz service's own command-line options, on top of every service's."""

from __future__ import annotations

import argparse
import json


class VizCli:
    """``--serve``, ``--save FILE.rrd`` and ``--connect URL``: a ``--connect`` value
    with a rerun scheme (``rerun+http://...``) is the viewer to push into, any other
    stays a Zenoh endpoint."""

    def add(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--serve", action="store_true", help="serve gRPC + web viewer")
        parser.add_argument("--save", metavar="FILE.rrd", help="write the recording to FILE")

    def overrides(self, args: argparse.Namespace) -> list[str]:
        out = ["serve=true"] if args.serve else []
        if args.save:
            out.append(f"save={json.dumps(args.save)}")
        viewers = [c for c in args.connect if c.startswith("rerun")]
        args.connect = [c for c in args.connect if not c.startswith("rerun")]
        if viewers:
            out.append(f"connect={json.dumps(viewers[-1])}")
        return out
