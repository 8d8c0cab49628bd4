"""The Python package's overhead (BENCHMARKS.md, "Python").

    python crates/stipple-py/benches/overhead.py frames [INPUT] [--size 1024] [--frames 20]
    python crates/stipple-py/benches/overhead.py views DRAGON.ply.gz --views 100 --cli target/release/stipple

`frames`: mean wall time of Renderer.render for the same input, size and camera as
`cargo run --release -p stipple-cli --example render_loop -- INPUT SIZE FRAMES --backend cpu`
(the Rust side). `views`: N views around a cloud through one Renderer, against N calls of the
command line for the same cameras (each reads the file and prepares the cloud again).
"""

import argparse
import subprocess
import time

import numpy as np
import stipple


def frames(a):
    cloud = stipple.read(a.input) if a.input else stipple.demo("plane-objects")
    r = stipple.Renderer(cloud, backend="cpu")
    cam = stipple.Camera.framing(cloud, size=a.size)
    r.render(cam)  # warm-up: normals, first allocation
    times, inner = [], []
    for _ in range(a.frames):
        t0 = time.perf_counter()
        res = r.render(cam)
        _ = res.image, res.depth
        times.append((time.perf_counter() - t0) * 1e3)
        inner.append(res.ms)
    print(f"{len(cloud)} points, {a.size}², {a.frames} frames from Python on {r.backend}: "
          f"mean {np.mean(times):.2f} ms, median {np.median(times):.2f} ms "
          f"(the frame alone: median {np.median(inner):.2f} ms)")


def orbit(framed, n):
    target = np.array(framed.target)
    offset = np.array(framed.eye) - target
    u = np.array(framed.up) / np.linalg.norm(framed.up)
    for k in range(n):
        t = 2 * np.pi * k / n
        rot = offset * np.cos(t) + np.cross(u, offset) * np.sin(t) + u * (u @ offset) * (1 - np.cos(t))
        yield framed.replace(eye=target + rot)


def views(a):
    t0 = time.perf_counter()
    cloud = stipple.read(a.input)
    r = stipple.Renderer(cloud, backend="cpu")
    cams = list(orbit(stipple.Camera.framing(cloud, size=a.size), a.views))
    for cam in cams:
        r.render(cam)
    py = time.perf_counter() - t0
    print(f"{a.views} views through one Renderer (read included): {py:.1f} s")
    if a.cli:
        t0 = time.perf_counter()
        n_cli = min(a.views, a.cli_views)
        for cam in cams[:n_cli]:
            v = lambda t: ",".join(repr(float(x)) for x in t)  # noqa: E731
            subprocess.run([a.cli, "render", a.input, "-o", "/tmp/stipple-view.png", "--backend", "cpu",
                            f"--eye={v(cam.eye)}", f"--target={v(cam.target)}", f"--up={v(cam.up)}",
                            f"--fov={cam.fov!r}", f"--size={a.size}x{a.size}"],
                           check=True, capture_output=True)
        per = (time.perf_counter() - t0) / n_cli
        print(f"command line: {per:.2f} s a view over {n_cli} calls, {per * a.views:.1f} s for {a.views}")


ap = argparse.ArgumentParser()
ap.add_argument("what", choices=["frames", "views"])
ap.add_argument("input", nargs="?")
ap.add_argument("--size", type=int, default=None)
ap.add_argument("--frames", type=int, default=20)
ap.add_argument("--views", type=int, default=100)
ap.add_argument("--cli")
ap.add_argument("--cli-views", type=int, default=100)
args = ap.parse_args()
if args.size is None:
    args.size = 1024 if args.what == "frames" else 512
frames(args) if args.what == "frames" else views(args)
