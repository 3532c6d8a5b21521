"""The meshcat viewer without a browser: scene contents against the run, HTML export, live server."""

from __future__ import annotations

import argparse
import re
import socket
import urllib.request

import numpy as np
import pytest
import umsgpack

import contactdyn
from contactdyn import ContactdynError, Result, Robot, load_result
from contactdyn.viewer import LiveViewer, build_scene, export_html, view_command
from contactdyn.viewer.export import html_payload, unpack_payload
from contactdyn.viewer.shapes import nice_ceil, nice_floor

# A cart-mounted surface with a mass in its chain: the tip strikes it (a plastic impact at
# touch) and slides with friction while the servo-driven cart moves along x.
CART_SCENE = """
name = "cart_touch"
duration = 0.1
[solver]
output_rate = 200.0
[robot]
urdf = "planar2r_b1"
gravity = [0.0, 0.0, 0.0]
tip0 = [0.45, -0.145, 0.0]
q_seed = [0.3, -1.3]
[body.cart]
mass = 20.0
axis = [1.0, 0.0, 0.0]
servo.velocity = 0.2
servo.gain = 1000.0
[contact.tip]
frame = "tip"
body = "cart"
point = [0.0, -0.15, 0.0]
normal.direction = [0.0, 1.0, 0.0]
normal.model = "chain"
normal.environment = [{k = 1e5, b = 50.0}, {m = 2.0}]
tangent.model = "friction"
tangent.directions = [[1.0, 0.0, 0.0]]
tangent.mu = 0.3
[controller]
kind = "task_pd"
kp = 2000.0
kd = 100.0
[[phase]]
name = "press"
[phase.reference]
start = [0.45, -0.17, 0.0]
"""


@pytest.fixture(scope="module")
def b1_run(tmp_path_factory):
    """B1, 0.2 s at 100 Hz, saved and loaded back as `contactdyn view` reads it."""
    path = contactdyn.simulate("b1", {"duration": 0.2, "solver.output_rate": 100}).save(
        tmp_path_factory.mktemp("b1") / "run")
    return path, load_result(path)


@pytest.fixture(scope="module")
def cart_run(tmp_path_factory):
    scene = tmp_path_factory.mktemp("cart") / "cart.toml"
    scene.write_text(CART_SCENE)
    return contactdyn.simulate(scene)


def commands_at(scene, path: str) -> list[dict]:
    return [c for c in scene.commands if c["path"] == path]


def clip(scene, path: str) -> dict[str, dict]:
    """The animation tracks of the node at ``path``, by property."""
    animation = scene.commands[-1]
    for a in animation["animations"]:
        if a["path"] == path:
            return {t["name"][1:]: t for t in a["clip"]["tracks"]}
    return {}


def values(track: dict) -> np.ndarray:
    return np.array([k["value"] for k in track["keys"]])


def positions(scene, path: str) -> np.ndarray:
    """(N, 3) the node's positions [m]: its animation track, or (1, 3) its static transform (a node that never
    moves, e.g. a gripper's pad holding a part, gets no track)."""
    track = clip(scene, path).get("position")
    if track:
        return values(track)
    matrix = next(c["matrix"] for c in scene.commands if c.get("type") == "set_transform" and c["path"] == path)
    return np.array(matrix, float).reshape(4, 4).T[:3, 3][None, :]


def test_robot_visuals_follow_the_simulated_tip(b1_run):
    """The tip's marker sphere, placed by the viewer from q, sits on the simulated tip channel."""
    _, result = b1_run
    scene = build_scene(result)
    assert scene.commands[-1]["type"] == "set_animation"
    robot = Robot.load(result.meta["robot"])
    names = [g.name for g in robot.visual_model.geometryObjects]
    assert len(names) == 4
    drawn = {c["path"].split("/")[3] for c in scene.commands if c["type"] == "set_object"
             and c["path"].startswith("/meshcat/robot/")}
    assert drawn == set(names) and not scene.notes  # every visual has an object
    tip = clip(scene, "/meshcat/robot/tip_0")
    np.testing.assert_allclose(values(tip["position"]), result["tip"], atol=1e-12)
    np.testing.assert_allclose([k["time"] for k in tip["position"]["keys"]], result["t"])
    # the base never moves: a static transform, no track
    assert not clip(scene, "/meshcat/robot/base_0")
    assert commands_at(scene, "/meshcat/robot/base_0")[0]["type"] == "set_transform"
    # the links' orientations are the simulated ones: link 1 turns by q1 about z
    quat = values(clip(scene, "/meshcat/robot/link1_0")["quaternion"])  # [x, y, z, w]
    angle = 2 * np.arctan2(quat[:, 2], quat[:, 3])
    np.testing.assert_allclose(np.unwrap(angle), result["q"][:, 0], atol=1e-12)


