"""Benchmarks that compare checkouts (``--tree``): run the tool again in a child process
that imports a given tree's ``hexactl`` and read the JSON it prints last."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any


def child_reply(tree: Path, script: str, arguments: list[str]) -> dict[str, Any]:
    """The last line ``script`` prints as JSON when run with ``arguments`` in a child process
    whose ``hexactl`` is ``tree``'s (its reply's ``hexactl`` says which it imported). Exits
    naming the tree if the child fails or imported another ``hexactl``."""
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    child = subprocess.run([sys.executable, script, *arguments], env=env, cwd=tree, capture_output=True, text=True)
    if child.returncode:
        sys.exit(f"{tree}: {child.stderr}")
    reply = json.loads(child.stdout.splitlines()[-1])
    if not Path(reply["hexactl"]).is_relative_to(tree.resolve()):
        sys.exit(f"{tree}: the child imported {reply['hexactl']}")
    return reply
