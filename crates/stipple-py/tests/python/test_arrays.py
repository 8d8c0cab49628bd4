"""Clouds from NumPy arrays: what is kept, what is refused."""

import numpy as np
import pytest
import stipple
from conftest import wavy_sheet


def test_positions_keep_lidar_precision_with_an_f64_origin():
    rng = np.random.default_rng(1)
    base = np.array([637_000.25, 851_000.5, 120.0])
    p = base + rng.uniform(0, 300, size=(5000, 3))
    c = stipple.Cloud(p)
    # float32 alone would round 637 000 m to 6 cm; offsets from the bounds' centre keep < 0.1 mm.
    assert np.abs(c.positions - p).max() < 1e-4
    o = c.origin
    assert np.allclose(o, (p.min(0) + p.max(0)) / 2)
    c2 = stipple.Cloud(p, origin=tuple(base))
    assert c2.origin == tuple(base)
    assert np.abs(c2.positions - p).max() < 1e-4
    info = c.info()
    assert info["count"] == 5000
    assert np.allclose(info["bounds"][0], p.min(0), atol=1e-4)
    assert np.allclose(info["bounds"][1], p.max(0), atol=1e-4)
    assert info["attributes"] == []
    assert info["spacing"] > 0


def test_float32_positions_and_every_column_round_trip():
    p, n, col = wavy_sheet(3000)
    p32 = p.astype(np.float32)
    inten = np.arange(3000, dtype=np.uint16)
    alpha = np.linspace(0, 1, 3000)
    cls = (np.arange(3000) % 7).astype(np.uint8)
    c = stipple.Cloud(p32, normals=n, colors=col, intensity=inten, opacity=alpha, classification=cls)
    assert len(c) == 3000
    assert c.origin == (0.0, 0.0, 0.0)
    assert np.array_equal(c.positions, p32.astype(np.float64))
    assert np.allclose(c.normals, n, atol=1e-6)
    assert np.array_equal(c.colors, col)
    assert np.array_equal(c.intensity, inten)
    assert np.allclose(c.opacity, alpha, atol=1e-7)
    assert np.array_equal(c.classification, cls)
    assert set(c.info()["attributes"]) == {"normals", "colors", "intensity", "classification", "opacity"}


@pytest.mark.parametrize(
    "colors, expected",
    [
        (np.array([[0, 128, 255]], dtype=np.uint8), [0, 128, 255]),
        (np.array([[0, 32768, 65535]], dtype=np.uint16), [0, 128, 255]),
        (np.array([[0.0, 0.5, 1.0]], dtype=np.float32), [0, 128, 255]),
        (np.array([[0.0, 0.5, 1.0]]), [0, 128, 255]),
    ],
)
def test_colour_dtypes(colors, expected):
    c = stipple.Cloud(np.zeros((1, 3)), colors=colors)
    assert c.colors.tolist() == [expected]


def test_intensity_of_any_integer_or_float_dtype():
    for dt in (np.uint8, np.uint16, np.int32, np.int64, np.uint32, np.float32, np.float64):
        c = stipple.Cloud(np.zeros((3, 3)), intensity=np.array([0, 7, 200], dtype=dt))
        assert len(c) == 3


BAD = [
    (dict(positions=np.zeros((5, 2))), "positions: expected shape (N, 3)"),
    (dict(positions=np.zeros((5, 3, 1))), "positions: expected shape (N, 3)"),
    (dict(positions=np.zeros((0, 3))), "positions: the cloud has no points"),
    (dict(positions=np.array([[0, 0, 0], [0, np.nan, 0]], dtype=float)), "positions: row 1 is not finite"),
    (dict(positions=np.array([[0, 0, np.inf]], dtype=np.float32)), "positions: row 0 is not finite"),
    (dict(positions=np.zeros((5, 3), dtype=np.int64)), "positions: dtype int64 is not supported"),
    (dict(positions=[[0, 0, 0]]), "positions: expected a NumPy array"),
    (dict(positions=np.zeros((5, 3)), normals=np.zeros((4, 3))), "normals: 4 rows, but positions has 5"),
    (dict(positions=np.zeros((2, 3)), normals=np.array([[0, 0, 1], [np.nan, 0, 0]])), "normals: row 1 is not finite"),
    (dict(positions=np.zeros((2, 3)), colors=np.full((2, 3), 1.5)), "colors: float colours must lie in 0..1"),
    (dict(positions=np.zeros((2, 3)), colors=np.zeros((2, 4), dtype=np.uint8)), "colors: expected shape (N, 3)"),
    (dict(positions=np.zeros((2, 3)), colors=np.zeros((2, 3), dtype=np.int8)), "colors: dtype int8 is not supported"),
    (dict(positions=np.zeros((2, 3)), opacity=np.array([0.5, 1.5])), "opacity: values must lie in 0..1"),
    (dict(positions=np.zeros((2, 3)), intensity=np.array([-1, 3])), "intensity: values must lie in 0..65535"),
    (dict(positions=np.zeros((2, 3)), classification=np.zeros(2, dtype=np.int64)), "classification: dtype int64"),
    (dict(positions=np.zeros((2, 3)), origin=(0.0, float("nan"), 0.0)), "origin: must be finite"),
]


