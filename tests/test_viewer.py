"""The interactive HTML viewer (--animate FILE.html): its embedded JSON (frames, times, points,
ground, up, precision), self-containment, escaping, refusals and atomic writing; then, in a real
headless Chromium, what it draws (pixels of the segment, trail and ground colours in
screenshots) and how it answers the slider, the play button, mouse drags, the wheel and a
double-click (a harness script added to a copy of the page reports into the DOM)."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import cmbs
from cmbs import viewer_html
from cmbs.animate import animate, checked_animation_path
from cmbs.errors import CmbsError
from cmbs.trajectory import Trajectory

#: colours the viewer draws with (src/cmbs/viewer.html)
SEGMENT, TRAIL, GROUND = (31, 119, 180), (255, 127, 14), (119, 119, 119)
DATA = re.compile(r'<script id="cmbs-data" type="application/json">(.*?)</script>', re.DOTALL)


def embedded(path: Path) -> dict:
    """The JSON object in a viewer file."""
    found = DATA.findall(path.read_text(encoding="utf-8"))
    assert len(found) == 1
    return json.loads(found[0])


def decoded(frames: list[list[int]], unit: float) -> np.ndarray:
    """(frames, points, 3) positions from the file's integers."""
    return np.array(frames, dtype=float).reshape(len(frames), -1, 3) * unit


def interpolated_points(model: cmbs.Model, run: Trajectory, times: np.ndarray) -> np.ndarray:
    """(frames, points, 2 or 3) the model's points at ``times``, interpolated here independently."""
    q = np.column_stack([np.interp(times, run.t, column) for column in run.q.T])
    return np.array([model.point_positions(row) for row in q])


@pytest.fixture(scope="module")
def top():
    model = cmbs.load("heavy-top")
    return model, cmbs.simulate(model, t_end=0.5, dt=0.01)


@pytest.fixture(scope="module")
def top_page(top, tmp_path_factory):
    model, run = top
    return animate(model, run, tmp_path_factory.mktemp("top") / "top.html", fps=20, trail="tip")


# ---------------------------------------------------------------- the file
def test_the_file_embeds_the_frames(top, top_page):
    model, run = top
    data = embedded(top_page)
    times = np.linspace(0.0, 0.5, 11)                        # 0.5 s at 20 frames per second, both ends
    assert data["format"] == "cmbs-viewer 1" and data["model"] == "heavy-top" and data["planar"] is False
    assert np.allclose(data["times"], times, rtol=0, atol=1e-12) and data["rate"] == 20
    assert data["points"] == list(model.point_names) and data["lines"] == [list(pair) for pair in model.lines]
    assert data["ground"] == [name == "O" for name in model.point_names]
    assert data["trail"] == model.point_names.index("tip") and data["ghost"] is None
    assert data["up"] == [0.0, 0.0, 1.0] and data["decimals"] == 2
    size = float(np.linalg.norm(np.ptp(interpolated_points(model, run, times).reshape(-1, 3), axis=0)))
    assert data["unit"] <= 1e-4 * size < 10 * data["unit"]
    assert all(isinstance(value, int) for frame in data["frames"] for value in frame)
    positions = decoded(data["frames"], data["unit"])
    assert positions.shape == (11, len(model.point_names), 3)
    assert np.abs(positions - interpolated_points(model, run, times)).max() <= 0.5 * data["unit"] + 1e-12
    assert np.ptp(positions[:, model.point_names.index("tip")], axis=0).max() > 0.05     # the tip moves


def test_the_file_is_self_contained(top_page):
    text = top_page.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") and "<canvas" in text
    for reference in ("http:", "https:", " src=", " href=", "url(", "@import", "import(", "fetch("):
        assert reference not in text, reference
    assert "__CMBS_" not in text                             # every template marker replaced
    assert top_page.stat().st_size < 40_000


def test_a_planar_model_is_drawn_in_the_plane_y_0(tmp_path):
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 0.5, 26))
    data = embedded(animate(model, motion, tmp_path / "four-bar.html", fps=10))
    times = np.linspace(0.0, 0.5, 6)
    assert data["planar"] is True and data["up"] == [0.0, 0.0, 1.0]
    assert np.allclose(data["times"], times, rtol=0, atol=1e-12)
    positions = decoded(data["frames"], data["unit"])
    expected = interpolated_points(model, motion, times)            # (x, z)
    assert np.all(positions[:, :, 1] == 0.0)
    assert np.abs(positions[:, :, [0, 2]] - expected).max() <= 0.5 * data["unit"] + 1e-12
    assert [name for name, ground in zip(data["points"], data["ground"]) if ground] == ["A", "B"]


