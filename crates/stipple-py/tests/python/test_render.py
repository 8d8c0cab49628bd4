"""Rendering from Python: the same frames as the command line, options, cameras, renderers."""

import json
import os
import signal
import threading
import time

import numpy as np
import pytest
import stipple
from conftest import read_png, run_cli, wavy_sheet

CAM = dict(eye=(0.4, -2.2, 1.6), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov=38.0, size=(240, 180))


def cli_camera_args(cam):
    v = lambda t: ",".join(repr(float(x)) for x in t)  # noqa: E731
    w, h = cam["size"]
    return [f"--eye={v(cam['eye'])}", f"--target={v(cam['target'])}", f"--up={v(cam['up'])}",
            f"--fov={cam['fov']!r}", f"--size={w}x{h}"]


@pytest.fixture(scope="module")
def sheet_file(tmp_path_factory):
    p, n, col = wavy_sheet(40_000)
    path = tmp_path_factory.mktemp("sheet") / "sheet.ply"
    stipple.Cloud(p, normals=n, colors=col).save(path)
    return path


@pytest.fixture(scope="module")
def bare_file(tmp_path_factory):
    """The same surface without normals: the estimation runs in both."""
    p, _, _ = wavy_sheet(20_000, seed=5)
    path = tmp_path_factory.mktemp("bare") / "bare.xyz"
    stipple.Cloud(p).save(path)
    return path


CASES = [
    ("dobrev", {}, []),
    ("splat", {}, []),
    ("raw", {"shading": "edl"}, ["--shading", "edl"]),
    ("auto", {"layers": 2, "opacity": 0.5, "background": (250, 250, 250)},
     ["--layers", "2", "--opacity", "0.5", "--background", "250,250,250"]),
    ("auto", {"no_lighting": True, "depth_cue": 0.5}, ["--no-lighting", "--depth-cue", "0.5"]),
]


@pytest.mark.parametrize("pipeline, options, flags", CASES)
def test_image_and_depth_equal_the_clis_byte_for_byte(cli, tmp_path, sheet_file, pipeline, options, flags):
    png, npy, nrm = tmp_path / "a.png", tmp_path / "d.npy", tmp_path / "n.npy"
    run_cli(cli, "render", sheet_file, "-o", png, "--depth-out", npy, "--normal-out", nrm,
            "--backend", "cpu", "--pipeline", pipeline, *flags, *cli_camera_args(CAM))
    r = stipple.render(stipple.read(sheet_file), stipple.Camera(**CAM), pipeline=pipeline,
                       backend="cpu", **options)
    assert r.image.shape == (180, 240, 4) and r.image.dtype == np.uint8
    assert r.depth.shape == (180, 240) and r.depth.dtype == np.float32
    assert np.array_equal(r.image, read_png(png))
    # Equal bit for bit, +inf background included.
    assert np.array_equal(r.depth.view(np.uint32), np.load(npy).view(np.uint32))
    n_cli = np.load(nrm)
    assert r.normals.shape == (180, 240, 3)
    assert np.array_equal(np.isnan(r.normals), np.isnan(n_cli))
    assert np.array_equal(np.nan_to_num(r.normals), np.nan_to_num(n_cli))
    assert np.isinf(r.depth).any() and np.isfinite(r.depth).any()


def test_a_cloud_without_normals_renders_as_the_cli_and_keeps_its_estimate(cli, tmp_path, bare_file):
    png, npy = tmp_path / "a.png", tmp_path / "d.npy"
    run_cli(cli, "render", bare_file, "-o", png, "--depth-out", npy, "--backend", "cpu",
            "--pipeline", "splat", *cli_camera_args(CAM))
    cloud = stipple.read(bare_file)
    assert cloud.normals is None
    r = stipple.render(cloud, stipple.Camera(**CAM), pipeline="splat", backend="cpu")
    assert np.array_equal(r.image, read_png(png))
    assert np.array_equal(r.depth.view(np.uint32), np.load(npy).view(np.uint32))
    assert any("estimated normals" in n for n in r.notes), r.notes
    # Kept: the next render does not estimate again.
    assert cloud.normals is not None and cloud.radius is not None
    r2 = stipple.render(cloud, stipple.Camera(**CAM), pipeline="splat", backend="cpu")
    assert not any("estimated normals" in n for n in r2.notes)
    assert np.array_equal(r2.image, r.image)