def test_playback_speed_and_thinned_frames(b1_run):
    _, result = b1_run
    fast = build_scene(result, speed=2.0, max_frames=5)
    animation = fast.commands[-1]
    assert all(a["clip"]["fps"] == 2.0 for a in animation["animations"])  # keys [s] / fps = 0.5 × real time
    times = [k["time"] for k in clip(fast, "/meshcat/robot/tip_0")["position"]["keys"]]
    assert len(times) <= 6 and times[0] == 0.0 and times[-1] == pytest.approx(result["t"][-1])
    assert fast.duration == pytest.approx(0.2) and fast.speed == 2.0


def test_chain_gauge_magnifies_the_compression(b1_run):
    """B1's chain ground —[k, b]— m: the mass node stands ℓ − S·x above the anchor."""
    _, result = b1_run
    scene = build_scene(result)
    x = result["stage.tip.n.env1.x"]
    S = float(re.search(r"magnified ×([0-9.e+]+)", " ".join(scene.legend)).group(1))
    assert S == scene.scales["magnification"]
    objects = {c["path"]: c["object"] for c in scene.commands if c["type"] == "set_object"}
    nodes = [p for p in objects if "/chains/tip_n/node" in p]
    assert len(nodes) == 2  # the mass (the surface node) and the tip
    mass = next(p for p in nodes if objects[p]["geometries"][0]["type"] == "BoxGeometry")
    mass_y = values(clip(scene, mass)["position"])[:, 1]
    length = values(clip(scene, "/meshcat/chains/tip_n/env1")["scale"])[:, 1]
    np.testing.assert_allclose(mass_y, length, atol=1e-12)  # the coil spans anchor → mass
    rest = mass_y + S * x
    np.testing.assert_allclose(rest, rest[0], atol=1e-12)  # y = ℓ − S·x with one ℓ
    ell = rest[0]
    assert ell == pytest.approx(scene.scales["stage_length"], rel=1e-12)
    # S is the largest 1-2-5 number keeping every compression within 60 % of ℓ
    assert S == nice_floor(S) and S * np.max(np.abs(x)) <= 0.6 * ell * (1 + 1e-12)
    assert nice_ceil(1.01 * S) * np.max(np.abs(x)) > 0.6 * ell


def test_force_arrows_end_at_the_tip_with_the_stated_scale(b1_run):
    from contactdyn.viewer.contact_visuals import ARROW_RADIUS

    _, result = b1_run
    scene = build_scene(result)
    line = next(s for s in scene.legend if s.startswith("force arrows"))
    metres, newtons, tangential = re.search(r": ([0-9.e+-]+) m = ([0-9.e+-]+) N normal \(red\), ([0-9.e+-]+) N "
                                            r"tangential", line).groups()
    metres, newtons, tangential = float(metres), float(newtons), float(tangential)
    assert metres / newtons == pytest.approx(scene.scales["arrow"], rel=1e-2)  # the legend rounds to 3 digits
    assert metres / tangential == pytest.approx(scene.scales["arrow_tangent"], rel=1e-2)
    unit = scene.scales["arrow"] * newtons  # [m] one scale step, exactly
    arrow = clip(scene, "/meshcat/forces/tip_normal")
    origin = values(arrow["position"])
    shaft = values(clip(scene, "/meshcat/forces/tip_normal/shaft")["scale"])[:, 1]
    head = clip(scene, "/meshcat/forces/tip_normal/head")
    head_tip = values(head["position"])[:, 1] + values(head["scale"])[:, 1] * 4 * ARROW_RADIUS * unit  # 4 radii
    F_n = result["contact.tip.F_n"]
    tip = result["tip"]
    # the arrow's origin is the tip minus the force vector, scaled: F_n along +y (the normal)
    np.testing.assert_allclose(tip - origin, np.outer(F_n * scene.scales["arrow"], [0.0, 1.0, 0.0]), atol=1e-9)
    np.testing.assert_allclose(head_tip, F_n * scene.scales["arrow"], atol=1e-9)  # the head touches the tip
    big = F_n > 0.5 * F_n.max()
    assert np.all(shaft[big] > 0) and np.all(shaft[big] < F_n[big] * scene.scales["arrow"])
    # each scale is the 1-2-5 number putting the 90th percentile of its forces at <= 3 steps
    F_t = np.abs(result["contact.tip.F_f"][:, 0])
    for per, F in ((newtons, F_n), (tangential, F_t)):
        assert per == nice_ceil(per) and 3 * nice_floor(0.99 * per) < np.percentile(F, 90) <= 3 * per
    assert np.percentile(F_t, 90) < np.percentile(F_n, 90) / 1.5  # why the tangential arrows have their own scale


