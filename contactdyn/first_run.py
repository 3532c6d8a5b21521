"""A scene's first run: the compiled call's own functions run interpreted while its code is built in the background.

Compiling what a scene runs on (the compiled call, its controller's and laws' stages; numba, cached
after: :mod:`contactdyn.numerics.compile_cache`) takes 20–40 s of CPU on a fresh install. The same functions
run interpreted (:mod:`contactdyn.numerics.twins`: their Python twins, only the rigid-body algorithms compiled,
a few seconds once per install) give the compiled run's outputs bit for bit, ~20× slower per call: any scene of
``sims/`` in seconds. So ``contactdyn run`` with the path ``auto`` (the default) decides per run:

- the scene's *kind* was built by this build of the package (a marker in its compile cache): the
  compiled call;
- else the interpreted call (``Result.stats["paths"]``: "interpreted call"), and after the run one background
  process (``python -m contactdyn.first_run FILE MARKER``, the scene's document on stdin; low priority, detached,
  silent) runs the same scene on the compiled call, so that it compiles and caches what the scene needs, and
  marks the kind built. One line says so after the run (and, while the leaves compile, the compile notice says
  that it compiles). A run the command takes on the compiled call (``--path compiled``) marks its kind too.

While a first run compiles its leaves (the rigid-body algorithms, dense algebra and step sums its twins call compiled,
one by one as it first reaches them: most of its time), a machine with a second core compiles them from the other end:
:func:`leaves_ahead` starts one helper (``python -m contactdyn.first_run --leaves FILE MARKER``; detached, silent)
that records which leaves the scene reaches in its first millisecond (and each later phase in its first, started
there), and with which argument types, with every leaf interpreted
(:class:`~contactdyn.numerics.twins.RecordingTwins`; RECORD_LIMIT seconds at most), then compiles them last-reached
first into the shared cache and marks the kind's leaves done (``<kind>.leaves``). Where it started one, the run
compiles its own leaves before it starts (:func:`leaves_first`): recorded the same way (RUN_RECORD_LIMIT at most), the
first-reached first. Each leaf is compiled under a claim (:func:`compile_claimed`, an exclusive lock on its file in
``kinds/claims``): the helper skips one the run holds, the run waits for one the helper holds and then loads it. The
two meet in the middle and compile no leaf twice. Then the helper compiles the *late leaves* the scene reaches (a
law's arithmetic, :data:`~contactdyn.numerics.twins.LATE_LEAVES`: seconds each, too slow to wait for), marking each
arrived (``claims/<name>.arrived``); the run, on its twin meanwhile, loads it from the cache once it has arrived
(:func:`arrived`, :func:`~contactdyn.numerics.twins.late_leaves`) and runs the rest of its calls faster. The helper
changes no result (it only fills the cache) and reports nothing: a leaf it cannot compile the run compiles, and says
why (a late leaf stays interpreted). ``CONTACTDYN_LEAVES_AHEAD=0`` turns it off.

A scene's kind (:func:`kind`) is its document with every number blanked: the law names, controller
kinds, robot and which keys are set decide what is compiled, the values do not. A wrong guess costs
time, never correctness: a kind marked built whose code is not all cached compiles the rest in the
foreground (the compile notice says so); a kind not marked runs interpreted (a kind whose build failed too,
without a new build). ``--path compiled`` (or ``CONTACTDYN_PATH=compiled``) always takes the compiled call,
compiling in the foreground; ``--path interpreted`` always the interpreted one (the same functions as Python: the
one to read or step through). ``Result.stats["paths"]`` names each mode's path.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from .errors import SceneError
from .scene.scene_file import Scene

__all__ = ["PATHS", "ENV", "Choice", "choose", "kind", "build_in_background", "leaves_ahead", "leaves_first",
           "compile_claimed", "arrived", "arrivals", "mark_built", "main"]

PATHS = ("auto", "compiled", "interpreted")  #: what ``--path`` takes
ENV = "CONTACTDYN_PATH"  #: the environment variable that sets the default path (else ``auto``)
BUILD_TIMEOUT = 1800.0  #: [s] a background build older than this is taken as dead (its lock is stale)
BUILD_DURATION = 60.0  #: [s] simulated by a background build at most
RECORD_DURATION = 1e-3  #: [s] simulated by the leaves' helper to learn which leaves the scene reaches
RECORD_LIMIT = 5.0  #: [s] of wall time the helper records at most (then it compiles what it has)
RUN_RECORD_LIMIT = 1.0  #: [s] of wall time a first run records its own leaves at most (the rest compile as reached)
CLAIMS = "claims"  #: the leaves' claims: a folder beside the kinds' markers, one lock file per leaf and argument types
CLAIM_WAIT = 120.0  #: [s] a run waits at most for a leaf its helper compiles (then it compiles it itself)
CLAIM_POLL = 0.02  #: [s] between a waiting run's looks at a claim
LEAVES_LOCK = "leaves"  #: the helper's lock, beside the kinds' markers: one helper at a time
LEAVES_TIMEOUT = 300.0  #: [s] a helper older than this is taken as dead (its lock is stale)
HELPER_ENV = "CONTACTDYN_LEAVES_AHEAD"  #: set to 0: no leaves' helper (a first run compiles its leaves alone)
CPU_QUOTA = Path("/sys/fs/cgroup/cpu.max")  #: a container's CPU quota (cgroup v2), where there is one


class Choice:
    """A run's path (``compiled`` or ``interpreted``), ``build`` (the kind's background build is due
    after the run), ``failed`` (the kind's build failed: its record), ``auto`` (chosen for the path ``auto``)."""

    def __init__(self, path: str, build: bool = False, failed: Path | None = None, auto: bool = False) -> None:
        self.path, self.build, self.failed, self.auto = path, build, failed, auto

    @property
    def compiled(self) -> bool:
        return self.path == "compiled"

    @property
    def interpreted(self) -> bool:
        return self.path == "interpreted"

    def line(self) -> str:
        """What the command says after a run whose build it started, or of a kind whose build failed ("" else)."""
        if self.failed is not None:
            return (f"contactdyn: this kind of scene's compiled call failed to build in the background ({self.failed}"
                    "): it ran interpreted; --path compiled builds it in the foreground and says why")
        return ("contactdyn: this kind of scene's compiled call was not built yet: it ran interpreted (the same "
                "functions, the same results); the call is being built in the background for the next runs "
                "(--path compiled builds it in the foreground)") if self.build else ""


def default_path(environ=os.environ) -> str:
    """``$CONTACTDYN_PATH`` if set (checked), else ``auto``."""
    return _checked(environ.get(ENV, "auto"), ENV)


def _checked(path: str, key: str, file: str | None = None) -> str:
    """``path`` if it is one of :data:`PATHS`, else a SceneError naming ``key`` (the option or variable)."""
    if path not in PATHS:
        raise SceneError(key, f"one of {', '.join(PATHS)}", path, file)
    return path


def _blank(value: Any) -> Any:
    """A document with its numbers blanked (booleans and strings kept)."""
    if isinstance(value, dict):
        return {k: _blank(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_blank(v) for v in value]
    if isinstance(value, bool | str) or value is None:
        return value
    return "#"  # a number (1 and 1.0 alike)


def kind(scene: Scene) -> str:
    """The scene's kind: 16 hex digits of SHA-256 over its document (after overrides) with the numbers blanked."""
    text = json.dumps(_blank(scene.document), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _folder() -> Path:
    """Where this build's markers live: ``kinds/`` in its compiled-code directory (numba imported here)."""
    from .numerics.compile_cache import directory  # (a local import: not a compiled module's mark)

    return directory() / "kinds"


def built(scene: Scene) -> bool:
    """Has this build compiled a scene of this kind (its background build finished)?"""
    return (_folder() / f"{kind(scene)}.built").is_file()


def choose(scene: Scene, path: str) -> Choice:
    """The run's path for ``path`` (one of :data:`PATHS`; another is a SceneError naming ``--path``)."""
    if _checked(path, "--path", scene.file) != "auto":
        return Choice(path)
    folder, name = _folder(), kind(scene)
    if (folder / f"{name}.built").is_file():
        return Choice("compiled", auto=True)
    failed = folder / f"{name}.failed"
    if failed.is_file():
        return Choice("interpreted", failed=failed, auto=True)
    return Choice("interpreted", build=_buildable(scene), auto=True)


def _buildable(scene: Scene) -> bool:
    """A background process can run the scene again: it comes from a regular file."""
    return bool(scene.file) and Path(scene.file).resolve().is_file()


def _alive(pid: int) -> bool:
    """Does process ``pid`` run (POSIX; elsewhere: taken as running)?"""
    if os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's: it runs
        return True
    return True


def _stale(lock: Path, timeout: float = BUILD_TIMEOUT) -> bool:
    """Is the build that holds ``lock`` gone (its process ended without removing it, or it is ``timeout`` [s] old)?"""
    age = time.time() - lock.stat().st_mtime  # [s]
    text = lock.read_text().strip()
    if not text.isdigit():  # (its process not written yet: a build just starting)
        return age > timeout
    return not _alive(int(text)) or age > timeout


def _lock(folder: Path, name: str, timeout: float = BUILD_TIMEOUT) -> bool:
    """Take the kind's build lock (False: a build of it runs already, or the folder cannot be written)."""
    lock = folder / f"{name}.building"
    for _ in range(2):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return True
        except FileExistsError:
            try:
                if not _stale(lock, timeout):
                    return False
                lock.unlink()  # a build that died: take over
            except OSError:
                return False
        except OSError:
            return False
    return False


def _child_environment() -> dict[str, str]:
    """This process's environment with this package's folder first on PYTHONPATH: the build imports the same
    contactdyn (with ``-P``, not one in the working directory)."""
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root, *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])])
    return env


