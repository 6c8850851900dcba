"""The Python package against the command line: shapes and dtypes, edits, errors with the
command line's messages, a reduced recovery whose numbers equal the command line's to the bit,
and Ctrl-C. `.ci/run` runs it in a venv it makes; MATFIT_BIN names the command line's binary."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import matfit

ROOT = Path(__file__).resolve().parents[2]
FIGURE6 = ROOT / "scenes" / "figure6" / "scene.toml"
BIN = os.environ.get("MATFIT_BIN", str(ROOT / "target" / "ci" / "matfit"))

# A recovery small enough for a test: the options of both sides.
REDUCED = dict(
    seed=7,
    max_iterations=3,
    max_pixels=1500,
    first_pixels=500,
    light_samples=8,
    indirect_samples=8,
    final_spp=4,
)
REDUCED_CLI = [
    "--seed", "7", "--max-iterations", "3", "--max-pixels", "1500", "--first-pixels", "500",
    "--light-samples", "8", "--indirect-samples", "8", "--final-spp", "4",
]


def cli(*args):
    r = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True)
    return r.returncode, r.stdout, r.stderr


def cli_error(*args):
    code, _, err = cli(*args)
    assert code == 2, err
    assert err.startswith("error: ") or "\nerror: " in err, err
    msg = err[err.index("error: ") + len("error: "):]
    return msg[:-1] if msg.endswith("\n") else msg  # the line's own newline


@pytest.fixture(scope="module")
def scene():
    return matfit.Scene.load(FIGURE6)


@pytest.fixture(scope="module")
def photo(tmp_path_factory, scene):
    """figure6's photo, rendered by the command line at 16 spp."""
    path = tmp_path_factory.mktemp("photo") / "photo.exr"
    code, _, err = cli("render", FIGURE6, "-o", path, "--spp", 16)
    assert code == 0, err
    return path