def test_up_is_against_gravity_and_the_reference_is_embedded(tmp_path):
    model = cmbs.load("bricard")                                    # gravity along -y
    q = np.array([model.q0, model.q0])
    still = Trajectory(np.array([0.0, 1.0]), q, np.zeros_like(q), np.zeros_like(q), model.coordinate_names)
    moved = q.copy()
    moved[:, [model.coordinate_index(f"P{k}.x") for k in range(1, 5)]] += 0.25
    reference = Trajectory(still.t, moved, np.zeros_like(q), np.zeros_like(q), model.coordinate_names)
    data = embedded(animate(model, still, tmp_path / "bricard.html", fps=2, reference=reference))
    assert data["up"] == [0.0, 1.0, 0.0]
    assert [name for name, ground in zip(data["points"], data["ground"]) if ground] == ["P0", "P5"]
    shift = decoded(data["ghost"], data["unit"]) - decoded(data["frames"], data["unit"])
    assert shift.shape == (3, 6, 3)
    moving = [model.point_names.index(f"P{k}") for k in range(1, 5)]
    assert np.allclose(shift[:, moving, 0], 0.25, atol=data["unit"])
    assert np.allclose(np.delete(shift, moving, axis=1), 0.0) and np.allclose(shift[:, :, 1:], 0.0)


def test_names_cannot_break_out_of_the_page(top, tmp_path):
    model, run = top
    tricky = model.replace(name='top</script><b onclick="x">&')
    path = animate(tricky, run, tmp_path / "tricky.html", fps=10)
    text = path.read_text(encoding="utf-8")
    assert embedded(path)["model"] == 'top</script><b onclick="x">&'
    assert "<title>top&lt;/script&gt;&lt;b onclick=&quot;x&quot;&gt;&amp; (cmbs viewer)</title>" in text
    assert text.count("</script>") == 2                     # the data's and the renderer's


def test_bad_paths_are_refused_with_the_extensions(top, tmp_path):
    model, run = top
    with pytest.raises(CmbsError, match=r"must end in \.gif or \.mp4 or \.html, got '\.htm'"):
        checked_animation_path(tmp_path / "top.htm", "--animate")
    with pytest.raises(CmbsError, match="does not exist"):
        animate(model, run, tmp_path / "missing" / "top.html")
    with pytest.raises(CmbsError, match="viewer must end in .html"):
        viewer_html.write_viewer(model, None, tmp_path / "top.gif")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(top, tmp_path, monkeypatch):
    model, run = top
    target = tmp_path / "top.html"
    target.write_text("old")

    def full_disk(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(viewer_html.Path, "write_text", full_disk)
    with pytest.raises(CmbsError, match="writing the viewer failed .No space left on device."):
        animate(model, run, target, fps=10)
    monkeypatch.undo()
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["top.html"]


def test_the_template_is_package_data():
    configuration = (Path(__file__).parents[1] / "pyproject.toml").read_text()
    assert re.search(r'\[tool\.setuptools\.package-data\]\s*cmbs = \[[^\]]*"viewer\.html"', configuration)
    template = (Path(viewer_html.__file__).parent / viewer_html.TEMPLATE).read_text(encoding="utf-8")
    assert template.count(viewer_html.TITLE_MARK) == 1 and template.count(viewer_html.DATA_MARK) == 1


# ---------------------------------------------------------------- in a browser
@pytest.fixture(scope="module")
def browser() -> str:
    """The Chromium executable; the tests skip without it unless CMBS_REQUIRE_BROWSER is set."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        if os.environ.get("CMBS_REQUIRE_BROWSER"):
            pytest.fail("CMBS_REQUIRE_BROWSER is set but chromium was not found (apt-get install chromium)")
        pytest.skip("chromium not found: the viewer is not tested in a browser (CMBS_REQUIRE_BROWSER=1 makes this "
                    "a failure)")
    return found


def chromium(browser: str, profile: Path, url: str, *options: str) -> str:
    """Run headless Chromium on ``url`` with 2 s of virtual time; its standard output."""
    command = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars",
               f"--user-data-dir={profile}", "--window-size=800,600", "--virtual-time-budget=2000", *options, url]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def screenshot(browser: str, page: Path, fragment: str, tmp_path: Path) -> np.ndarray:
    """The page opened at ``#fragment`` as an RGB array, the texts above (whose anti-aliased
    greys can match the ground's), the control bar and the axis triad cut off."""
    picture = tmp_path / f"shot-{fragment.replace('=', '-')}.png"
    chromium(browser, tmp_path / "profile", f"{page.as_uri()}#{fragment}", f"--screenshot={picture}")
    with Image.open(picture) as image:
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.shape == (600, 800, 3)
    view = pixels[40:550].copy()
    view[410:, :100] = 255                                   # the x/y/z triad in the lower left corner
    return view


def mask(pixels: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(pixels == colour, axis=2)


def test_screenshots_show_the_moving_top_its_trail_and_ground(browser, top_page, tmp_path):
    start, end = (screenshot(browser, top_page, f"t={t}", tmp_path) for t in (0, 0.5))
    for pixels in (start, end):
        assert mask(pixels, SEGMENT).sum() > 100            # the top's axis, O to tip
        assert mask(pixels, GROUND).sum() > 20              # the ground symbol at O
        assert mask(pixels, (0, 0, 0)).sum() > 10           # the dot at the tip
    assert mask(start, TRAIL).sum() == 0                    # one frame: no trail yet
    assert mask(end, TRAIL).sum() > 30
    assert (mask(start, SEGMENT) ^ mask(end, SEGMENT)).sum() > 100      # the top has moved


def test_a_planar_model_is_seen_from_the_front(browser, tmp_path):
    """The four-bar from the front (x to the right, z up, the plane across the view, so one scale
    in it): its ground points A (0, 0) and B (10, 0) at the same height on the screen, the bars
    reaching as far above them, relative to A-B, as the model's highest point P2."""
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 0.5, 6))
    start = dict(zip(model.point_names, model.point_positions(motion.q[0])))
    assert start["A"][1] == start["B"][1] == 0.0 and start["B"][0] - start["A"][0] == 10.0
    highest = max(z for _, z in start.values())
    assert highest == start["P2"][1] > 1.0
    page = animate(model, motion, tmp_path / "four-bar.html", fps=10)
    pixels = screenshot(browser, page, "t=0", tmp_path)
    rows, columns = np.nonzero(mask(pixels, GROUND))
    left, right = columns < 400, columns >= 400
    assert left.sum() > 20 and right.sum() > 20
    assert rows[left].min() == rows[right].min()            # the triangles' apexes, at A and B
    across = np.median(columns[right]) - np.median(columns[left])
    segment_rows = np.nonzero(mask(pixels, SEGMENT))[0]
    assert segment_rows.size > 300
    up = rows.min() - segment_rows.min()                    # to P2, plus half a line's width
    assert up / across == pytest.approx(highest / 10.0, rel=0.03)


