"""The package's own exceptions: each message says what was expected and what was found."""

from __future__ import annotations

__all__ = ["ContactdynError", "RobotError", "FrameError", "RunFileError", "SceneError", "UnknownKeyError",
           "SimulationError", "close_matches", "signal_name", "first_line"]


class ContactdynError(Exception):
    """Base class of every error contactdyn raises on purpose."""


class RobotError(ContactdynError):
    """A robot description (URDF, example-robot-data name, frame, joint) is unusable; ``key``: the scene key it is
    about where that is not the robot's source (a joint name of ``robot.active_joints`` or ``robot.locked``)."""

    def __init__(self, message: str, key: str | None = None):
        super().__init__(message)
        self.key = key


class FrameError(RobotError):
    """A frame name the robot does not have (the message lists close ones)."""


class SceneError(ContactdynError):
    """A scene file or override is invalid.

    The message names the file, the key path (e.g. ``contact.tip.normal.k``), what was
    expected and what was found.
    """

    def __init__(self, key: str, expected: str, found: object, file: str | None = None):
        self.file, self.key, self.expected, self.found = file, key, expected, found
        where = f"{file}: " if file else ""
        if len(expected) > 300:
            expected = f"{expected[:260]} ... {expected[-20:]}"
        # our own error's message (a robot's, a frame's) is kept whole; a value the user typed is shortened
        found_text = str(found) if isinstance(found, ContactdynError) else abbreviate(found)
        super().__init__(f"{where}{key}: expected {expected}, found {found_text}")


def abbreviate(value: object, limit: int = 200) -> str:
    """``repr(value)`` cut to about ``limit`` characters (head ... tail, with the full length)."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit - 40]} ... {text[-20:]} ({len(text)} characters)"


def first_line(text: str, limit: int = 500) -> str:
    """The first line of ``text`` that is not blank, without terminal colours: whole up to ``limit`` characters (a
    message quoted from someone's exception; a longer line keeps its head and says its length), "" for none."""
    import re

    lines = [line.strip() for line in re.sub(r"\x1b\[[0-9;]*m", "", text).splitlines() if line.strip()]
    line = lines[0] if lines else ""
    return line if len(line) <= limit else f"{line[:limit - 40]} ... ({len(line)} characters)"


def close_matches(name: str, choices, n: int = 3, cutoff: float = 0.6) -> list[str]:
    """Up to ``n`` of ``choices`` close to ``name``, best first (for a "did you mean" hint)."""
    import difflib

    return difflib.get_close_matches(str(name), list(choices), n=n, cutoff=cutoff)


class UnknownKeyError(SceneError):
    """A key no reader knows: ``contact.tip.normal.kk: unknown key; did you mean 'k'? (known here: b, k, m)``."""

    def __init__(self, key: str, known: list[str], suggestion: str | None, file: str | None = None):
        super().__init__(key, f"a known key ({', '.join(known) or 'none'})", "an unknown key", file)
        hint = f"; did you mean {suggestion!r}?" if suggestion else ""
        where = f"{file}: " if file else ""
        self.args = (f"{where}{key}: unknown key{hint} (known here: {', '.join(known) or 'none'})",)


class SimulationError(ContactdynError):
    """A run could not continue (solver failure, blow-up, event storm); says when and why."""


class RunFileError(ContactdynError):
    """A saved run (NAME.npz + NAME.json) is missing, damaged or not one of ours; names the file."""


def signal_name(sig: int) -> str:
    """A signal for a message: ``SIGSEGV (11)``."""
    import signal

    try:
        return f"{signal.Signals(sig).name} ({sig})"
    except ValueError:
        return f"signal {sig}"


def numerical_errors() -> tuple[type[Exception], ...]:
    """The numerical failures a blow-up raises from numpy inside a run (a failed run, not a bug)."""
    import numpy as np  # here, not at the top: the command line's light commands need no numpy

    return (np.linalg.LinAlgError, FloatingPointError, OverflowError)


#: a name that may become a file or folder name as it is: no path separator, no leading dot, printable
PLAIN_NAME = r"[A-Za-z0-9_][A-Za-z0-9_.+-]{0,127}"


def is_plain_name(name: str) -> bool:
    """Whether ``name`` can name a file or folder without leaving its parent (PLAIN_NAME)."""
    import re

    return re.fullmatch(PLAIN_NAME, name) is not None