def test_tool_ball_and_trace_follow_the_tip(b1_run):
    _, result = b1_run
    scene = build_scene(result)
    ball = values(clip(scene, "/meshcat/tool/tip/ball")["position"])
    np.testing.assert_allclose(ball, result["tip"], atol=1e-12)
    trace = next(c for c in scene.commands if c["type"] == "set_object" and c["path"] == "/meshcat/tool/tip/trace")
    packed = trace["object"]["geometries"][0]["data"]["attributes"]["position"]["array"]  # a Float32Array
    points = np.frombuffer(packed.data, np.float32).reshape(-1, 3)
    np.testing.assert_allclose(points, result["tip"], atol=1e-6)  # float32


def _in_view(scene, points: np.ndarray, margin: float = 1.0) -> np.ndarray:
    """Whether world points, as drawn (the scene is shifted), fall inside the default camera's frustum."""
    from contactdyn.viewer.camera import ASPECT, FOV

    eye = next(c for c in scene.commands if c["type"] == "set_property" and c["path"].startswith("/Cameras"))["value"]
    eye = np.array([eye[0], -eye[2], eye[1]])  # meshcat's y-up frame -> world
    d = eye / np.linalg.norm(eye)
    right = np.cross([0.0, 0.0, 1.0], d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    shift = np.array(commands_at(scene, "/meshcat")[0]["matrix"]).reshape(4, 4).T[:3, 3]
    rel = np.atleast_2d(points) + shift - eye
    depth = -rel @ d
    t = np.tan(FOV / 2) / margin
    return (depth > 0) & (np.abs(rel @ up) < t * depth) & (np.abs(rel @ right) < ASPECT * t * depth)


def test_default_camera_looks_along_the_surface_from_the_robot_side(b1_run):
    """B1: normal +y, slide x: the camera looks along ±z (the surface's second tangent), raised towards +y."""
    from contactdyn.viewer.camera import ELEVATION

    _, result = b1_run
    scene = build_scene(result)
    eye = next(c for c in scene.commands if c["type"] == "set_property" and c["path"].startswith("/Cameras"))["value"]
    eye = np.array([eye[0], -eye[2], eye[1]])
    d = eye / np.linalg.norm(eye)
    assert abs(d[0]) < 1e-12 and abs(abs(d[2]) - np.cos(ELEVATION)) < 1e-12
    assert abs(abs(d[1]) - np.sin(ELEVATION)) < 1e-12
    right = np.cross([0.0, 0.0, 1.0], d)
    up = np.cross(d, right / np.linalg.norm(right))
    assert up @ [0.0, 1.0, 0.0] > 0.9  # the normal points up the screen
    assert _in_view(scene, result["tip"], margin=1.5).all()


SIMS = sorted(p.stem for p in contactdyn.scene.scene_file.sims_dir().glob("*.toml"))


@pytest.mark.parametrize("name", SIMS)
def test_every_scene_shows_its_tool_and_arrows_in_the_default_view(name):
    """The tool's path and each arrow's both ends lie inside the default view, away from its edges."""
    result = contactdyn.simulate(name, {"duration": 0.3, "solver.output_rate": 50})
    scene = build_scene(result)
    for c in result.meta["contacts"]:
        tool = positions(scene, f"/meshcat/tool/{c}/ball")
        assert _in_view(scene, tool, margin=1.2).all(), f"{name}: the tool leaves the view"
        for kind in ("normal", "tangent"):
            arrow = clip(scene, f"/meshcat/forces/{c}_{kind}")
            if arrow:
                tails = values(arrow["position"])
                assert _in_view(scene, tails, margin=1.05).all(), f"{name}: the {kind} arrow leaves the view"


def test_cart_moves_impact_marked_and_friction_drawn(cart_run):
    result = cart_run
    assert len(result.impacts) == 1
    scene = build_scene(result)
    cart = clip(scene, "/meshcat/environment/cart")
    np.testing.assert_allclose(values(cart["position"])[:, 0], result["body.cart.x"], atol=1e-12)
    assert np.ptp(result["body.cart.x"]) > 1e-3
    marker = clip(scene, "/meshcat/environment/cart/impact0")["scale"]
    t_imp = result.impacts[0]["t"]
    times, size = np.array([k["time"] for k in marker["keys"]]), values(marker)[:, 0]
    assert np.all(np.diff(times) > 0)
    assert np.interp(0.5 * t_imp, times, size) < 1e-3 and np.interp(t_imp, times, size) == 1.0
    assert any("impact on tip at t = " in s for s in scene.legend)
    friction = clip(scene, "/meshcat/forces/tip_tangent")
    assert friction and values(clip(scene, "/meshcat/forces/tip_tangent/shaft")["scale"])[:, 1].max() > 1e-3
    # the impact marker sits where the tip was at impact, in the cart's frame
    place = commands_at(scene, "/meshcat/environment/cart/impact0")
    p = np.array(place[-1]["matrix"]).reshape(4, 4).T[:3, 3]
    tip_x = np.interp(t_imp, result["t"], result["tip"][:, 0]) - np.interp(t_imp, result["t"], result["body.cart.x"])
    assert p[0] == pytest.approx(tip_x, abs=2e-3) and p[1] == pytest.approx(-0.15, abs=1e-3)


def test_html_stores_each_mesh_once_compressed(tmp_path):
    """A UR5 whose meshes appear twice (two identical frames) still carries each mesh file once, gzip'd."""
    ur5 = Robot.load("ur5")
    q = np.zeros((2, ur5.nq))
    scene = build_scene(Result({"t": np.array([0.0, 1.0]), "q": q}, meta={"robot": "ur5", "name": "ur5"}))
    doubled = type(scene)(scene.commands[:-1] + scene.commands, scene.duration, scene.speed, scene.legend)
    meshes = [c for c in scene.commands if c["type"] == "set_object" and c["object"]["object"]["type"] ==
              "_meshfile_object"]
    raw = sum(len(m["object"]["object"]["data"]) for m in meshes)  # [bytes] the Collada text, once
    once, twice = export_html(scene, tmp_path / "a.html"), export_html(doubled, tmp_path / "b.html")
    assert len(html_payload(twice.read_text())) < len(html_payload(once.read_text())) + 0.02 * raw
    assert len(html_payload(once.read_text())) < 0.35 * raw  # gzip'd text, not base64 of msgpack (1.33 × raw)
    assert [umsgpack.packb(c) for c in unpack_payload(html_payload(twice.read_text()))] == doubled.packed()


def test_locked_joints_and_example_robot_meshes():
    """A reduced robot (locked joints) and example-robot-data meshes: dae keeps its colors, stl is colored."""
    t = np.linspace(0.0, 0.1, 3)
    locked = Result({"t": t, "q": np.outer(t, [1.0])}, scene={}, meta={"robot": "cylindrical3", "name": "c3"})
    with pytest.raises(ContactdynError, match="channel q has 1 columns but robot .* has 3 active joints"):
        build_scene(locked)
    doc = {"duration": 0.1, "robot": {"urdf": "cylindrical3", "active_joints": ["q3"]},
           "controller": {"kind": "task_pd"}}
    scene = build_scene(Result({"t": t, "q": np.outer(t, [1.0])}, scene=doc, meta={"name": "c3"}))
    assert scene.commands[-1]["animations"]
    ur5 = Robot.load("ur5")
    q = np.zeros((2, ur5.nq))
    q[1, 0] = 1.0
    scene = build_scene(Result({"t": np.array([0.0, 1.0]), "q": q}, meta={"robot": "ur5", "name": "ur5"}))
    meshes = [c["object"]["object"] for c in scene.commands if c["type"] == "set_object"
              and c["object"]["object"]["type"] == "_meshfile_object"]
    assert len(meshes) == ur5.visual_model.ngeoms and all(m["format"] == "dae" for m in meshes)
    so100 = Robot.load("so100")
    scene = build_scene(Result({"t": np.array([0.0, 1.0]), "q": np.zeros((2, so100.nq))},
                               meta={"robot": "so100", "name": "so100"}))
    stl = [c["object"]["geometries"][0] for c in scene.commands if c["type"] == "set_object"
           and c["object"].get("geometries") and c["object"]["geometries"][0].get("format") == "stl"]
    assert len(stl) == so100.visual_model.ngeoms
    assert isinstance(stl[0]["data"], umsgpack.Ext) and len(stl[0]["data"].data) > 1000


def test_export_html_is_self_contained_and_replays_the_commands(b1_run, tmp_path):
    _, result = b1_run
    scene = build_scene(result)
    out = export_html(scene, tmp_path / "b1.html")
    text = out.read_text()
    assert "MeshCat.Viewer" in text and "<script src" not in text  # meshcat's JavaScript is inline
    decoded = unpack_payload(html_payload(text))
    assert [umsgpack.packb(c) for c in decoded] == scene.packed()  # every command, bit for bit
    assert decoded[-1]["animations"][0]["path"] == scene.commands[-1]["animations"][0]["path"]
    assert "magnified ×" in text  # the legend overlay
    again = export_html(result, tmp_path / "again.html", speed=0.5)
    assert '"speed": 0.5' in again.read_text()


def test_view_command_exports_and_reports_bad_input(b1_run, tmp_path, capsys):
    path, _ = b1_run
    args = argparse.Namespace(run=str(path), html=str(tmp_path / "v.html"), port=None, speed=1.0)
    assert view_command(args) == 0
    assert (tmp_path / "v.html").stat().st_size > 100_000
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(ContactdynError, match="not a saved run"):
        view_command(argparse.Namespace(run=str(tmp_path / "nothing"), html=None, port=None, speed=1.0))
    with pytest.raises(ContactdynError, match="speed must be a number > 0"):
        view_command(argparse.Namespace(run=str(path), html=str(tmp_path / "w.html"), port=None, speed=0.0))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.timeout(60)
def test_live_server_holds_the_scene(b1_run):
    """The server serves meshcat's page and keeps our commands for browsers that connect later."""
    _, result = b1_run
    scene = build_scene(result)
    with LiveViewer(port=free_port(), zmq_url=f"tcp://127.0.0.1:{free_port()}") as live:
        live.show(scene)
        page = urllib.request.urlopen(live.url, timeout=10).read().decode()
        assert "MeshCat.Viewer" in page
        live.socket.send(b"get_scene")
        static = live.socket.recv().decode()
        kinds = {kind: [c["path"] for c in scene.commands if c["type"] == kind] for kind in
                 ("set_object", "set_transform", "set_property")}
        expected = len(set(kinds["set_object"])) + len(set(kinds["set_transform"])) + len(kinds["set_property"]) + 1
        assert static.count("fetch(\"data:") == expected  # each node's object, transform, properties; the animation
        proc = live.proc
    assert proc.poll() is not None  # closed with the context


@pytest.mark.timeout(60)
def test_live_server_port_in_use_is_a_clear_error():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ContactdynError, match="meshcat server did not start: exit code 1: .*(in use|Errno)"):
            LiveViewer(port=port)


