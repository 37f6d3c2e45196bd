"""The visual geometry of robots drawn: boxes, cylinders and spheres made of triangles in their
link frames; the UR5's mesh files (example-robot-data, COLLADA) read with trimesh, in the link
frame and simplified to a bounded triangle count; an unreadable mesh as a one-line warning and
a stick figure; the HTML viewer (format 2) drawing a red box where it projects, checked in a
real headless Chromium, and the UR5's page without script errors; the GIF with the surfaces.
Motions are given as trajectories written here (no simulation) to keep the tests quick."""

from __future__ import annotations

import functools
import html
import importlib
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.spatial import ConvexHull

import cmbs
from cmbs import animate as animate_module
from cmbs.animate import animate
from cmbs.cli import main
from cmbs.errors import CmbsWarning
from cmbs.surfaces import GREY, SEGMENTS, TRIANGLES, link_surfaces
from cmbs.trajectory import Trajectory
from helpers import example_robots
from test_viewer import browser, chromium, embedded  # noqa: F401  (browser: the fixture)

UR5 = None if example_robots() is None else example_robots() / "ur_description/urdf/ur5_robot.urdf"
needs_ur5 = pytest.mark.skipif(UR5 is None, reason="needs example-robot-data (the UR5 URDF)")
INERTIAL = '<inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>'
#: one link turning about z, carrying a red box (its centre 0.3 m out along x, 0.2 m up), a
#: green cylinder and a sphere without colour
SHAPES = f"""<robot name="shapes">
  <link name="base"/>
  <link name="arm">{INERTIAL}
    <visual><origin xyz="0.3 0 0.2" rpy="0 0 0.5"/><geometry><box size="0.2 0.1 0.05"/></geometry>
      <material name="red"><color rgba="1 0 0 1"/></material></visual>
    <visual><origin xyz="0 0 0.1" rpy="1.5707963267948966 0 0"/>
      <geometry><cylinder radius="0.03" length="0.2"/></geometry>
      <material name="green"><color rgba="0 1 0 1"/></material></visual>
    <visual><origin xyz="0 0.1 0"/><geometry><sphere radius="0.05"/></geometry></visual>
  </link>
  <joint name="turn" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <origin xyz="0 0 0.1"/></joint>
</robot>
"""
RED = (255, 0, 0)


@pytest.fixture(scope="module")
def shapes(tmp_path_factory) -> cmbs.Model:
    path = tmp_path_factory.mktemp("shapes") / "shapes.urdf"
    path.write_text(SHAPES)
    return cmbs.load(path)


def still(model: cmbs.Model, q: np.ndarray, t_end: float = 0.1) -> Trajectory:
    """The model held at ``q`` from 0 to ``t_end``."""
    rows = np.array([q, q], dtype=float)
    return Trajectory(np.array([0.0, t_end]), rows, np.zeros_like(rows), np.zeros_like(rows), model.coordinate_names)