@pytest.mark.parametrize("kwargs, message", BAD)
def test_bad_arrays_raise_value_errors_naming_the_argument(kwargs, message):
    with pytest.raises(ValueError) as e:
        stipple.Cloud(**kwargs)
    assert message in str(e.value)


def test_strided_and_fortran_arrays_are_read_in_logical_order():
    rng = np.random.default_rng(4)
    wide = rng.uniform(-1, 1, size=(1000, 6))
    records = np.zeros(1000, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", "u2")])
    records["intensity"] = np.arange(1000)
    for p in (wide[:, :3], wide[:, ::2], np.asfortranarray(wide[:, 3:]), wide[::-1, 1:4]):
        assert not p.flags.c_contiguous
        c = stipple.Cloud(p, intensity=records["intensity"], colors=(np.abs(wide[:, :3]) * 255).astype(np.uint8)[::1])
        assert np.abs(c.positions - p).max() < 1e-6
    # A structured array's field (laspy's columns) is a strided view too.
    assert not records["intensity"].flags.c_contiguous
    c = stipple.Cloud(wide[:, :3].copy(), intensity=records["intensity"])
    assert np.array_equal(c.intensity, np.arange(1000))


def test_a_cloud_is_not_changed_by_the_callers_array_afterwards():
    p = np.zeros((10, 3))
    p[:, 0] = np.arange(10)
    c = stipple.Cloud(p)
    p[:] = 99.0
    assert c.positions[:, 0].tolist() == list(range(10))


def test_save_never_replaces_a_file_unless_asked(tmp_path):
    p, n, col = wavy_sheet(500)
    c = stipple.Cloud(p, normals=n, colors=col)
    out = tmp_path / "c.ply"
    c.save(out)
    before = out.read_bytes()
    with pytest.raises(FileExistsError):
        c.save(out)
    assert out.read_bytes() == before
    back = stipple.read(out)
    assert len(back) == 500
    assert np.abs(back.positions - p).max() < 1e-5
    c.save(out, overwrite=True)
    with pytest.raises(ValueError, match="cannot write"):
        c.save(tmp_path / "c.obj")


def test_read_errors():
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        stipple.read("/nonexistent/nope.ply")


def test_read_malformed_file(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 999999999999\nproperty float x\nend_header\n")
    with pytest.raises((ValueError, OSError), match="bad.ply"):
        stipple.read(bad)


def test_demo_scenes():
    c = stipple.demo("torus", points=1000)
    assert len(c) == 1000
    with pytest.raises(ValueError, match="unknown scene"):
        stipple.demo("teapot")


def test_a_volume_through_a_transfer_function(tmp_path):
    # A 12-cube ball of value 200 in a background of 0 (radius 4 samples).
    n = 12
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    inside = (x - 5.5) ** 2 + (y - 5.5) ** 2 + (z - 5.5) ** 2 < 16
    vol = tmp_path / "ball_12x12x12_uint8.raw"
    (inside.astype(np.uint8) * 200).tofile(vol)
    cloud = stipple.read(vol, transfer="100 40 200 60 0; 150 40 200 60 0.5")
    assert len(cloud) == int(inside.sum())
    assert np.all(cloud.colors == np.array([40, 200, 60], dtype=np.uint8))
    assert np.allclose(cloud.opacity, 0.5, atol=1 / 255)
    with pytest.raises(ValueError, match="transfer"):
        stipple.read(vol, transfer="1 2 3")
    with pytest.raises(ValueError, match="iso and transfer"):
        stipple.read(vol, iso=100.0, transfer="0 0 0 0 1")