HARNESS = """
<script>
window.addEventListener("load", () => setTimeout(() => {
  const canvas = document.getElementById("canvas"), label = document.getElementById("time");
  const slider = document.getElementById("slider"), button = document.getElementById("play");
  const context = canvas.getContext("2d");
  function segment() {            // pixels of the segment colour and their extent
    const pixels = context.getImageData(0, 0, canvas.width, canvas.height).data;
    let count = 0, left = Infinity, right = -Infinity, top = Infinity, bottom = -Infinity;
    for (let i = 0; i < pixels.length; i += 4) {
      if (pixels[i] === 31 && pixels[i + 1] === 119 && pixels[i + 2] === 180) {
        const x = (i / 4) % canvas.width, y = Math.floor(i / 4 / canvas.width);
        count++; left = Math.min(left, x); right = Math.max(right, x); top = Math.min(top, y);
        bottom = Math.max(bottom, y);
      }
    }
    return { count, width: right - left, height: bottom - top };
  }
  const pointer = (type, x, y) => canvas.dispatchEvent(new PointerEvent(type, { clientX: x, clientY: y, button: 0,
                                                                                  pointerId: 1, bubbles: true }));
  const result = { start: { label: label.textContent, button: button.textContent, segment: segment() } };
  const image = canvas.toDataURL();
  pointer("pointerdown", 300, 300); pointer("pointermove", 380, 320); pointer("pointerup", 380, 320);
  result.dragged = canvas.toDataURL() !== image;
  canvas.dispatchEvent(new MouseEvent("dblclick", { bubbles: true }));
  result.reset = canvas.toDataURL() === image;
  canvas.dispatchEvent(new WheelEvent("wheel", { deltaY: -400, bubbles: true, cancelable: true }));
  result.zoomed = segment();
  canvas.dispatchEvent(new MouseEvent("dblclick", { bubbles: true }));
  slider.value = slider.max;
  slider.dispatchEvent(new Event("input", { bubbles: true }));
  result.end = { label: label.textContent, changed: canvas.toDataURL() !== image };
  slider.value = "0";
  slider.dispatchEvent(new Event("input", { bubbles: true }));
  button.click();
  result.playing = button.textContent;
  setTimeout(() => {
    result.played = label.textContent;
    const out = document.createElement("pre");
    out.id = "harness";
    out.textContent = JSON.stringify(result);
    document.body.appendChild(out);
  }, 300);
}, 0));
</script>
"""


def test_the_controls_answer(browser, top_page, tmp_path):
    page = tmp_path / "harness.html"
    page.write_text(top_page.read_text(encoding="utf-8").replace("</body>", HARNESS + "</body>"), encoding="utf-8")
    dom = chromium(browser, tmp_path / "profile", f"{page.as_uri()}#t=0.2", "--dump-dom")
    found = re.search(r'<pre id="harness">(.*?)</pre>', dom, re.DOTALL)
    assert found, dom[-1000:]
    result = json.loads(html.unescape(found.group(1)))
    start = result["start"]
    assert start["label"] == "t = 0.20 s" and start["button"] == "Play"      # #t=0.2 opens it paused there
    assert start["segment"]["count"] > 100
    assert result["dragged"] and result["reset"]                              # drag orbits, double-click resets
    before, after = start["segment"], result["zoomed"]
    assert max(after["width"], after["height"]) > 1.4 * max(before["width"], before["height"])   # wheel zooms in
    assert result["end"] == {"label": "t = 0.50 s", "changed": True}          # the slider's last frame
    assert result["playing"] == "Pause"
    played = float(result["played"].split()[2])
    assert 0.2 <= played <= 0.35                                              # 0.3 s of playback at real time