def placement(xyz, yaw=0.0, roll=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Rotation Rz(yaw) Rx(roll) and translation xyz."""
    c, s, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]), \
        np.array(xyz, dtype=float)


# ---------------------------------------------------------------- triangles
def test_boxes_cylinders_and_spheres_are_triangles_in_the_link_frame(shapes):
    """The box's 8 corners, the cylinder's rims at its radius from its axis and ends at ±l/2,
    the sphere's vertices at its radius, each placed by its origin; 12, 4 x SEGMENTS and
    2 x SEGMENTS x (SEGMENTS / 2 - 1) triangles over all their vertices; colours the URDF's,
    else grey."""
    box, cylinder, sphere = link_surfaces(shapes)
    assert [surface.link for surface in (box, cylinder, sphere)] == ["arm"] * 3
    assert (box.colour, cylinder.colour, sphere.colour) == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), GREY)
    assert [len(s.triangles) for s in (box, cylinder, sphere)] == [12, 4 * SEGMENTS, 2 * SEGMENTS * (SEGMENTS // 2 - 1)]
    for surface in (box, cylinder, sphere):
        assert np.array_equal(np.unique(surface.triangles), np.arange(len(surface.vertices)))
    R, t = placement((0.3, 0, 0.2), yaw=0.5)
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.05, 0.05) for z in (-0.025, 0.025)])
    assert np.allclose(np.sort(box.vertices, axis=0), np.sort(corners @ R.T + t, axis=0), rtol=0, atol=1e-15)
    R, t = placement((0, 0, 0.1), roll=np.pi / 2)
    local = (cylinder.vertices - t) @ R                    # back in the cylinder's frame: axis z
    radial = np.hypot(local[:, 0], local[:, 1])
    rims = radial > 1e-9
    assert np.allclose(np.abs(local[:, 2]), 0.1, rtol=0, atol=1e-15)
    assert np.allclose(radial[rims], 0.03, rtol=0, atol=1e-15)
    assert rims.sum() == 2 * SEGMENTS and len(local) == 2 * SEGMENTS + 2         # and the caps' centres
    assert np.allclose(np.linalg.norm(sphere.vertices - [0, 0.1, 0], axis=1), 0.05, rtol=0, atol=1e-15)


# ---------------------------------------------------------------- meshes
@needs_ur5
def test_the_ur5_meshes_are_read_in_the_link_frames_and_bounded():
    """Every UR5 link with a visual mesh (COLLADA) gets surfaces of at most TRIANGLES triangles
    whose box lies inside the box of trimesh's own reading of the file, within 1 cm of it; with
    a budget above the file's triangle count the vertices are the file's own."""
    import trimesh

    model = cmbs.load(UR5)
    surfaces = link_surfaces(model)
    visuals = model.parameters["visuals"]
    assert {surface.link for surface in surfaces} == set(visuals) and len(visuals) == 7
    for link, (visual,) in visuals.items():
        mine = np.concatenate([s.vertices for s in surfaces if s.link == link])
        count = sum(len(s.triangles) for s in surfaces if s.link == link)
        theirs = trimesh.load(visual.filename, force="mesh")
        assert visual.filename.endswith(".dae") and np.array_equal(visual.origin, np.eye(4))
        assert 0.5 * TRIANGLES < count <= TRIANGLES < len(theirs.faces)
        low, high = theirs.bounds
        assert np.all(mine.min(axis=0) >= low - 1e-12) and np.all(mine.max(axis=0) <= high + 1e-12)
        assert np.abs(mine.min(axis=0) - low).max() < 0.01 and np.abs(mine.max(axis=0) - high).max() < 0.01
    whole = link_surfaces(model, budget=10 ** 6)
    wrist = np.concatenate([s.vertices for s in whole if s.link == "wrist_3_link"])
    reference = trimesh.load(visuals["wrist_3_link"][0].filename, force="mesh")
    assert sum(len(s.triangles) for s in whole if s.link == "wrist_3_link") == len(reference.faces)
    assert np.array_equal(np.unique(wrist, axis=0), np.unique(reference.vertices, axis=0))


@needs_ur5
def test_a_mesh_is_scaled_then_placed_by_its_origin(tmp_path):
    """The UR5's wrist mesh with scale (0.5, 2, 1) at xyz (0.1, -0.2, 0.3): the box of trimesh's
    reading scaled, then moved."""
    import trimesh

    wrist = cmbs.load(UR5).parameters["visuals"]["wrist_3_link"][0].filename
    path = tmp_path / "scaled.urdf"
    path.write_text(SHAPES.replace('<box size="0.2 0.1 0.05"/>', f'<mesh filename="{wrist}" scale="0.5 2 1"/>')
                    .replace('<origin xyz="0.3 0 0.2" rpy="0 0 0.5"/>', '<origin xyz="0.1 -0.2 0.3"/>'))
    surface = link_surfaces(cmbs.load(path), budget=10 ** 6)
    mesh = np.concatenate([s.vertices for s in surface if s.colour == (1.0, 0.0, 0.0)])
    low, high = trimesh.load(wrist, force="mesh").bounds * [0.5, 2.0, 1.0] + [0.1, -0.2, 0.3]
    assert np.allclose(mesh.min(axis=0), low, rtol=0, atol=1e-12) and np.allclose(mesh.max(axis=0), high, atol=1e-12)


def test_an_unreadable_mesh_is_a_warning_and_a_stick_figure(tmp_path):
    """A mesh file trimesh cannot read (broken COLLADA), one without triangles, a missing one: a
    CmbsWarning naming the link and the file each, and those links get no surfaces (the others
    keep theirs)."""
    (tmp_path / "broken.dae").write_text("<COLLADA><not closed")
    (tmp_path / "empty.stl").write_bytes(b"\x00\x01 not a mesh")
    path = tmp_path / "broken.urdf"
    text = SHAPES.replace('<sphere radius="0.05"/>', '<mesh filename="missing.stl"/>') \
        .replace('<link name="base"/>', '<link name="base"><visual><geometry><mesh filename="broken.dae"/>'
                                        '</geometry></visual></link>') \
        .replace("</robot>", '<link name="tip"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
                             '<joint name="tip" type="fixed"><parent link="arm"/><child link="tip"/></joint></robot>')
    for urdf, problem in ((text, r"cannot read mesh {folder}/broken\.dae \(.+\)"),
                          (text.replace("broken.dae", "empty.stl"), r"mesh {folder}/empty\.stl has no triangles")):
        path.write_text(urdf)
        model = cmbs.load(path)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert [surface.link for surface in link_surfaces(model)] == ["tip"]
        messages = [str(warning.message) for warning in caught if warning.category is CmbsWarning]
        assert len(messages) == 2 and len(caught) == 2
        assert re.fullmatch(re.escape(f"{path}: link 'base': ") + problem.format(folder=re.escape(str(tmp_path)))
                            + "; the link is drawn as a stick figure", messages[0]), messages[0]
        assert messages[1] == f"{path}: link 'arm': mesh missing.stl: no such file; the link is drawn as a stick figure"


def test_the_command_line_warns_in_one_line(tmp_path, capsys, monkeypatch):
    """`cmbs simulate --animate` says so in one line and writes the viewer of the stick figure
    (its run in the Python loop: no compiled loop to build for this test)."""
    simulation = importlib.import_module("cmbs.simulate")
    monkeypatch.setattr(simulation, "simulate", functools.partial(simulation.simulate, compiled=False))
    path = tmp_path / "missing.urdf"
    path.write_text(SHAPES.replace('<sphere radius="0.05"/>', '<mesh filename="missing.stl"/>'))
    page = tmp_path / "missing.html"
    assert main(["simulate", str(path), "--t-end", "0.02", "--dt", "0.01", "--integrator", "dop853",
                 "--animate", str(page)]) == 0
    err = capsys.readouterr().err
    assert err == f"cmbs: warning: {path}: link 'arm': mesh missing.stl: no such file; the link is drawn as a stick " \
                  "figure\n"
    assert embedded(page)["format"] == "cmbs-viewer 1" and "surfaces" not in embedded(page)


# ---------------------------------------------------------------- the viewer
def test_the_viewer_file_has_the_surfaces_and_the_link_rotations(shapes, tmp_path):
    """Format 2: the surfaces once, in link coordinates (integers of the unit), and per frame
    the quaternion of the turning link (to 1e-5)."""
    q = np.linspace(0.0, 1.0, 11)[:, None]
    run = Trajectory(np.linspace(0.0, 1.0, 11), q, np.zeros_like(q), np.zeros_like(q), ("turn",))
    data = embedded(animate(shapes, run, tmp_path / "shapes.html", fps=10))
    assert data["format"] == "cmbs-viewer 2" and data["turning"] == [data["points"].index("arm")]
    surfaces = link_surfaces(shapes)
    assert [s["link"] for s in data["surfaces"]] == [data["points"].index("arm")] * 3
    assert [s["colour"] for s in data["surfaces"]] == [[255, 0, 0], [0, 255, 0], [153, 153, 153]]
    for mine, theirs in zip(data["surfaces"], surfaces):
        assert mine["triangles"] == theirs.triangles.ravel().tolist()
        vertices = np.array(mine["vertices"]).reshape(-1, 3) * data["unit"]
        assert np.abs(vertices - theirs.vertices).max() <= 0.5 * data["unit"] + 1e-15
    angles = np.array(data["times"])                     # turned by q = t about z
    expected = np.column_stack([np.cos(angles / 2), 0 * angles, 0 * angles, np.sin(angles / 2)])
    assert np.abs(np.array(data["rotations"]) * data["quaternionUnit"] - expected).max() <= 0.5e-5 + 1e-12


def project(points: np.ndarray, data: dict, corners_of_view: np.ndarray, width: int, height: int) -> np.ndarray:
    """Screen (x, y) of ``points`` by the viewer's home camera (src/cmbs/viewer.html, written out
    again here): it orbits the centre of the box around ``corners_of_view`` (the link origins and
    the surfaces at every frame) at yaw -60° from the first world axis across "up" and pitch
    π/7, at 1.08 r / sin(17.5°) (r half the box's diagonal), 35° field of view."""
    up = np.array(data["up"], dtype=float)
    axes = np.eye(3)
    across1 = axes[int(np.argmin(np.abs(axes @ up)))]
    across2 = np.cross(up, across1)
    low, high = corners_of_view.min(axis=0), corners_of_view.max(axis=0)
    centre, radius = (low + high) / 2, np.linalg.norm(high - low) / 2
    fov, yaw, pitch = np.radians(35), -np.pi / 3, np.pi / 7
    direction = np.cos(pitch) * (np.cos(yaw) * across1 + np.sin(yaw) * across2) + np.sin(pitch) * up
    eye = centre + direction * 1.08 * radius / np.sin(fov / 2)
    forward = -direction
    right = np.cross(forward, up) / np.linalg.norm(np.cross(forward, up))
    upward = np.cross(right, forward)
    focal = 0.5 * min(width, height) / np.tan(fov / 2)
    d = points - eye
    scale = focal / (d @ forward)
    return np.column_stack([width / 2 + (d @ right) * scale, height / 2 - (d @ upward) * scale])


def test_the_viewer_draws_the_red_box_where_it_projects(browser, tmp_path):  # noqa: F811
    """In Chromium, at t = 0 with the arm, which carries only the box, turned by 0.7 rad: the
    flat-shaded red pixels (red only, any brightness) fill the box's projected outline (its 8
    corners' convex hull, 95 % of its area at least) and lie nowhere else (within 1.5 px of its
    bounding rectangle)."""
    path = tmp_path / "box.urdf"
    path.write_text(re.sub(r"<visual><origin xyz=\"0 0 0.1\".*?</visual>\s*<visual>.*?</visual>", "", SHAPES,
                           flags=re.DOTALL))
    boxed = cmbs.load(path)
    assert [visual.shape for visual in boxed.parameters["visuals"]["arm"]] == ["box"]
    q = 0.7
    page = animate(boxed, still(boxed, [q]), tmp_path / "box.html", fps=10)
    picture = tmp_path / "box.png"
    chromium(browser, tmp_path / "profile", f"{page.as_uri()}#t=0", f"--screenshot={picture}")
    with Image.open(picture) as image:
        pixels = np.asarray(image.convert("RGB")).astype(int)
    height = int(np.argmax(np.all(pixels == (221, 221, 221), axis=2).mean(axis=1) > 0.9))   # the bar's top border
    assert 450 < height < 600
    red = (pixels[:height, :, 0] > 80) & (pixels[:height, :, 1] == 0) & (pixels[:height, :, 2] == 0)
    data = embedded(page)
    R, t = placement((0, 0, 0.1), yaw=q)                                     # the arm's frame
    box_R, box_t = placement((0.3, 0, 0.2), yaw=0.5)
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.05, 0.05) for z in (-0.025, 0.025)])
    world = (corners @ box_R.T + box_t) @ R.T + t
    everything = np.concatenate([[[0, 0, 0], t], world])
    outline = project(world, data, everything, pixels.shape[1], height)
    rows, columns = np.nonzero(red)
    assert red.sum() >= 0.95 * ConvexHull(outline).volume > 500
    assert columns.min() >= outline[:, 0].min() - 1.5 and columns.max() <= outline[:, 0].max() + 1.5
    assert rows.min() >= outline[:, 1].min() - 1.5 and rows.max() <= outline[:, 1].max() + 1.5
    lit = pixels[:height][red][:, 0]
    assert lit.max() - lit.min() > 20                                        # the faces are shaded apart


