import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="session")
def cli():
    """The `stipple` binary of the same build (the Rust harness passes it)."""
    path = os.environ.get("STIPPLE_CLI") or shutil.which("stipple")
    if not path:
        pytest.skip("the stipple command line is not built (run `cargo test --workspace`)")
    return path


@pytest.fixture(scope="session")
def data():
    """../shared/data, where the harness found it."""
    d = os.environ.get("STIPPLE_DATA")
    if not d or not Path(d).exists():
        pytest.skip("../shared/data is absent")
    return Path(d)


def run_cli(cli, *args):
    r = subprocess.run([cli, *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, f"stipple {' '.join(map(str, args))}:\n{r.stdout}{r.stderr}"
    return r


def read_png(path):
    from PIL import Image

    with Image.open(path) as im:
        assert im.mode == "RGBA"
        return np.asarray(im).copy()


def wavy_sheet(n, seed=3):
    """A surface nobody else uses: z = 0.15 sin(3x) cos(2y) over [-1, 1]², with normals."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.0, 1.0, size=(n, 2))
    x, y = xy[:, 0], xy[:, 1]
    z = 0.15 * np.sin(3 * x) * np.cos(2 * y)
    p = np.stack([x, y, z], axis=1)
    dzdx = 0.45 * np.cos(3 * x) * np.cos(2 * y)
    dzdy = -0.3 * np.sin(3 * x) * np.sin(2 * y)
    nrm = np.stack([-dzdx, -dzdy, np.ones_like(x)], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    col = np.clip((p + 1.0) * 120, 0, 255).astype(np.uint8)
    return p, nrm, col
