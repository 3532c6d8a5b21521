"""Run many ``contactdyn`` command lines in this one process; print one JSON line per case.

Used by tests/test_hostile_inputs.py inside a subprocess with a memory cap and a timeout:
reads ``[{"id": ..., "argv": [...]}, ...]`` on stdin, prints ``{"id", "code", "err", "out"}``
per case as soon as it ends (so a crash shows which case caused it).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import traceback


def main() -> None:
    from contactdyn.cli import main as cli

    for case in json.load(sys.stdin):
        out, err = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = cli(case["argv"])
        except BaseException:  # noqa: BLE001 (what the corpus looks for: reported, not raised)
            code = "exception"
            err.write(traceback.format_exc())
        print(json.dumps({"id": case["id"], "code": code, "err": err.getvalue()[-4000:],
                          "err_chars": len(err.getvalue()), "out": out.getvalue()[-2000:]}), flush=True)


if __name__ == "__main__":
    main()