HARNESS = """
<script>
window.failures = [];
window.addEventListener("error", (event) => window.failures.push(String(event.message)));
window.addEventListener("load", () => setTimeout(() => {
  const canvas = document.getElementById("canvas");
  const pixels = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  let dark = 0;
  for (let i = 0; i < pixels.length; i += 4) if (Math.max(pixels[i], pixels[i + 1], pixels[i + 2]) < 100) dark++;
  const sticks = document.getElementById("sticks");
  const before = canvas.toDataURL();
  sticks.click();
  const out = document.createElement("pre");
  out.id = "harness";
  const shown = !document.getElementById("in-front").hidden;
  out.textContent = JSON.stringify({ failures: window.failures, dark, shown, toggled: canvas.toDataURL() !== before });
  document.body.appendChild(out);
}, 0));
</script>
"""


@needs_ur5
def test_the_ur5_viewer_draws_its_meshes_without_script_errors(browser, tmp_path):  # noqa: F811
    """The UR5 over 2 s at 30 frames per second (a motion written here): a file of at most
    250 kB that Chromium draws without a script error, with thousands of dark (mesh) pixels at
    t = 1 s, where the stick figure alone has few; the stick figure can be put in front."""
    model = cmbs.load(UR5)
    times = np.linspace(0.0, 2.0, 41)
    q = model.q0 + np.outer(np.sin(times), [0.5, -0.8, 1.0, -0.4, 0.6, 0.3])
    run = Trajectory(times, q, np.zeros_like(q), np.zeros_like(q), model.coordinate_names)
    page = animate(model, run, tmp_path / "ur5.html")
    size = page.stat().st_size
    print(f"UR5 viewer over 2 s at 30 fps: {size / 1000:.0f} kB")
    assert size < 250_000
    text = page.read_text(encoding="utf-8")
    for reference in ("http:", "https:", " src=", " href=", "url(", "@import", "import(", "fetch("):
        assert reference not in text, reference
    counts = {}
    for name, page_text in (("surfaces", text), ("sticks", text.replace('"surfaces":[', '"surfaces":[],"unused":['))):
        harness = tmp_path / f"{name}.html"
        harness.write_text(page_text.replace("<script>\n\"use strict\";", HARNESS + "<script>\n\"use strict\";"),
                           encoding="utf-8")
        dom = chromium(browser, tmp_path / "profile", f"{harness.as_uri()}#t=1", "--dump-dom")
        found = re.search(r'<pre id="harness">(.*?)</pre>', dom, re.DOTALL)
        assert found, dom[-1000:]
        result = json.loads(html.unescape(found.group(1)))
        assert result["failures"] == []
        counts[name] = result
    assert counts["surfaces"]["shown"] and counts["surfaces"]["toggled"] and not counts["sticks"]["shown"]
    assert counts["surfaces"]["dark"] > 5000 > 5 * counts["sticks"]["dark"]