def test_nice_numbers():
    assert [nice_floor(x) for x in (0.7, 1.0, 3.3, 19.2, 0.049)] == [0.5, 1.0, 2.0, 10.0, 0.02]
    assert [nice_ceil(x) for x in (0.7, 1.0, 3.3, 19.2, 0.049)] == [1.0, 1.0, 5.0, 20.0, 0.05]


def listening(pid: int) -> set[tuple[str, int]]:
    """(address, port) of every TCP socket in LISTEN state that process ``pid`` holds, from /proc."""
    import ipaddress
    import os
    from pathlib import Path

    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        target = os.readlink(fd)
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = set()
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "0A" or fields[9] not in inodes:  # 0A: TCP_LISTEN
                continue
            addr, port = fields[1].split(":")
            raw = bytes.fromhex(addr)
            raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))  # host-order 32-bit words
            found.add((str(ipaddress.ip_address(raw)), int(port, 16)))
    return found


@pytest.mark.timeout(60)
def test_live_server_listens_on_loopback_only():
    with LiveViewer() as live:
        addresses = listening(live.proc.pid)
        web_port = int(live.url.split(":")[2].split("/")[0])
        zmq_port = int(live.zmq_url.rsplit(":", 1)[1])
    assert {port for _, port in addresses} == {web_port, zmq_port}
    assert {addr for addr, _ in addresses} == {"127.0.0.1"}


