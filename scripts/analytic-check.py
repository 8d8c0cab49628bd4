#!/usr/bin/env python3
"""`stipple render` at its default settings on an analytic shape, measured against the
exact surface (the surface goals of issue "Surfaces from any cloud", end to end through the
CLI: the pipeline `auto` picks, the camera it frames, the depth and normal outputs).

usage: scripts/analytic-check.py SHAPE N SEED MODE [render args...]
  SHAPE  sphere | torus | thin-torus | fat-torus | box | cylinder | ellipsoid | capsule
         (tori of radii 1 and 0.35, 0.2, 0.5), roundbox (a box rounded by 0.15), bumpy (a sphere of radius 0.9 with bumps of
         0.06 and wavelength about 1); open: wave (a height field over a square),
         bowl (half a sphere), whose normals are compared up to sign
  N      points, area-uniform on the surface
  MODE   given (exact normals) | none (no normals) | random (exact normals, random sign)
  env    STIPPLE (the binary; target/release/stipple), OUT (a scratch folder;
         /tmp/stipple-analytic), SCALE (the shape's size, 1), OFFSET (x,y,z of its centre,
         0,0,0; written as doubles where not zero)

Prints one line: ok/FAIL, the mean nearest-neighbour distance in pixels at the median
depth, the silhouette IoU, the share of pixels whose depth is within 0.5% of the depth
range, the share showing a surface behind (5% of the range deeper), the median and 90th
percentile of the normal error in degrees, and the pipeline line stipple printed. The truth
is sphere-traced per pixel from the camera `--camera-out` writes. Needs numpy.
"""
import json, subprocess, sys, os
import numpy as np

BIN = os.environ.get("STIPPLE", "target/release/stipple")
OUT = os.environ.get("OUT", "/tmp/stipple-analytic")


def sd_sphere(p):
    return np.linalg.norm(p, axis=-1) - 1.0


def torus(small):
    def sd(p):
        q = np.stack([np.hypot(p[..., 0], p[..., 1]) - 1.0, p[..., 2]], -1)
        return np.linalg.norm(q, axis=-1) - small
    return sd


sd_torus = torus(0.35)


def sd_box(p, b=np.array([0.8, 0.6, 0.5])):
    q = np.abs(p) - b
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def sd_roundbox(p, b=np.array([0.7, 0.5, 0.4]), r=0.15):
    q = np.abs(p) - b
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0) - r


def sd_cyl(p):
    d = np.stack([np.hypot(p[..., 0], p[..., 2]) - 0.6, np.abs(p[..., 1]) - 0.8], -1)
    return np.minimum(d.max(-1), 0) + np.linalg.norm(np.maximum(d, 0), axis=-1)


def sd_ellipsoid(p, r=np.array([1.0, 0.6, 0.45])):
    k0 = np.linalg.norm(p / r, axis=-1)
    k1 = np.linalg.norm(p / (r * r), axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def sd_capsule(p):
    x = np.clip(p[..., 0], -0.6, 0.6)
    q = p.copy()
    q[..., 0] -= x
    return np.linalg.norm(q, axis=-1) - 0.4


def sd_bumpy(p):
    # A sphere of radius 0.9 with bumps of 0.06 (wavelength about 1); f / |grad f| is a
    # distance to first order.
    r = np.maximum(np.linalg.norm(p, axis=-1), 1e-9)
    s, c = np.sin(6 * p), np.cos(6 * p)
    f = r - 0.9 - 0.06 * s[..., 0] * s[..., 1] * s[..., 2]
    g = p / r[..., None] - 0.36 * np.stack(
        [c[..., 0] * s[..., 1] * s[..., 2], s[..., 0] * c[..., 1] * s[..., 2],
         s[..., 0] * s[..., 1] * c[..., 2]], -1)
    return f / np.linalg.norm(g, axis=-1)


def h_wave(x, y):
    return 0.25 * np.sin(2 * x) * np.cos(1.5 * y)


def h_wave_grad(x, y):
    return 0.5 * np.cos(2 * x) * np.cos(1.5 * y), -0.375 * np.sin(2 * x) * np.sin(1.5 * y)


def ud_wave(p):
    # Open: a height field over [-1, 1]^2 (distance to first order, unsigned).
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    cx, cy = np.clip(x, -1, 1), np.clip(y, -1, 1)
    gx, gy = h_wave_grad(cx, cy)
    s = (z - h_wave(cx, cy)) / np.sqrt(1 + gx * gx + gy * gy)
    return np.sqrt(s * s + (x - cx) ** 2 + (y - cy) ** 2)


def n_wave(p):
    gx, gy = h_wave_grad(np.clip(p[..., 0], -1, 1), np.clip(p[..., 1], -1, 1))
    n = np.stack([-gx, -gy, np.ones_like(gx)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def s_wave(n, rng):
    out = []
    while sum(len(o) for o in out) < n:
        x, y = rng.random((2, 4 * n)) * 2 - 1
        gx, gy = h_wave_grad(x, y)
        a = np.sqrt(1 + gx * gx + gy * gy)
        k = rng.random(4 * n) * 1.7 < a
        out.append(np.stack([x[k], y[k], h_wave(x[k], y[k])], -1))
    return np.concatenate(out)[:n]


def ud_bowl(p):
    # Open: the unit sphere's half below y = 0.
    r = np.linalg.norm(p, axis=-1)
    rim = np.hypot(np.hypot(p[..., 0], p[..., 2]) - 1, p[..., 1])
    return np.where(p[..., 1] <= 0, np.abs(r - 1), rim)


def n_bowl(p):
    return p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), 1e-12)


def s_bowl(n, rng):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:, 1] = -np.abs(d[:, 1])
    return d


