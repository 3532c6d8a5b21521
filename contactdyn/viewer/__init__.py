"""See runs in meshcat: live in a browser, or as a self-contained HTML file.

``build_scene(result)`` turns a :class:`~contactdyn.output.result.Result` into meshcat commands
headless (robot from its URDF visuals, surfaces and carts, deformation-chain gauges,
force arrows, impact markers, all animated over the run); ``export_html`` writes them
into one offline HTML player; ``view_result`` / ``view_command`` start a meshcat server
and print its URL. Playback runs at ``speed`` × real time with meshcat's own controls
(it opens at t = 0 and loops; Open Controls → Animations: play, pause, the time scrubber and its time scale).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from ..output.result import Result, load_result
from .build import build_scene
from .export import export_html
from .live import LOOPBACK, LiveViewer
from .writer import ViewerScene

__all__ = ["build_scene", "export_html", "view_result", "view_command", "LiveViewer", "ViewerScene"]


def view_command(args: argparse.Namespace) -> int:
    """``contactdyn view RUN [--html FILE] [--port N] [--speed X]``: RUN is a saved run (NAME.npz + NAME.json)."""
    return view_result(load_result(args.run), args)


def view_result(result: Result, args: argparse.Namespace) -> int:
    """Show a run: write ``args.html`` if given, else serve it live until Ctrl+C."""
    speed = getattr(args, "speed", None)
    scene = build_scene(result, speed=1.0 if speed is None else speed)
    html = getattr(args, "html", None)
    if html:
        path = export_html(scene, html)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): open it in a browser, no server needed")
        _print_legend(scene)
        return 0
    host = getattr(args, "host", None) or LOOPBACK
    if host != LOOPBACK:
        print(f"warning: the viewer listens on {host}: whoever can reach that address sees this run", file=sys.stderr)
    with LiveViewer(port=getattr(args, "port", None), host=host) as live:
        live.show(scene)
        print(f"meshcat: open {live.url}", flush=True)
        _print_legend(scene)
        print("serving until Ctrl+C", flush=True)
        with _sigterm_as_interrupt():
            live.wait()
    return 0


def _print_legend(scene: ViewerScene) -> None:
    for line in scene.legend + scene.notes:
        print(f"  {line}", flush=True)


class _sigterm_as_interrupt:  # noqa: N801 (used as a context manager)
    """SIGTERM ends serving like Ctrl+C (so the server child is closed), in the main thread only."""

    def __enter__(self):
        self.previous = None
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGTERM, self._raise)
        return self

    @staticmethod
    def _raise(signum, frame):
        raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