def test_default_camera_and_json_match_the_cli(cli, tmp_path, sheet_file):
    png, cam_json = tmp_path / "a.png", tmp_path / "cam.json"
    run_cli(cli, "render", sheet_file, "-o", png, "--camera-out", cam_json, "--size", "200x150",
            "--backend", "cpu")
    cloud = stipple.read(sheet_file)
    framed = stipple.Camera.framing(cloud, size=(200, 150))
    r = stipple.render(cloud, framed, backend="cpu")
    assert np.array_equal(r.image, read_png(png))
    from_cli = stipple.Camera.from_json(cam_json.read_text())
    assert json.loads(from_cli.to_json()) == json.loads(cam_json.read_text())
    assert json.loads(r.camera.to_json()) == json.loads(cam_json.read_text())
    # A named view, as --view frames it; a bad name is the flag's error.
    top_json = tmp_path / "top.json"
    run_cli(cli, "render", sheet_file, "-o", tmp_path / "top.png", "--camera-out", top_json,
            "--size", "64", "--backend", "cpu", "--view", "top")
    top = stipple.Camera.framing(cloud, size=64, view="top")
    assert json.loads(top.to_json()) == json.loads(top_json.read_text())
    with pytest.raises(ValueError, match="three-quarter-back"):
        stipple.Camera.framing(cloud, size=64, view="sideways")
    # Round trip of a camera with an orthographic view.
    ortho = stipple.Camera((0, 0, 5), (0, 0, 0), ortho=2.5, size=64, near=1.0, far=9.0)
    back = stipple.Camera.from_json(ortho.to_json())
    assert back.ortho == 2.5 and back.fov is None and back.size == (64, 64)