# Open surfaces: (unsigned distance, normal, sampler); their normals' sign is not defined,
# so the normal error is measured up to sign.
OPEN = {"wave": (ud_wave, n_wave, s_wave), "bowl": (ud_bowl, n_bowl, s_bowl)}

SHAPES = {
    "sphere": (sd_sphere, 1.1),
    "torus": (sd_torus, 1.4),
    "thin-torus": (torus(0.2), 1.25),
    "fat-torus": (torus(0.5), 1.55),
    "box": (sd_box, 0.9),
    "roundbox": (sd_roundbox, 0.95),
    "cylinder": (sd_cyl, 0.9),
    "ellipsoid": (sd_ellipsoid, 1.05),
    "capsule": (sd_capsule, 1.05),
    "bumpy": (sd_bumpy, 1.05),
    "wave": (ud_wave, 1.0),
    "bowl": (ud_bowl, 1.0),
}


def grad(sdf, p, e=1e-5):
    g = np.zeros_like(p)
    for i in range(3):
        d = np.zeros(3)
        d[i] = e
        g[..., i] = (sdf(p + d) - sdf(p - d)) / (2 * e)
    n = np.linalg.norm(g, axis=-1, keepdims=True)
    return g / np.maximum(n, 1e-12)


def sample(sdf, lim, n, rng):
    out = []
    have = 0
    while have < n:
        p = (rng.random((max(4 * n, 100000), 3)) * 2 - 1) * lim
        p = p[np.abs(sdf(p)) < 0.01]
        for _ in range(8):
            p = p - grad(sdf, p) * sdf(p)[..., None]
        p = p[np.abs(sdf(p)) < 1e-6]
        out.append(p)
        have += len(p)
    p = np.concatenate(out)[:n]
    return p, grad(sdf, p)


def write_ply(path, p, nrm, double=False):
    with open(path, "wb") as f:
        hdr = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(p)
        t = "double" if double else "float"
        hdr += f"property {t} x\nproperty {t} y\nproperty {t} z\n"
        if nrm is not None:
            hdr += "property float nx\nproperty float ny\nproperty float nz\n"
        hdr += "end_header\n"
        f.write(hdr.encode())
        if nrm is None:
            f.write(p.astype("<f8" if double else "<f4").tobytes())
        else:
            rec = np.zeros(len(p), dtype=[("p", ("<f8" if double else "<f4"), 3), ("n", "<f4", 3)])
            rec["p"], rec["n"] = p, nrm
            f.write(rec.tobytes())