def build_in_background(scene: Scene) -> bool:
    """Start the kind's background build (False: not started, one runs already or the scene has no file)."""
    if not _buildable(scene):
        return False
    folder, name = _folder(), kind(scene)
    return _lock(folder, name) and _start(scene, folder / name)


def leaves_ahead(scene: Scene) -> bool:
    """Before a first run of ``scene`` (interpreted): start the helper that compiles its leaves from the other end
    (see the module; False: not started: one core only, one runs already, the scene has no file,
    ``$CONTACTDYN_LEAVES_AHEAD`` is 0, or it would not help: the kind's build runs, or a helper did the kind)."""
    if os.environ.get(HELPER_ENV, "").strip() == "0" or _cores() < 2 or not _buildable(scene):
        return False
    folder, name = _folder(), kind(scene)
    if (folder / f"{name}.building").exists() or (folder / f"{name}.leaves").exists():
        return False
    return _lock(folder, LEAVES_LOCK, LEAVES_TIMEOUT) and _start(scene, folder / LEAVES_LOCK, "--leaves")


def _cores() -> int:
    """The cores this process may run on: its affinity, at most a container's CPU quota (cgroup v2)."""
    affinity = getattr(os, "sched_getaffinity", None)
    cores = len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)
    try:
        quota, period = CPU_QUOTA.read_text().split()[:2]  # "max 100000" or "<quota> <period>" [µs]
        if quota != "max":
            cores = min(cores, max(1, int(quota) // int(period)))
    except (OSError, ValueError):  # (no cgroup v2 here, or a line it cannot read)
        pass
    return cores


def _start(scene: Scene, marker: Path, *options: str) -> bool:
    """Start ``python -m contactdyn.first_run [options] FILE MARKER`` detached, the scene's document on stdin; its
    lock ``MARKER.building`` (taken) then holds its process id (False, the lock given back: it could not start)."""
    lock = Path(f"{marker}.building")
    low = 0 if "--leaves" in options else getattr(subprocess, "BELOW_NORMAL_PRIORITY_CLASS", 0)  # (as main's nice)
    flags = getattr(subprocess, "DETACHED_PROCESS", 0) | getattr(subprocess, "CREATE_NEW_PROCESS_GROUP", 0) | low
    detached = {"start_new_session": True} if os.name == "posix" else {"creationflags": flags}
    try:
        child = subprocess.Popen([sys.executable, "-P", "-m", __name__, *options, str(Path(scene.file).resolve()),
                                  str(marker)], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, env=_child_environment(), **detached)
        lock.write_text(str(child.pid))
        with child.stdin:
            child.stdin.write(json.dumps(scene.document, default=str).encode())
    except OSError:
        lock.unlink(missing_ok=True)
        return False
    return True


def mark_built(scene: Scene) -> None:
    """After a run on the compiled call: the scene's kind is built (its code compiled and cached)."""
    try:
        folder, name = _folder(), kind(scene)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{name}.built").touch()
        (folder / f"{name}.failed").unlink(missing_ok=True)
    except OSError:  # an unwritable cache: the next run is interpreted again, as if never built
        pass


def build(file: str, document: dict, marker: str) -> None:
    """Run the scene (its document, read relative to ``file``) on the compiled call, for BUILD_DURATION simulated
    seconds at most (what a longer run reaches later compiles then, in the foreground); mark its kind built."""
    import warnings

    from .scene.scene_file import parse_scene
    from .simulate import simulate

    scene = parse_scene(document, None, file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate(scene, {"duration": min(scene.duration, BUILD_DURATION)}, compiled=True)
    Path(f"{marker}.built").touch()


def compile_leaves(file: str, document: dict, marker: str) -> None:
    """The helper of :func:`leaves_ahead`: the leaves the scene reaches (:func:`record_leaves`, RECORD_LIMIT at most)
    compiled last-reached first, claimed (:func:`compile_claimed`); then the kind's leaves marked done beside
    ``marker``; then its late leaves, in their order (the most worth first), each marked arrived once compiled
    (:func:`arrived`)."""
    from .numerics.twins import LATE_LEAVES, name_of
    from .scene.scene_file import parse_scene

    done = Path(marker).with_name(f"{kind(parse_scene(document, None, file))}.leaves")  # (the run's kind: no override)
    calls = record_leaves(file, document, RECORD_LIMIT)
    compile_claimed(_early(calls), backwards=True)
    done.touch()
    with contextlib.suppress(AttributeError, OSError):
        os.nice(10)  # (the late leaves only speed the run up: they wait where the run needs the core)
    late = sorted((call for call in calls if name_of(call[0]) in LATE_LEAVES),
                  key=lambda call: LATE_LEAVES.index(name_of(call[0])))  # (the most worth first)
    for leaf, types_ in late:  # each marked arrived for the run
        with _claim(leaf, types_) or contextlib.nullcontext():
            if _compile(leaf, types_):
                _arrival(leaf, types_).touch()


def _early(calls: list[tuple[Any, tuple]]) -> list[tuple[Any, tuple]]:
    """The leaves of a record, its late leaves left out (they arrive later: :func:`compile_leaves`)."""
    from .numerics.twins import LATE_LEAVES, name_of

    return [(leaf, types_) for leaf, types_ in calls if name_of(leaf) not in LATE_LEAVES]


def arrived(leaf, types_: tuple) -> bool:
    """Has the helper compiled the late leaf ``leaf`` for ``types_`` and cached it (:func:`compile_leaves`)?"""
    try:
        return _arrival(leaf, types_).is_file()
    except OSError:
        return False


def arrivals(choice: Choice):
    """Where a run's late leaves arrive from (a context): an interpreted run of the path ``auto`` loads each once a
    helper has compiled it (:func:`arrived`); any other run as it is."""
    from .numerics.twins import late_leaves

    return late_leaves(arrived) if choice.interpreted and choice.auto else contextlib.nullcontext()


def _arrival(leaf, types_: tuple) -> Path:
    """The marker of a late leaf compiled for ``types_``: beside its claim."""
    return _folder() / CLAIMS / f"{_claim_name(leaf, types_)}.arrived"


def leaves_first(scene: Scene) -> None:
    """A first run's own leaves, before it starts, beside the helper :func:`leaves_ahead` started: recorded as the
    helper records them (RUN_RECORD_LIMIT at most), compiled first-reached first, claimed (:func:`compile_claimed`).
    A failure here is left to the run, which meets it again and reports it."""
    try:
        compile_claimed(_early(record_leaves(scene.file, scene.document, RUN_RECORD_LIMIT)))
    except Exception:  # noqa: BLE001,S110 (the run reports its own error; a leaf not compiled here compiles there)
        pass


def record_leaves(file: str, document: dict, limit: float) -> list[tuple[Any, tuple]]:
    """The leaves the scene (its document, read relative to ``file``) reaches, each (numba dispatcher, argument types)
    in the order first reached: RECORD_DURATION of it interpreted with every leaf interpreted too (none compiled),
    then as much of each later phase started from the scene's start (:func:`_phase_starts`: a law of a later phase
    reaches its own leaves, ``pinv`` for one); ``limit`` [s] of wall time at most (what it recorded by then). A later
    phase that cannot start there adds nothing (the run compiles what it reaches)."""
    from .numerics.twins import RecordingTwins

    recorder = RecordingTwins(deadline=time.monotonic() + limit)
    for k, start in enumerate(_phase_starts(document)):
        if k and time.monotonic() > recorder.deadline:  # (a phase's start is checked here, its leaves as called)
            break
        try:
            _record(file, start, recorder)
        except RecordingTwins.Enough:  # (what it recorded so far: the leaves the run reaches first)
            break
        except Exception:
            if k == 0:
                raise
    return recorder.calls


def _phase_starts(document: dict) -> list[dict]:
    """The scene's document, then for each later ``[[phase]]`` a copy whose phases begin with it."""
    phases = document.get("phase")
    later = range(1, len(phases)) if isinstance(phases, list) else range(0)
    return [document, *({**document, "phase": phases[k:]} for k in later)]


def _record(file: str, document: dict, recorder) -> None:
    """RECORD_DURATION of the scene of ``document`` run interpreted on ``recorder`` (RecordingTwins); then the state
    at one time inside its last segment of nonzero length, as an event's location evaluates it (a millisecond without
    events does not)."""
    import warnings

    from .hybrid.loop import HybridRun
    from .model.system import System
    from .numerics.twins import running
    from .scene.scene_file import parse_scene

    scene = parse_scene(document, {"duration": RECORD_DURATION}, file)
    run = HybridRun(System(scene), interpreted=True, twins=recorder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run.run(time.perf_counter())
    last = next((seg for seg in reversed(run.segments) if seg.t1 > seg.t0), None)  # (not a Held end: no interpolant)
    if last is not None:
        with running(recorder):
            last.sol(0.5 * (last.t0 + last.t1))


def compile_claimed(calls: list[tuple[Any, tuple]], backwards: bool = False) -> None:
    """Compile each (numba dispatcher, argument types) of ``calls`` in order (``backwards``: the last first, as the
    helper does), each holding its claim (:func:`_claim`). One whose claim another process holds is skipped
    (backwards) or, after the others, waited for and then loaded from the cache (forwards: the run's own leaves).
    One that does not compile (or takes no new types) is left: the run that reaches it compiles it and says why."""
    held_elsewhere = []
    for leaf, types_ in reversed(calls) if backwards else calls:
        claim = _claim(leaf, types_)
        if claim is None:
            held_elsewhere.append((leaf, types_))
            continue
        with claim:
            _compile(leaf, types_)
    if backwards:  # (the helper: the run compiles those)
        return
    for leaf, types_ in held_elsewhere:
        with _claim(leaf, types_, wait=CLAIM_WAIT) or contextlib.nullcontext():  # (waited too long: compiled here)
            _compile(leaf, types_)


def _compile(leaf, types_: tuple) -> bool:
    """numba's ``leaf.compile(types_)`` (loaded from the cache where it is there); False: it failed, left to the run."""
    try:
        leaf.compile(types_)
        return True
    except Exception:  # noqa: BLE001 (nothing is lost: the run compiles it itself)
        return False


def _claim_name(leaf, types_: tuple) -> str:
    """The name of (``leaf``, ``types_``)'s claim and arrival: 16 hex digits of SHA-256 of both."""
    from .numerics.twins import name_of

    return hashlib.sha256(f"{name_of(leaf)}{types_}".encode()).hexdigest()[:16]


def _claim(leaf, types_: tuple, wait: float = 0.0):
    """The claim of compiling ``leaf`` for ``types_``: its lock file (``kinds/claims``) open and locked (``flock``,
    exclusive; released when closed, or when its process ends), to use in a ``with``; None if another process holds
    it after ``wait`` [s]. Where there are no claims (no ``fcntl``: Windows; a folder that cannot be written), a
    claim that holds nothing: each process compiles what it reaches."""
    try:
        import fcntl

        folder = _folder() / CLAIMS
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(folder / f"{_claim_name(leaf, types_)}.lock", "w")  # noqa: SIM115 (closed by the caller's with)
    except (ImportError, AttributeError, OSError):
        return contextlib.nullcontext()
    deadline = time.monotonic() + wait
    while True:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return handle
        except BlockingIOError:  # (held by another process)
            if time.monotonic() >= deadline:
                handle.close()
                return None
            time.sleep(CLAIM_POLL)
        except OSError:  # a file system that does not lock: no claims
            handle.close()
            return contextlib.nullcontext()


def main(argv: list[str] | None = None) -> int:
    """``python -m contactdyn.first_run FILE MARKER`` (the scene's document on stdin): the background build. A build
    that fails writes MARKER.failed (its error): later runs of the kind run interpreted and say why.
    ``python -m contactdyn.first_run --leaves FILE MARKER``: the leaves' helper (:func:`leaves_ahead`; its lock
    MARKER.building); it records nothing of a failure (the run it helps reports its own)."""
    args = list(sys.argv[1:] if argv is None else argv)
    helper = args[:1] == ["--leaves"]
    file, marker = args[1:3] if helper else args[:2]
    try:
        os.nice(0 if helper else 10)  # (the helper works for a run the user waits for, which may wait for its claims)
    except (AttributeError, OSError):
        pass
    try:
        document = json.loads(sys.stdin.read())
        compile_leaves(file, document, marker) if helper else build(file, document, marker)
        return 0
    except Exception as exc:  # noqa: BLE001 (any failure of the build is recorded, none raised: nobody reads it)
        if not helper:
            Path(f"{marker}.failed").write_text(f"{type(exc).__name__}: {exc}\n")
        return 1
    finally:
        lock = Path(f"{marker}.building")
        if lock.is_file() and lock.read_text().strip() in ("", str(os.getpid())):  # its own lock only
            lock.unlink(missing_ok=True)


if __name__ == "__main__":
    sys.exit(main())