@pytest.mark.timeout(60)
def test_view_on_another_host_warns(b1_run, capsys, monkeypatch):
    import contactdyn.viewer as viewer

    class Stop(Exception):
        pass

    def probe(**kwargs):
        with LiveViewer(**kwargs) as live:
            hosts = {addr for addr, _ in listening(live.proc.pid)}
        assert hosts == {"127.0.0.2"}
        raise Stop

    monkeypatch.setattr(viewer, "LiveViewer", probe)
    with pytest.raises(Stop):
        viewer.view_result(b1_run[1], argparse.Namespace(html=None, port=None, speed=1.0, host="127.0.0.2"))
    assert "warning: the viewer listens on 127.0.0.2" in capsys.readouterr().err


def test_a_body_from_a_urdf_is_drawn_with_its_visuals_and_its_path():
    """pinch_hold's part (sims/part_cylinder.urdf): its cylinder under /meshcat/bodies/part, placed where the body
    is (its coordinate along z), and no box drawn for it under its surfaces; opened, the fingers let it fall and
    the cylinder's track follows the body's coordinate."""
    result = contactdyn.simulate("pinch_hold", {"duration": 0.2, "solver.output_rate": 50, "robot.q0": [0.0, 0.0],
                                                "phase.0.reference.start": [0.0, 0.0]})
    scene = build_scene(result)
    paths = [c["path"] for c in scene.commands if c["type"] == "set_object"]
    part = [p for p in paths if p.startswith("/meshcat/bodies/part/")]
    assert part and not [p for p in paths if "/cart_" in p]
    track = next(clip(scene, p.rsplit("/", 1)[0]) for p in part)["position"]
    assert values(track)[:, 2] == pytest.approx(result["body.part.x"], abs=1e-6)  # (float32 in the scene)
    assert result["body.part.x"][-1] < -0.1  # it fell ~0.2 m in 0.2 s


