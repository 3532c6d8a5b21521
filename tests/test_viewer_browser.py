"""The viewer in a real browser (Debian's chromium via Playwright): exported HTML and the live page.

Each test seeks meshcat's animation to two times, takes screenshots (kept in the test's
temporary directory), and checks that the page ran without JavaScript errors and that
the robot's pixels differ between the two times. The robot's pixels are those that
change when everything but the robot is hidden, against a frame with the robot hidden too.
"""

from __future__ import annotations

import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

import contactdyn
from contactdyn.viewer import export_html

CHROMIUM = "/usr/bin/chromium"
# headless=True adds --headless; Playwright gives each browser its own temporary profile (--user-data-dir)
FLAGS = ["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]
TIMES = (0.05, 0.95)  #: [s] the two animation times compared; B1's tip slides 0.135 m between them
MIN_ROBOT_PIXELS = 2000  #: the robot covers far more of an 800 × 600 frame
OTHERS = ["/meshcat/environment", "/meshcat/chains", "/meshcat/forces", "/meshcat/labels", "/Grid", "/Axes"]

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


@pytest.fixture(scope="module")
def browser():
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} missing: install Debian's chromium (.ci/run does)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def b1_run(tmp_path_factory):
    result = contactdyn.simulate("b1", {"duration": 1.0, "solver.output_rate": 50})
    return result, result.save(tmp_path_factory.mktemp("run") / "b1")


def open_page(browser, url: str, ready: str, errors: list[str]):
    page = browser.new_page(viewport={"width": 800, "height": 600})
    page.on("pageerror", lambda exc: errors.append(f"page error: {exc}"))

    def console(msg):
        if msg.type == "error" and not msg.location.get("url", "").endswith("/favicon.ico"):
            errors.append(f"console error: {msg.text} at {msg.location}")

    page.on("console", console)
    page.goto(url)
    page.wait_for_function(ready, timeout=60_000)
    return page


def show(page, paths: list[str], visible: bool) -> None:
    for path in paths:
        page.evaluate("([path, visible]) => viewer.handle_command("
                      "{type: 'set_property', path: path, property: 'visible', value: visible})", [path, visible])


def frame(page, t: float, path: Path) -> np.ndarray:
    """Seek the animation to t [s of playback], render, screenshot to ``path``; RGB array."""
    from PIL import Image

    page.evaluate("t => { viewer.animator.pause(); viewer.animator.seek(t); viewer.render(); }", t)
    page.screenshot(path=str(path))
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)


def check_robot_moves(page, shots: Path, name: str) -> None:
    full = [frame(page, t, shots / f"{name}_full_{t:g}.png") for t in TIMES]
    assert np.any(full[0] != full[1])
    show(page, OTHERS, False)
    robot = [frame(page, t, shots / f"{name}_robot_{t:g}.png") for t in TIMES]
    show(page, ["/meshcat/robot"], False)
    empty = frame(page, TIMES[0], shots / f"{name}_background.png")
    masks = [np.abs(r - empty).sum(axis=2) > 30 for r in robot]
    counts = [int(m.sum()) for m in masks]
    assert min(counts) > MIN_ROBOT_PIXELS, f"robot barely visible: {counts} pixels (screenshots in {shots})"
    moved = int((masks[0] ^ masks[1]).sum())
    assert moved > 0.05 * max(counts), f"robot pixels barely differ: {moved} of {counts} (screenshots in {shots})"


@contextmanager
def html_page(browser, result, tmp_path: Path):
    """The run's exported HTML open in a page, once its scene is complete; no JavaScript error by the end."""
    html = export_html(result, tmp_path / "b1.html")
    errors: list[str] = []
    page = open_page(browser, html.as_uri(), "window.contactdyn && window.contactdyn.ready === true", errors)
    try:
        yield page
    finally:
        page.close()
    assert not errors, errors