def test_scene_files_render_as_the_cli(cli, tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(
        '[camera]\neye = [0.0, 2.2, 3.0]\ntarget = [0.0, 0.0, 0.0]\nsize = [160, 120]\n'
        '[render]\nlayers = 2\nbackground = [250, 250, 250]\n'
        '[[cloud]]\ndemo = "torus"\npoints = 30000\ncolour = [60, 170, 70]\nopacity = 0.5\n'
    )
    png = tmp_path / "s.png"
    run_cli(cli, "render", scene, "-o", png, "--backend", "cpu")
    r = stipple.render(scene, backend="cpu")
    assert r.image.shape == (120, 160, 4)
    assert np.array_equal(r.image, read_png(png))


def test_options_are_validated_like_the_cli_flags():
    c = stipple.demo("sphere", points=2000)
    cam = stipple.Camera.framing(c, size=64)
    cases = [
        (dict(fill_iteration=2), "unknown option `fill_iteration`"),
        (dict(layers="three"), "layers: invalid value"),
        (dict(opacity=2.0), "opacity 2: must lie in 0..1"),
        (dict(size=64), "size: is part of the camera"),
        (dict(depth_out="x.npy"), "depth_out: is a file output"),
        (dict(no_lighting=1), "no_lighting: a switch: pass True or False"),
        (dict(layers=True), "layers: takes a value"),
        (dict(background=(1, 2)), "background"),
        (dict(light=[{"x": 1}]), "light: expected a number"),
        (dict(light=["point:0,2,1", "point:1,2,1"]), "light: expected a number"),
        (dict(fill_radius=10**30), "fill_radius: expected a number"),
    ]
    for options, message in cases:
        with pytest.raises(ValueError) as e:
            stipple.render(c, cam, backend="cpu", **options)
        assert message in str(e.value), (options, str(e.value))
    with pytest.raises(ValueError, match="pipeline"):
        stipple.render(c, cam, pipeline="fancy", backend="cpu")
    with pytest.raises(ValueError, match="source"):
        stipple.render(42, cam)
    with pytest.raises(ValueError, match="eye and target coincide"):
        stipple.Camera((0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="size"):
        stipple.Camera((0, 0, 1), (0, 0, 0), size=(0, 10))
    with pytest.raises(ValueError, match="field of view"):
        stipple.Camera((0, 0, 1), (0, 0, 0), fov=190)
    with pytest.raises(ValueError, match="near and far"):
        stipple.Camera((0, 0, 1), (0, 0, 0)).to_json()
    opts = stipple.render_options()
    assert "fill_radius" in opts and "layers" in opts and "size" not in opts and "output" not in opts


def test_options_that_change_colours_leave_the_cloud_as_given():
    p, n, col = wavy_sheet(5000)
    c = stipple.Cloud(p, normals=n, colors=col)
    cam = stipple.Camera(**CAM)
    plain = stipple.render(c, cam, backend="cpu")
    by_z = stipple.render(c, cam, backend="cpu", colour_by="z", colour_map="turbo")
    assert not np.array_equal(plain.image, by_z.image)
    assert np.array_equal(c.colors, col)
    again = stipple.render(c, cam, backend="cpu")
    assert np.array_equal(again.image, plain.image)


def test_a_renderer_renders_many_views_as_single_renders_do():
    p, n, col = wavy_sheet(20_000)
    c = stipple.Cloud(p, normals=n, colors=col)
    r = stipple.Renderer(c, backend="cpu", fill_radius=2)
    base = stipple.Camera(**CAM)
    assert r.default_camera.size == (1024, 1024)
    for k in range(4):
        a = 2 * np.pi * k / 4
        cam = base.replace(eye=(2.5 * np.cos(a), 2.5 * np.sin(a), 1.5))
        one = stipple.render(c, cam, backend="cpu", fill_radius=2)
        many = r.render(cam)
        assert np.array_equal(one.image, many.image)
        assert np.array_equal(one.depth.view(np.uint32), many.depth.view(np.uint32))
        assert many.stats and all(v >= 0 for v in many.stats.values())
        assert many.pipeline in ("dobrev", "splat")


def test_arrays_are_handed_over_not_copied():
    c = stipple.demo("sphere", points=3000)
    r = stipple.render(c, stipple.Camera.framing(c, size=32), backend="cpu")
    # The image array owns no memory of its own (the frame's buffer is its base), and every
    # access returns the same array.
    assert not r.image.flags.owndata
    assert r.image is r.image or np.shares_memory(r.image, r.image)


@pytest.mark.skipif(not hasattr(signal, "SIGINT"), reason="no SIGINT on this platform")
def test_keyboard_interrupt_during_a_long_render_is_honoured():
    rng = np.random.default_rng(7)
    # 1.5 M points without normals: estimating them takes seconds on 2 cores.
    p = rng.normal(size=(1_500_000, 3))
    c = stipple.Cloud(p)
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    t0 = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        stipple.render(c, stipple.Camera.framing(c, size=256), pipeline="splat", backend="cpu")
    waited = time.monotonic() - t0
    timer.cancel()
    # The estimation stops within one of its steps.
    assert waited < 4.0, f"the interrupt took {waited:.2f} s to be honoured"
    # Nothing half-done is kept: the cloud has no normals, and renders again.
    assert c.normals is None
    small = stipple.Cloud(p[:2000])
    assert stipple.render(small, stipple.Camera.framing(small, size=32), backend="cpu").image.shape == (32, 32, 4)


def test_rendering_releases_the_gil():
    rng = np.random.default_rng(8)
    c = stipple.Cloud(rng.normal(size=(300_000, 3)))
    ticks = 0
    done = threading.Event()

    def count():
        nonlocal ticks
        while not done.is_set():
            ticks += 1
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    t0 = time.monotonic()
    stipple.render(c, stipple.Camera.framing(c, size=128), pipeline="splat", backend="cpu")
    spent = time.monotonic() - t0
    done.set()
    t.join()
    # Normal estimation takes about a second here; a held GIL would leave the counter near 0.
    assert spent > 0.2 and ticks > 0.3 * spent * 1000 * 0.5, (ticks, spent)


def rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="needs /proc")
def test_many_renders_do_not_leak():
    c = stipple.demo("torus", points=20_000)
    cam = stipple.Camera.framing(c, size=(160, 120))
    r = stipple.Renderer(c, backend="cpu")
    for _ in range(20):
        r.render(cam).normals
    stipple.render(c, cam, backend="cpu")
    before = rss_bytes()
    for i in range(200):
        res = r.render(cam)
        _ = res.image, res.depth, res.normals, res.stats
        if i % 20 == 0:
            stipple.render(c, cam, backend="cpu")
    grown = rss_bytes() - before
    # One frame's arrays are ~0.5 MB: 200 leaked frames would be ~100 MB.
    assert grown < 16 << 20, f"RSS grew by {grown >> 20} MiB over 200 renders"


def test_build_a_tree_and_render_it(tmp_path, cli):
    p, n, col = wavy_sheet(60_000)
    las = tmp_path / "sheet.las"
    stipple.Cloud(p * 100 + np.array([500_000.0, 4_000_000.0, 50.0]), colors=col).save(las)
    tree = tmp_path / "sheet.stlod"
    stipple.build_lod(las, tree, memory="256M", max_node_points=4096)
    assert tree.exists()
    with pytest.raises(FileExistsError, match="exists"):
        stipple.build_lod([las], tree)
    with pytest.raises(FileExistsError, match="refusing to overwrite an input"):
        stipple.build_lod([las], las)
    cam = stipple.Camera(eye=(500_000.0, 3_999_700.0, 250.0), target=(500_000.0, 4_000_000.0, 50.0),
                         up=(0, 0, 1), fov=40.0, size=(200, 150))
    r = stipple.render(tree, cam, backend="cpu", point_budget="1M")
    assert r.pipeline == "raw"
    framed = stipple.Renderer(tree, backend="cpu").default_camera
    assert framed.up == (0.0, 0.0, 1.0) and framed.size == (1024, 1024)
    assert np.isfinite(r.depth).mean() > 0.2
    png, npy = tmp_path / "t.png", tmp_path / "t.npy"
    run_cli(cli, "render", tree, "-o", png, "--depth-out", npy, "--backend", "cpu",
            "--point-budget", "1M", "--eye", "500000,3999700,250", "--target", "500000,4000000,50",
            "--up", "0,0,1", "--fov", "40", "--size", "200x150")
    assert np.array_equal(r.image, read_png(png))
    assert np.array_equal(r.depth.view(np.uint32), np.load(npy).view(np.uint32))
    with pytest.raises(ValueError, match="memory"):
        stipple.build_lod(las, tmp_path / "x.stlod", memory=[1])


def test_a_copc_file_is_written_and_drawn_from_a_cut(tmp_path, cli):
    p, n, col = wavy_sheet(150_000)
    las = tmp_path / "sheet.las"
    stipple.Cloud(p * 100 + np.array([500_000.0, 4_000_000.0, 50.0]), colors=col).save(las)
    copc = tmp_path / "sheet.copc.laz"
    stipple.build_lod(las, copc)
    whole = stipple.read(copc)
    assert len(whole) == 150_000 and whole.colors is not None
    cam = stipple.Camera(eye=(500_000.0, 3_999_700.0, 250.0), target=(500_000.0, 4_000_000.0, 50.0),
                         up=(0, 0, 1), fov=40.0, size=(200, 150))
    # Beyond the budget: the nodes this view needs, as the command line draws them.
    r = stipple.render(copc, cam, backend="cpu", point_budget="60K")
    assert np.isfinite(r.depth).mean() > 0.2
    png = tmp_path / "c.png"
    out = run_cli(cli, "render", copc, "-o", png, "--backend", "cpu", "--point-budget", "60K",
                  "--eye", "500000,3999700,250", "--target", "500000,4000000,50", "--up", "0,0,1",
                  "--fov", "40", "--size", "200x150")
    assert "COPC:" in out.stdout + out.stderr
    assert np.array_equal(r.image, read_png(png))


def test_an_interrupted_tree_build_leaves_nothing(tmp_path):
    rng = np.random.default_rng(3)
    las = tmp_path / "big.las"
    stipple.Cloud(rng.uniform(0, 1000, size=(6_000_000, 3))).save(las)
    out = tmp_path / "big.stlod"
    # The interrupt comes once the build is under way (its temporary files exist), not after
    # a fixed delay: 3 M points once built in 0.3 s, and a signal after the build escaped the
    # test and stopped the whole session. It never comes after the build has returned.
    returned = threading.Event()

    def interrupt():
        deadline = time.monotonic() + 30
        while not returned.is_set() and time.monotonic() < deadline:
            if any(f.name != "big.las" for f in tmp_path.iterdir()):
                time.sleep(0.02)
                break
            time.sleep(0.001)
        if not returned.is_set():
            os.kill(os.getpid(), signal.SIGINT)

    watcher = threading.Thread(target=interrupt)
    t0 = time.monotonic()
    watcher.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            stipple.build_lod(las, out, memory="128M")
    finally:
        returned.set()
        watcher.join()
    assert time.monotonic() - t0 < 3.0
    assert not out.exists()
    assert sorted(f.name for f in tmp_path.iterdir()) == ["big.las"]


def test_real_scans_from_every_reader(data, cli, tmp_path):
    files = [
        data / "stanford/bunny/bun_zipper.ply",
        data / "lidar/autzen_trim.laz",
        data / "colored/milk_color.pcd",
        data / "bunny_e57/bunnyDouble.e57",
    ]
    for f in files:
        if not f.exists():
            continue
        c = stipple.read(f)
        assert len(c) > 1000, f
    bunny = data / "stanford/bunny/bun_zipper.ply"
    if bunny.exists():
        png = tmp_path / "b.png"
        run_cli(cli, "render", bunny, "-o", png, "--size", "256x256", "--backend", "cpu")
        c = stipple.read(bunny)
        r = stipple.render(c, stipple.Camera.framing(c, size=256), backend="cpu")
        assert np.array_equal(r.image, read_png(png))


def test_gpu_backend_matches_the_cli_where_there_is_one(cli, tmp_path, sheet_file):
    cloud = stipple.read(sheet_file)
    try:
        r = stipple.render(cloud, stipple.Camera(**CAM), backend="gpu", pipeline="dobrev")
    except (RuntimeError, ValueError) as e:
        if os.environ.get("STIPPLE_REQUIRE_GPU") == "1":
            raise
        pytest.skip(f"no GPU adapter: {e}")
    png = tmp_path / "g.png"
    run_cli(cli, "render", sheet_file, "-o", png, "--backend", "gpu", "--pipeline", "dobrev",
            *cli_camera_args(CAM))
    assert np.array_equal(r.image, read_png(png))
    assert "cpu" not in r.backend.split(":")[0]


def test_a_gpu_render_without_a_desktop_session_prints_no_wayland_errors():
    """Mesa's device-select layer printed "error: XDG_RUNTIME_DIR is invalid" twice on the
    first GPU render where no desktop session exists; importing stipple switches it off."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items()
           if k not in ("XDG_RUNTIME_DIR", "NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT")}
    code = ("import stipple\n"
            "c = stipple.demo('sphere', points=20000)\n"
            "try:\n"
            "    stipple.render(c, stipple.Camera.framing(c, size=64), backend='gpu')\n"
            "    print('rendered')\n"
            "except (RuntimeError, ValueError) as e:\n"
            "    print('no GPU:', e)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    if "rendered" not in r.stdout:
        if os.environ.get("STIPPLE_REQUIRE_GPU") == "1":
            raise AssertionError(r.stdout + r.stderr)
        pytest.skip(r.stdout.strip())
    assert "XDG_RUNTIME_DIR" not in r.stderr, r.stderr


def test_scalar_fields_read_and_lookup_tables_render(tmp_path):
    rows = [(x / 39.0, y / 39.0, 0.0, 1 + x // 20) for y in range(40) for x in range(40)]
    head = ("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
            "property float z\nproperty ushort segment\nend_header\n" % len(rows))
    path = tmp_path / "bands.ply"
    path.write_text(head + "".join("%r %r %r %d\n" % r for r in rows))
    c = stipple.read(path)
    assert set(c.fields) == {"segment"} and "segment" in c.info()["attributes"]
    assert np.array_equal(c.fields["segment"], np.array([r[3] for r in rows], dtype=np.float64))
    table = tmp_path / "t.toml"
    table.write_text('key = "segment"\n[value.1]\ncolour = [255, 0, 0]\n[value.2]\nshow = false\n')
    cam = stipple.Camera(eye=(0.5, 0.5, 3.0), target=(0.5, 0.5, 0.0), up=(0.0, 1.0, 0.0), fov=30.0,
                         size=(64, 64))
    f = stipple.render(c, cam, backend="cpu", lookup=str(table), no_lighting=True,
                     background=(0, 0, 0))
    img = f.image[..., :3].astype(int)
    left, right = img[16:48, 14:30], img[16:48, 36:]
    assert (left[..., 0] > 200).all() and (left[..., 1] < 40).all()
    assert right.max() == 0, "the hidden half shows the background"
    assert len(c) == len(rows), "the cloud stays as given"
    table.write_text('key = "nope"\n')
    with pytest.raises(ValueError, match="nope"):
        stipple.render(c, cam, backend="cpu", lookup=str(table))


def test_environments_and_algorithm_3_render_as_the_cli(cli, tmp_path):
    # Transparent splats with an environment, refraction, dispersion and Algorithm 3: the
    # keyword options are the flags, and the image is the CLI's.
    png = tmp_path / "glass.png"
    run_cli(cli, "render", "--demo", "sphere", "--points", "3000", "--opacity", "0.5",
            "--env", "sky", "--ior", "1.5", "--dispersion", "0.02", "--smooth-nearest",
            "--pipeline", "splat", "--size", "64", "--backend", "cpu", "-o", png)
    c = stipple.demo("sphere", points=3000)
    r = stipple.render(c, stipple.Camera.framing(c, size=64), backend="cpu", opacity=0.5,
                       env="sky", ior=1.5, dispersion=0.02, smooth_nearest=True,
                       pipeline="splat")
    assert np.array_equal(r.image, read_png(png))
    # Enlarged radii instead of duplicates (coverage="enlarge", --coverage enlarge).
    png2 = tmp_path / "enlarged.png"
    run_cli(cli, "render", "--demo", "sphere", "--points", "3000", "--opacity", "0.5",
            "--coverage", "enlarge", "--pipeline", "splat", "--size", "64",
            "--backend", "cpu", "-o", png2)
    e = stipple.render(c, stipple.Camera.framing(c, size=64), backend="cpu", opacity=0.5,
                       coverage="enlarge", pipeline="splat")
    assert np.array_equal(e.image, read_png(png2))
    with pytest.raises(ValueError, match="ior"):
        stipple.render(c, stipple.Camera.framing(c, size=32), backend="cpu", opacity=0.5,
                       env="sky", ior=-2.0, pipeline="splat")
