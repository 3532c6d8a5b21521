"""Before/after timing of two source trees: a benchmark run alternately in child processes.

``alternate(script, args, trees, repeats)`` runs ``script args --json`` once per tree per
repeat (tree order alternating inside each repeat), each child importing ``contactdyn`` from
its tree (``CONTACTDYN_TREE``, honoured by the scripts that use this module), and returns
every child's JSON rows per tree. The machine's load drifts over minutes; alternating the
trees within each repeat and taking medians keeps the ratio honest.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ENV = "CONTACTDYN_TREE"  #: the source tree a child imports contactdyn from
HERE = Path(__file__).resolve().parent.parent  #: this tree


def use_tree() -> None:
    """Put the chosen tree (``$CONTACTDYN_TREE``, else this one) first on sys.path; call before importing contactdyn."""
    sys.path.insert(0, os.environ.get(ENV) or str(HERE))


def alternate(script: str, args: list[str], trees: dict[str, str], repeats: int) -> dict[str, list[list[dict]]]:
    """{label: [the child's JSON rows, per repeat]} for each tree (label -> path)."""
    got: dict[str, list[list[dict]]] = {label: [] for label in trees}
    for _ in range(repeats):
        for label, tree in trees.items():
            out = subprocess.run([sys.executable, script, *args, "--json"], check=True, capture_output=True, text=True,
                                 env={**os.environ, ENV: str(Path(tree).resolve())}).stdout
            got[label].append(json.loads(out.splitlines()[-1]))
    return got