def test_a_body_with_two_coordinates_is_drawn_moving_with_both_and_its_path_traced():
    """push_box's box (sims/box_xz.urdf, x and z slides): its cube's track follows both coordinates, its path is a
    trace under /meshcat/bodies, and its bottom's contact point (a body's point touching) is drawn where it is."""
    result = contactdyn.simulate("push_box", {"solver.output_rate": 50})
    scene = build_scene(result)
    paths = [c["path"] for c in scene.commands if c["type"] == "set_object"]
    box = [p for p in paths if p.startswith("/meshcat/bodies/box/")]
    assert box and "/meshcat/bodies/box_path" in paths
    track = values(next(clip(scene, p.rsplit("/", 1)[0]) for p in box)["position"])
    assert track[:, 0] == pytest.approx(0.3 + result["body.box.slide.x"], abs=1e-6)  # (float32 in the scene)
    assert track[:, 2] == pytest.approx(0.05 + result["body.box.lift.x"], abs=1e-6)  # (its visual 50 mm up)
    assert np.ptp(result["body.box.slide.x"]) > 0.15
    floor = values(clip(scene, "/meshcat/tool/floor/ball")["position"])
    assert floor[:, 0] == pytest.approx(0.3 + result["body.box.slide.x"], abs=1e-6)