def test_exported_html_plays_offline(browser, b1_run, tmp_path):
    with html_page(browser, b1_run[0], tmp_path) as page:
        assert page.evaluate("viewer.animator.duration") == pytest.approx(1.0)
        check_robot_moves(page, tmp_path, "html")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def read_url(proc: subprocess.Popen, timeout: float) -> str:
    """The URL `view` prints, read from its stdout within ``timeout`` seconds."""
    seen = b""
    deadline = time.monotonic() + timeout
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout.fileno(), selectors.EVENT_READ)
        while b"open http" not in seen or not seen.split(b"open ", 1)[1].count(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0 or proc.poll() is not None:
                raise AssertionError(f"`view` printed no URL within {timeout} s: {seen.decode(errors='replace')}")
            if sel.select(min(left, 0.5)):
                chunk = os.read(proc.stdout.fileno(), 4096)
                if not chunk:
                    continue
                seen += chunk
    return seen.split(b"open ", 1)[1].split(b"\n", 1)[0].decode().strip()


def test_live_page_plays(browser, b1_run, tmp_path):
    _, saved = b1_run
    port = free_port()
    code = ("import argparse, sys\nfrom contactdyn.viewer import view_command\n"
            f"sys.exit(view_command(argparse.Namespace(run={str(saved)!r}, html=None, port={port}, speed=1.0)))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)  # its own process group: the server child ends with it
    try:
        url = read_url(proc, 60.0)
        assert url == f"http://127.0.0.1:{port}/static/"
        errors: list[str] = []
        page = open_page(browser, url, "window.viewer && viewer.animator.duration > 0", errors)
        try:
            check_robot_moves(page, tmp_path, "live")
        finally:
            page.close()
        assert not errors, errors
        proc.send_signal(signal.SIGTERM)  # `view` closes its server and exits 0
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        else:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # anything left in its group
            except ProcessLookupError:
                pass
        proc.stdout.close()


# ---- the default view: tool and both force arrows on screen --------------------------------------
#: (scene, simulated [s], time shown [s]): B1 slides with 100 N; the UR5 writes pressing 5 N
DEFAULT_VIEWS = [("b1", 1.0, 0.5), ("case2_writer_ur5", 1.5, 1.2)]
MIN_PART_PIXELS = 40  #: each part covers at least this many pixels of its own colour in an 800 × 600 frame


def colour_pixels(shown: np.ndarray, hidden: np.ndarray, colour: int) -> int:
    """Pixels that change when a part is shown and then have the part's (unlit) colour."""
    rgb = np.array([(colour >> 16) & 255, (colour >> 8) & 255, colour & 255])
    changed = np.abs(shown - hidden).sum(axis=2) > 30
    return int((changed & (np.abs(shown - rgb).max(axis=2) <= 12)).sum())


@pytest.mark.parametrize("name, duration, t", DEFAULT_VIEWS)
def test_default_view_shows_the_tool_and_both_arrows(browser, tmp_path, name, duration, t):
    from contactdyn.viewer.contact_visuals import COLORS

    result = contactdyn.simulate(name, {"duration": duration, "solver.output_rate": 100})
    html = export_html(result, tmp_path / f"{name}.html")
    errors: list[str] = []
    page = open_page(browser, html.as_uri(), "window.contactdyn && window.contactdyn.ready === true", errors)
    try:
        full = frame(page, t, tmp_path / f"{name}_default.png")  # the default camera, nothing moved
        counts = {}
        for part, paths, colours in (("tool", ["/meshcat/tool"], {"tool": COLORS["tool"]}),
                                     ("arrows", ["/meshcat/forces"], {"normal": COLORS["normal"],
                                                                      "tangential": COLORS["friction"]})):
            show(page, paths, False)
            hidden = frame(page, t, tmp_path / f"{name}_without_{part}.png")
            show(page, paths, True)
            counts.update({k: colour_pixels(full, hidden, c) for k, c in colours.items()})
    finally:
        page.close()
    assert not errors, errors
    assert min(counts.values()) >= MIN_PART_PIXELS, f"{name}: pixels per part {counts} (screenshots in {tmp_path})"


def test_the_html_opens_at_the_start_and_plays_in_a_loop(browser, b1_run, tmp_path):
    """Loading takes a while; the page starts playing at t = 0 after it (not at the last frame), and loops."""
    with html_page(browser, b1_run[0], tmp_path) as page:
        assert page.evaluate("viewer.animator.playing")
        assert page.evaluate("viewer.animator.actions.every(a => a.repetitions >= 1e9)")  # loops
        page.wait_for_timeout(1500)  # past the run's 1 s: still playing (repetitions 1 would stop on the last frame)
        assert page.evaluate("viewer.animator.playing")
        assert page.evaluate("viewer.animator.actions.every(a => !a.paused)")


def _plain_screenshot(html: Path, png: Path) -> np.ndarray:
    """`chromium --headless --screenshot` of the file, no script driving it; RGB array."""
    from PIL import Image

    subprocess.run([CHROMIUM, "--headless", *FLAGS, f"--screenshot={png}", "--window-size=800,600", html.as_uri()],
                   check=True, timeout=120, capture_output=True)
    return np.asarray(Image.open(png).convert("RGB"), dtype=np.int16)


def test_a_plain_headless_screenshot_finishes_and_shows_the_robot_and_the_surface(b1_run, tmp_path):
    """The payload is inflated while the page's script runs, so the scene is drawn before the load event that
    a plain --screenshot waits for: the shot differs from the empty scene's over the robot and the surface."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} missing: install Debian's chromium (.ci/run does)")
    from contactdyn.viewer.build import build_scene
    from contactdyn.viewer.export import html_document
    from contactdyn.viewer.writer import ViewerScene

    result, _ = b1_run
    scene = build_scene(result)
    empty = ViewerScene([], scene.duration, scene.speed, scene.legend, scene.notes, scene.groups, scene.scales)
    (tmp_path / "full.html").write_text(html_document(scene))
    (tmp_path / "empty.html").write_text(html_document(empty))
    full = _plain_screenshot(tmp_path / "full.html", tmp_path / "full.png")
    bare = _plain_screenshot(tmp_path / "empty.html", tmp_path / "empty.png")
    drawn = np.abs(full - bare).sum(axis=2) > 30
    assert drawn.sum() > 2 * MIN_ROBOT_PIXELS, f"only {drawn.sum()} pixels drawn (screenshots in {tmp_path})"