def test_render_gives_float32_images_and_int32_index_buffers(scene):
    h, w = scene.shape
    img = scene.render(spp=1, seed=3)
    assert img.shape == (h, w, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.mean() > 0
    assert np.array_equal(img, scene.render(spp=1, seed=3)), "seeded renders repeat"
    ids = scene.render(aov="group")
    assert ids.shape == (h, w) and ids.dtype == np.int32
    assert set(np.unique(ids)) <= set(range(-1, len(scene.groups)))
    assert scene.render(aov="depth").dtype == np.float32


def test_the_render_equals_the_command_lines(scene, tmp_path):
    out = tmp_path / "r.pfm"
    code, _, err = cli("render", FIGURE6, "-o", out, "--spp", 2, "--seed", 5)
    assert code == 0, err
    from_cli = read_pfm(out)
    assert np.array_equal(scene.render(spp=2, seed=5), from_cli)


def test_groups_and_edits(scene):
    assert "floor" in scene.groups
    before = scene.render(spp=1, aov="group")
    edited = scene.edit(material=['left_wall={ type = "diffuse", rho_d = 0.95 }'])
    assert edited.groups == scene.groups
    a, b = scene.render(spp=2, seed=1), edited.render(spp=2, seed=1)
    wall = before == scene.groups.index("left_wall")
    assert wall.any() and b[wall].mean() > a[wall].mean()
    removed = scene.edit(remove=[scene.groups[-1]])
    assert isinstance(removed, matfit.Scene)


def test_errors_are_exceptions_of_their_kind_with_the_command_lines_messages(scene, tmp_path):
    missing = tmp_path / "missing.toml"
    with pytest.raises(matfit.SceneError) as e:
        matfit.Scene.load(missing)
    assert str(e.value) == cli_error("render", missing, "-o", tmp_path / "x.exr")

    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nwidth = 'wide'\n")
    with pytest.raises(matfit.SceneError) as e:
        matfit.Scene.load(bad)
    assert str(e.value) == cli_error("info", bad)

    wrong = tmp_path / "small.pfm"
    write_pfm(wrong, np.ones((10, 12, 3), np.float32))
    with pytest.raises(matfit.PhotoError) as e:
        matfit.recover(scene, wrong, **REDUCED)
    assert str(e.value) == cli_error("recover", FIGURE6, wrong, "-o", tmp_path / "o")

    with pytest.raises(matfit.OptionsError):
        scene.render(aov="colour")
    with pytest.raises(matfit.OptionsError):
        matfit.recover(scene, wrong, no_such_option=1)
    assert issubclass(matfit.PhotoError, matfit.MatfitError)


def test_a_reduced_recovery_equals_the_command_lines_to_the_bit(scene, photo, tmp_path):
    out_cli = tmp_path / "cli"
    t = time.perf_counter()
    code, _, err = cli("recover", FIGURE6, photo, "-o", out_cli, *REDUCED_CLI)
    t_cli = time.perf_counter() - t
    assert code == 0, err
    t = time.perf_counter()
    rec = matfit.recover(scene, photo, output=tmp_path / "py", progress=False, **REDUCED)
    t_py = time.perf_counter() - t
    print(f"\nreduced recovery: command line {t_cli:.2f} s, Python {t_py:.2f} s")
    ours = rec.results
    theirs = json.loads((out_cli / "results.json").read_text())
    for a, b in zip(ours["groups"], theirs["groups"]):
        assert a["name"] == b["name"]
        for k in ["level", "status", "params", "sigma", "error", "noise_floor", "fit_error"]:
            assert a.get(k) == b.get(k), (a["name"], k, a.get(k), b.get(k))
    floor = rec.groups["floor"]
    assert floor.level and floor.status and "rho_d" in floor.parameters
    assert isinstance(floor.parameters["rho_d"], list) and "rho_d" in floor.sigma
    h, w = scene.shape
    for img in (rec.photo, rec.synthetic, rec.error):
        assert img.shape == (h, w, 3) and img.dtype == np.float32
    assert np.array_equal(rec.synthetic, matfit.read_image(out_cli / "synthetic.exr"))
    assert rec.log and {"iteration", "group", "event"} <= set(rec.log[0])
    assert isinstance(rec.scene, matfit.Scene) and rec.scene.groups == scene.groups
    # The same recovery from the photo as an array.
    again = matfit.recover(scene, matfit.read_image(photo), progress=False, **REDUCED)
    assert again.results["groups"][0]["params"] == ours["groups"][0]["params"]


def test_composite_renders_an_edit_into_the_photo(scene, photo):
    ball = '{ name = "ball", group = "ball", shape = "sphere", center = [0, 0.3, -3], radius = 0.3 }'
    out = matfit.composite(scene, photo, add=[ball], spp=4, exposure=1.0)
    assert out.shape == (*scene.shape, 3) and out.dtype == np.float32


def test_ctrl_c_raises_keyboard_interrupt_and_keeps_the_checkpoint(photo, tmp_path):
    out = tmp_path / "interrupted"
    script = textwrap.dedent(
        f"""
        import signal, matfit
        # A process started in the background inherits SIGINT ignored: restore Python's handler.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        scene = matfit.Scene.load({str(FIGURE6)!r})
        try:
            matfit.recover(scene, {str(photo)!r}, output={str(out)!r}, progress=False,
                           seed=7, max_iterations=40, max_pixels=1500, first_pixels=500,
                           light_samples=8, indirect_samples=8, final_spp=4)
        except KeyboardInterrupt:
            print("KeyboardInterrupt")
        """
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    ck = out / "checkpoint.json"
    deadline = time.time() + 120
    while not ck.exists() and time.time() < deadline and p.poll() is None:
        time.sleep(0.05)
    assert ck.exists(), "no checkpoint written"
    p.send_signal(signal.SIGINT)
    stdout, _ = p.communicate(timeout=120)
    assert "KeyboardInterrupt" in stdout
    assert p.returncode == 0
    assert json.loads(ck.read_text())["fingerprint"]
    assert not (out / "results.json").exists()
    # The run continues from its checkpoint.
    scene = matfit.Scene.load(FIGURE6)
    rec = matfit.recover(scene, photo, output=out, resume=True, progress=False, seed=7,
                         max_iterations=40, max_pixels=1500, first_pixels=500,
                         light_samples=8, indirect_samples=8, final_spp=4)
    assert (out / "results.json").exists() and rec.groups


def test_ctrl_c_stops_a_render_partway(tmp_path):
    """A render of minutes stops within a second of Ctrl-C, not when it would have ended."""
    script = textwrap.dedent(
        f"""
        import signal, time, matfit
        signal.signal(signal.SIGINT, signal.default_int_handler)
        scene = matfit.Scene.load({str(FIGURE6)!r})
        print("rendering", flush=True)
        t = time.perf_counter()
        try:
            scene.render(spp=4096, seed=1)
            print("finished")
        except KeyboardInterrupt:
            print(f"KeyboardInterrupt after {{time.perf_counter() - t:.2f}} s")
        """
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "rendering"
    time.sleep(1.0)
    sent = time.perf_counter()
    p.send_signal(signal.SIGINT)
    stdout, _ = p.communicate(timeout=120)
    stopped = time.perf_counter() - sent
    print(f"\nrender stopped {stopped:.2f} s after Ctrl-C: {stdout.strip()}")
    assert "KeyboardInterrupt" in stdout, stdout
    # 4096 spp of figure6 takes minutes on two cores; a row takes milliseconds.
    assert stopped < 10, stopped


def test_progress_is_drawn_without_tqdm(scene, capsys, monkeypatch):
    """progress=True draws a bar on stderr even where tqdm is not installed."""
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    scene.render(spp=2, seed=1, progress=True)
    err = capsys.readouterr().err
    assert "render" in err and "%" in err and "[" in err, err


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        assert kind == b"PF"
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return np.flipud(data.reshape(h, w, 3)).astype(np.float32)


def write_pfm(path, img):
    h, w, _ = img.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.flipud(img).astype("<f4").tobytes())