# ---------------------------------------------------------------- the GIF
@pytest.fixture
def handed(monkeypatch) -> list[tuple[np.ndarray, np.ndarray]]:
    """Records, at every frame handed to the GIF writer, the triangles last given to the
    surfaces' collection (T, 3, 3) and the canvas pixels (rows, columns, RGB)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    given, frames = [], []
    set_verts = Poly3DCollection.set_verts
    grab = animate_module._BlitPillowWriter.grab_canvas

    def recording_verts(self, verts, *args, **kwargs):
        if self.get_gid() == "surfaces":
            given.append(np.array(verts))
        return set_verts(self, verts, *args, **kwargs)

    def recording(self):
        frames.append((given[-1], np.asarray(self.fig.canvas.buffer_rgba())[:, :, :3].astype(int)))
        grab(self)

    monkeypatch.setattr(Poly3DCollection, "set_verts", recording_verts)
    monkeypatch.setattr(animate_module._BlitPillowWriter, "grab_canvas", recording)
    return frames


def test_the_gif_draws_the_surfaces_turning_with_the_link(shapes, tmp_path, handed):
    """Every frame hands the writer the surfaces' triangles placed by the link's pose (q = t
    about z) and a canvas with the shaded red box, which moves."""
    times = np.linspace(0.0, 1.5, 4)
    q = times[:, None]
    run = Trajectory(times, q, np.zeros_like(q), np.zeros_like(q), ("turn",))
    path = animate(shapes, run, tmp_path / "shapes.gif", fps=2, dpi=60)
    with Image.open(path) as image:
        assert image.n_frames == 4
    assert len(handed) == 4
    surfaces = link_surfaces(shapes)
    reds = []
    for t, (triangles, pixels) in zip(times, handed):
        R, o = placement((0, 0, 0.1), yaw=t)
        expected = np.concatenate([s.vertices[s.triangles] for s in surfaces]) @ R.T + o
        assert np.allclose(triangles, expected, rtol=0, atol=1e-12)
        reds.append((pixels[:, :, 0] > 80) & (pixels[:, :, 1] < 30) & (pixels[:, :, 2] < 30))
        assert reds[-1].sum() > 30
    assert (reds[0] ^ reds[-1]).sum() > 30                                  # the box has moved


@needs_ur5
def test_the_ur5_gif_is_written(tmp_path, handed):
    model = cmbs.load(UR5)
    path = animate(model, still(model, model.q0 + 0.3), tmp_path / "ur5.gif", fps=20, dpi=40)
    with Image.open(path) as image:
        assert image.n_frames == 3
    count = sum(len(s.triangles) for s in link_surfaces(model))
    assert len(handed) == 3 and all(triangles.shape == (count, 3, 3) for triangles, _ in handed)