def main():
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    shape, n, seed, mode = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    extra = sys.argv[5:]
    if shape not in SHAPES or mode not in ("given", "none", "random"):
        sys.exit(__doc__)
    if not os.path.isfile(BIN):
        sys.exit(f"{BIN}: no such binary: build it with `cargo build --release --bin stipple` "
                 "from the repository root, or set STIPPLE to one")
    unit_sdf, lim = SHAPES[shape]
    rng = np.random.default_rng(seed)
    if shape in OPEN:
        p = OPEN[shape][2](n, rng)
        nrm = OPEN[shape][1](p)
    else:
        p, nrm = sample(unit_sdf, lim, n, rng)
    # The shape scaled and moved: the truth is traced in the same world coordinates.
    scale = float(os.environ.get("SCALE", "1"))
    off = np.array([float(v) for v in os.environ.get("OFFSET", "0,0,0").split(",")])
    p = p * scale + off

    def sdf(q):
        return unit_sdf((q - off) / scale) * scale
    if mode == "none":
        nn = None
    elif mode == "random":
        nn = nrm * np.where(rng.random(len(p)) < 0.5, -1, 1)[:, None]
    else:
        nn = nrm
    tag = f"{OUT}/{shape}-{n}-{seed}-{mode}"
    os.makedirs(OUT, exist_ok=True)
    write_ply(tag + ".ply", p, nn, double=bool(off.any()))
    for suf in [".png", ".npy", ".n.npy", ".json"]:
        if os.path.exists(tag + suf):
            os.remove(tag + suf)
    r = subprocess.run(
        [BIN, "render", tag + ".ply", "-o", tag + ".png", "--depth-out", tag + ".npy",
         "--normal-out", tag + ".n.npy", "--camera-out", tag + ".json"] + extra,
        capture_output=True, text=True)
    if r.returncode != 0:
        print(shape, n, mode, "ERROR", r.stderr.strip()[-300:])
        return
    pipe = "?"
    for line in (r.stdout + r.stderr).splitlines():
        if "drawing" in line.lower() or "pipeline" in line.lower():
            pipe = line.strip()[:80]
    cam = json.load(open(tag + ".json"))
    depth = np.load(tag + ".npy")
    nout = np.load(tag + ".n.npy")
    H, W = depth.shape
    V = np.array(cam["view"])
    P = np.array(cam["projection"])
    R = V[:3, :3]
    eye = np.array(cam["eye"])
    fwd = -R[2]
    xs = (np.arange(W) + 0.5) / W * 2 - 1
    ys = 1 - (np.arange(H) + 0.5) / H * 2
    X, Y = np.meshgrid(xs, ys)
    dv = np.stack([X / P[0, 0], Y / P[1, 1], -np.ones_like(X)], -1)
    dw = dv @ R  # view->world: R^T applied to row vectors
    dw /= np.linalg.norm(dw, axis=-1, keepdims=True)
    t = np.zeros((H, W))
    o = np.broadcast_to(eye, dw.shape)
    alive = np.ones((H, W), bool)
    hit = np.zeros((H, W), bool)
    # Open surfaces' distances, and those of the ellipsoid and the bumpy sphere, are exact
    # only to first order: damped steps keep the tracer from stepping through them.
    damped = shape in OPEN or shape in ("ellipsoid", "bumpy")
    for _ in range(1500 if damped else 400):
        q = o + dw * t[..., None]
        d = sdf(q)
        hit |= alive & (d < 1e-6 * scale)
        alive &= ~hit & (t < 1e3 * scale)
        t = np.where(alive, t + (0.8 * d if damped else d), t)
        if not alive.any():
            break
    q = o + dw * t[..., None]
    tdepth = np.where(hit, ((q - eye) @ fwd), np.inf)
    tn = OPEN[shape][1]((q - off) / scale) if shape in OPEN else grad(unit_sdf, (q - off) / scale)
    cov = np.isfinite(depth)
    inter = (cov & hit).sum()
    union = (cov | hit).sum()
    iou = inter / union
    rng_d = tdepth[hit].max() - tdepth[hit].min()
    both = cov & hit
    err = depth[both] - tdepth[both]
    within = (np.abs(err) <= 0.005 * rng_d).mean()
    behind = (err > 0.05 * rng_d).mean()
    nn_ = nout[both]
    cs = (nn_ * tn[both]).sum(-1).clip(-1, 1)
    if shape in OPEN:
        cs = np.abs(cs)
    ang = np.degrees(np.arccos(cs))
    # Spacing: the mean nearest-neighbour distance (of 1 500 points) over a pixel's
    # width at the median depth.
    zmed = np.median(tdepth[hit])
    px = 2 * zmed / P[0, 0] / W
    sub = p[np.random.default_rng(0).choice(len(p), min(1500, len(p)), replace=False)]
    best = np.full(len(sub), np.inf)
    for k in range(0, len(p), 4000):
        d2 = ((sub[:, None, :] - p[None, k:k + 4000, :]) ** 2).sum(-1)
        d2[d2 == 0] = np.inf
        best = np.minimum(best, d2.min(1))
    sp = np.mean(np.sqrt(best)) / px
    ok = iou >= 0.99 and within >= 0.95 and behind <= 0.02 and np.median(ang) <= 5 and np.percentile(ang, 90) <= 15
    print(f"{'ok  ' if ok else 'FAIL'} {shape} {n} {mode} nn_px {sp:.2f} iou {iou:.4f} depth {within:.4f} behind {behind:.4f} "
          f"nmed {np.median(ang):.2f} np90 {np.percentile(ang, 90):.2f} | {pipe}")


main()
