"""The run's player inline in a notebook: the self-contained HTML page of ``view --html`` in an iframe."""

from __future__ import annotations

import html

from ..output.result import Result
from .build import build_scene
from .export import html_document

__all__ = ["InlinePlayer", "inline_player"]


class InlinePlayer:
    """A page that Jupyter shows inline (``_repr_html_``): an iframe holding the whole player."""

    def __init__(self, page: str, height: int):
        self.page, self.height = page, int(height)

    def _repr_html_(self) -> str:
        return (f'<iframe srcdoc="{html.escape(self.page, quote=True)}" style="width: 100%; '
                f'height: {self.height}px; border: 0"></iframe>')


def inline_player(result: Result, speed: float = 1.0, height: int = 480) -> InlinePlayer:
    """The player of ``result`` at ``speed`` × real time, ``height`` [px] tall."""
    return InlinePlayer(html_document(build_scene(result, speed), title=str(result.meta.get("name", "run"))), height)
