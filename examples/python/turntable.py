"""A turntable of a cloud from Python: NumPy in, PNG frames and depth out.

    pip install ./crates/stipple-py pillow
    python examples/python/turntable.py                      # the built-in torus
    python examples/python/turntable.py scan.ply -n 36 -o frames/

Each view is rendered by one stipple.Renderer, which keeps the cloud (and the normals it
estimated) between frames; depth comes back as float32 (H, W) with +inf on background.
"""

import argparse
from pathlib import Path

import numpy as np
import stipple
from PIL import Image


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud", nargs="?", help="a cloud file (default: the torus demo scene)")
    ap.add_argument("-n", "--views", type=int, default=12, help="number of views (default 12)")
    ap.add_argument("-o", "--out", type=Path, default=Path("turntable"), help="output folder")
    ap.add_argument("--size", type=int, default=512, help="image side in pixels (default 512)")
    ap.add_argument("--backend", default="auto", choices=["auto", "cpu", "gpu"])
    a = ap.parse_args()

    cloud = stipple.read(a.cloud) if a.cloud else stipple.demo("torus", points=400_000)
    print(cloud, cloud.info()["bounds"])
    renderer = stipple.Renderer(cloud, backend=a.backend)
    framed = stipple.Camera.framing(cloud, size=a.size)
    target = np.array(framed.target)
    offset = np.array(framed.eye) - target
    up = np.array(framed.up)
    a.out.mkdir(parents=True, exist_ok=True)
    for k in range(a.views):
        # Turn the framed view about the up axis (Rodrigues' rotation).
        t = 2 * np.pi * k / a.views
        u = up / np.linalg.norm(up)
        rotated = offset * np.cos(t) + np.cross(u, offset) * np.sin(t) + u * (u @ offset) * (1 - np.cos(t))
        result = renderer.render(framed.replace(eye=target + rotated))
        Image.fromarray(result.image).save(a.out / f"view-{k:03}.png")
        covered = np.isfinite(result.depth).mean()
        print(f"view {k:3}: {result.ms:6.1f} ms, {result.pipeline}, {100 * covered:.0f}% of the image covered")
    print(f"wrote {a.views} views to {a.out}/ on {renderer.backend}")


if __name__ == "__main__":
    main()
