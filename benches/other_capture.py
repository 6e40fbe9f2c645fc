#!/usr/bin/env python3
"""A capture written by another program than jawtrack: its own rasteriser, camera rig, motion,
lips and segmentation errors, to the capture format alone (../shared/spec/capture-format.md).

jawtrack's own captures (`synth`) are drawn by the tracker's own rasteriser, with its own motion
model and noise: a convention that both share (where a pixel's centre is, how masks smaller than
the image scale the intrinsics, which faces make the boundary of interest) cancels there and
would not on a user's capture. This program shares no code with jawtrack (Python and numpy):

  - meshes read from OBJ and written as binary PLY; the boundary of interest as face-index lists
    (faces within 1.5 mm of each front tooth's incisal edge, its own rule);
  - the lower arch placed in the rest bite by raising it under the upper until the crowns touch
    (no overjet, midline or interdigitation assumed: the scans' own x and z);
  - cameras on an arc 170-230 mm from the incisors, 1920x1080 calibrated, masks at half size
    (intrinsics scaled as the spec says), optional radial distortion;
  - the jaw turning about a hinge 95 mm behind and 28 mm above the incisal edge, its condyles
    sliding forwards 0.25 mm a degree past 8 degrees, with a lateral swing about the working
    side's condyle, opened further wherever the crowns would pass through each other; the head
    drifting and nodding;
  - a z-buffer rasteriser with pixel centres at integer coordinates (the spec's convention),
    depth interpolated as 1/z;
  - lips as two 3D curves in front of each arch's crowns (the opening follows the jaw); teeth
    outside the opening are hidden, the opening's other pixels are the mouth interior;
  - segmentation errors (`--noise`): `clean`; `tool`, a tool's bias: each camera's teeth grown
    or shrunk by one pixel (drawn per camera), for the whole take; `rough`, per frame: each
    pixel of the teeth's edge lost with probability 0.3, and three small blobs of teeth missed.

Usage:
  other_capture.py OUT --scans DIR [--frames 34] [--seed S] [--noise clean|tool|rough]
                       [--distortion K1] [--cameras 3] [--photos none|clean|hard]

Writes OUT/capture.json, cameras/, meshes/ (PLY + .boi.json), masks/, init.json (the first
frame's true poses), gt/poses.json. Needs numpy. With `--photos`, colour pictures instead of
masks (images/, drawn by benches/other_photos.py), and the true labels in gt/masks/.
"""
import argparse, json, math, os, struct, zlib
import numpy as np

import other_photos

UPPER, LOWER, MOUTH = 1, 2, 3


def read_obj(path):
    v, f = [], []
    for line in open(path):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            idx = [int(t.split("/")[0]) for t in line.split()[1:]]
            idx = [i - 1 if i > 0 else len(v) + i for i in idx]
            for k in range(1, len(idx) - 1):
                f.append([idx[0], idx[k], idx[k + 1]])
    return np.array(v, float), np.array(f, np.int64)


def write_ply(path, v, f):
    with open(path, "wb") as out:
        out.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
                   "property float x\nproperty float y\nproperty float z\n"
                   "element face %d\nproperty list uchar int vertex_indices\nend_header\n"
                   % (len(v), len(f))).encode())
        out.write(v.astype("<f4").tobytes())
        rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rec["n"], rec["i"] = 3, f
        out.write(rec.tobytes())


def rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def incisal_band(v, f, tip_sign, width_mm=1.5, front_mm=12.0):
    """Faces of the front teeth within width_mm of the incisal edge (tip_sign: -1 the upper's
    tips point down, +1 the lower's up)."""
    c = v[f].mean(axis=1)
    front = c[:, 2] > v[:, 2].max() - front_mm
    tip = np.full(len(c), -np.inf)
    cols = np.round(c[:, 0]).astype(int)
    for x in np.unique(cols[front]):
        sel = front & (cols == x)
        tip[sel] = (tip_sign * c[sel, 1]).max()
    return np.nonzero(front & (tip_sign * c[:, 1] > tip - width_mm))[0]


def column_heights(v):
    """Per 0.5 mm column of the occlusal plane (x, z), the lowest y of the points: the columns'
    codes, sorted, and their heights."""
    cells = np.round(v[:, [0, 2]] / 0.5).astype(int)
    code = cells[:, 0] * 100003 + cells[:, 1]
    keys, inverse = np.unique(code, return_inverse=True)
    low = np.full(len(keys), np.inf)
    np.minimum.at(low, inverse, v[:, 1])
    return keys, low


def clearance(upper_low, lower_points):
    """How far (mm) the lower arch's points stay below the upper's crowns, column by column
    (negative: they pass through them)."""
    keys, low = upper_low
    cells = np.round(lower_points[:, [0, 2]] / 0.5).astype(int)
    # Each point's column among the upper's (sorted) columns, where it has one.
    code = lambda c: c[:, 0] * 100003 + c[:, 1]
    at = np.searchsorted(keys, code(cells))
    at = np.minimum(at, len(keys) - 1)
    hit = keys[at] == code(cells)
    return float((low[at[hit]] - lower_points[hit, 1]).min()) if hit.any() else np.inf


def look_at(centre, target, up=(0, 1, 0)):
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])
    return r, -r @ centre


def project(cam, p):
    """World points to pixel coordinates of the masks (and depth)."""
    pc = p @ cam["R"].T + cam["t"]
    x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
    k1 = cam["k1"]
    r2 = x * x + y * y
    x, y = x * (1 + k1 * r2), y * (1 + k1 * r2)
    s = cam["scale"]
    u = cam["fx"] * s * x + (cam["cx"] + 0.5) * s - 0.5
    w = cam["fy"] * s * y + (cam["cy"] + 0.5) * s - 0.5
    return np.stack([u, w], 1), pc[:, 2]


def rasterise(cam, items, w, h, faces_too=False):
    """items: (world vertices, faces, label). The label image, nearest surface wins (and, with
    faces_too, the face drawn at each pixel: its index among all items' faces in order, -1)."""
    pix, depth, lab, fid = [], [], [], []
    offset = 0
    for verts, faces, label in items:
        uv, z = project(cam, verts)
        a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
        iz = 1.0 / z[faces]
        lo = np.ceil(np.minimum(np.minimum(a, b), c)).astype(int)
        hi = np.floor(np.maximum(np.maximum(a, b), c)).astype(int)
        area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        ok = (np.abs(area) > 1e-12) & (hi[:, 0] >= lo[:, 0]) & (hi[:, 1] >= lo[:, 1])
        span = np.maximum(hi - lo + 1, 0).max(axis=1)
        for k in np.unique(span[ok]):
            sel = np.nonzero(ok & (span == k))[0]
            for dy in range(k):
                for dx in range(k):
                    px, py = lo[sel, 0] + dx, lo[sel, 1] + dy
                    def edge(p, q):
                        return (q[sel, 0] - p[sel, 0]) * (py - p[sel, 1]) - (q[sel, 1] - p[sel, 1]) * (px - p[sel, 0])
                    e0, e1, e2 = edge(b, c), edge(c, a), edge(a, b)
                    sgn = np.sign(area[sel])
                    inside = (e0 * sgn >= 0) & (e1 * sgn >= 0) & (e2 * sgn >= 0)
                    inside &= (px <= hi[sel, 0]) & (py <= hi[sel, 1]) & (px >= 0) & (py >= 0) & (px < w) & (py < h)
                    if not inside.any():
                        continue
                    l0, l1, l2 = e0 / area[sel], e1 / area[sel], e2 / area[sel]
                    inv = l0 * iz[sel, 0] + l1 * iz[sel, 1] + l2 * iz[sel, 2]
                    pix.append((py * w + px)[inside])
                    depth.append(inv[inside])
                    lab.append(np.full(inside.sum(), label, np.uint8))
                    fid.append(offset + sel[inside])
        offset += len(faces)
    out = np.zeros(w * h, np.uint8)
    drawn = np.full(w * h, -1, np.int64)
    if pix:
        pix, depth, lab, fid = (np.concatenate(x) for x in (pix, depth, lab, fid))
        order = np.lexsort((-depth, pix))
        first = np.ones(len(order), bool)
        first[1:] = pix[order][1:] != pix[order][:-1]
        out[pix[order][first]] = lab[order][first]
        drawn[pix[order][first]] = fid[order][first]
    if faces_too:
        return out.reshape(h, w), drawn.reshape(h, w)
    return out.reshape(h, w)


LIP_XS = np.linspace(-23.0, 23.0, 47)


def lip_curve(v, tip_sign, show_mm):
    """A lip's edge in an arch's frame: for each x across the mouth (LIP_XS), show_mm from the
    crowns' tips towards the gums, 2 mm in front of the labial surface."""
    pts = []
    for x in LIP_XS:
        col = v[np.abs(v[:, 0] - x) < 1.0]
        z = col[:, 2].max()
        tip = (tip_sign * col[col[:, 2] > z - 8.0, 1]).max() * tip_sign
        pts.append([x, tip - tip_sign * show_mm, z + 2.0])
    return np.array(pts)


def lip_opening(top, bottom, xs, half_width=23.0):
    """The lips' opening in a picture: the two lip edges (image points at the same xs across
    the mouth) pinched together towards the corners."""
    c = ((np.abs(xs) / half_width) ** 4)[:, None]
    mid = 0.5 * (top + bottom)
    return np.concatenate([top * (1 - c) + mid * c, (bottom * (1 - c) + mid * c)[::-1]])


def fill_polygon(poly, w, h):
    """Pixels whose centres lie inside a closed polygon (even-odd rule)."""
    out = np.zeros((h, w), bool)
    lo = np.clip(np.floor(poly.min(axis=0)).astype(int), 0, [w - 1, h - 1])
    hi = np.clip(np.ceil(poly.max(axis=0)).astype(int) + 1, 0, [w, h])
    ys, xs = np.mgrid[lo[1]:hi[1], lo[0]:hi[0]]
    inside = np.zeros(ys.shape, bool)
    n = len(poly)
    for i in range(n):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % n]
        if y0 == y1:
            continue
        cross = ((y0 <= ys) & (ys < y1)) | ((y1 <= ys) & (ys < y0))
        xi = x0 + (ys - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (xs < xi)
    out[lo[1]:hi[1], lo[0]:hi[0]] = inside
    return out


def shifted(mask, dx, dy):
    out = np.zeros_like(mask)
    h, w = mask.shape
    out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = \
        mask[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return out


def grow(mask, px):
    """The mask grown (px > 0) or shrunk (px < 0) by |px| pixels (4-neighbours)."""
    m = mask.copy()
    for _ in range(abs(px)):
        nb = [shifted(m, 1, 0), shifted(m, -1, 0), shifted(m, 0, 1), shifted(m, 0, -1)]
        m = (m | nb[0] | nb[1] | nb[2] | nb[3]) if px > 0 else (m & nb[0] & nb[1] & nb[2] & nb[3])
    return m


def write_png(path, image):
    """An 8-bit grey (h x w) or RGB (h x w x 3) PNG."""
    h, w = image.shape[:2]
    colour = 2 if image.ndim == 3 else 0
    raw = b"".join(b"\x00" + image[y].tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def pose_json(r, t):
    return {"rotation": r.tolist(), "translation": list(map(float, t))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--scans", required=True)
    ap.add_argument("--frames", type=int, default=34)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise", choices=["clean", "tool", "rough"], default="clean")
    ap.add_argument("--distortion", type=float, default=0.0)
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--photos", choices=["none", "clean", "hard"], default="none",
                    help="write colour pictures (images/) and the true labels to gt/masks/ instead of masks")
    ap.add_argument("--boi-depth", type=float, default=12.0,
                    help="how far back from the frontmost tooth (mm) the incisal band reaches")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    os.makedirs(a.out, exist_ok=True)
    for d in ["cameras", "meshes", "gt"]:
        os.makedirs(os.path.join(a.out, d), exist_ok=True)

    vu, fu = read_obj(os.path.join(a.scans, "upper.obj"))
    vl, fl = read_obj(os.path.join(a.scans, "lower.obj"))
    for name, v, f, sign in [("upper", vu, fu, -1), ("lower", vl, fl, 1)]:
        write_ply(os.path.join(a.out, "meshes", name + ".ply"), v, f)
        band = incisal_band(v, f, sign, front_mm=a.boi_depth)
        json.dump(band.tolist(), open(os.path.join(a.out, "meshes", name + ".boi.json"), "w"))

    # The lower arch in the rest bite, in the upper's frame: raised until it touches.
    upper_low = column_heights(vu)
    bite_t = np.array([0.0, clearance(upper_low, vl) - 0.1, 0.0])
    tip = np.array([0.0, vu[:, 1].min(), vu[:, 2].max()])
    hinge = tip + np.array([0.0, 28.0, -95.0])
    vl_probe = vl[::3]

    def jaw_pose(open_deg, lateral):
        """The lower arch's frame in the upper's (rotation, origin) for these controls."""
        slide = 0.25 * max(open_deg - 8, 0)
        condyle = hinge + np.array([50.0 * np.sign(lateral), 0, 0])
        r_open, r_lat = rot([1, 0, 0], math.radians(open_deg)), rot([0, 1, 0], lateral)

        def move(p):
            q = p + bite_t
            q = (q - hinge) @ r_open.T + hinge + np.array([0, -0.3 * slide, slide])
            return (q - condyle) @ r_lat.T + condyle

        origin = move(np.zeros((1, 3)))[0]
        return np.stack([move(np.eye(3)[k:k + 1])[0] - origin for k in range(3)], 1), origin

    lip_u = lip_curve(vu, -1, show_mm=rng.uniform(7.0, 9.0))
    lip_l = lip_curve(vl, 1, show_mm=rng.uniform(4.5, 6.5))

    # Cameras on an arc in front of the incisors (world = the upper's frame at frame 0).
    names = ["cam%d" % k for k in range(a.cameras)]
    cams = []
    for k, name in enumerate(names):
        az = math.radians(np.interp(k, [0, max(a.cameras - 1, 1)], [-32, 32]) + rng.uniform(-4, 4))
        el = math.radians(rng.uniform(-8, 12))
        dist = rng.uniform(170, 230)
        centre = tip + dist * np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
        r, t = look_at(centre, tip + np.array([0, -6.0, -8.0]))
        f = rng.uniform(1300, 1600)
        cam = {"width": 1920, "height": 1080, "fx": f, "fy": f * rng.uniform(0.998, 1.002),
               "cx": 959.5 + rng.uniform(-20, 20), "cy": 539.5 + rng.uniform(-15, 15),
               "R": r, "t": t, "k1": a.distortion if k == 0 else 0.0, "scale": 0.5}
        cams.append(cam)
        js = {key: cam[key] for key in ["width", "height", "fx", "fy", "cx", "cy"]}
        js["distortion"] = [cam["k1"], 0.0, 0.0, 0.0, 0.0]
        js["rotation"], js["translation"] = r.tolist(), t.tolist()
        json.dump(js, open(os.path.join(a.out, "cameras", name + ".json"), "w"), indent=1)

    capture = {"format": "jawtrack-capture/1", "cameras": names,
               "frames": {"first": 0, "count": a.frames},
               "meshes": {"upper": "meshes/upper.ply", "lower": "meshes/lower.ply"},
               "boi": {"upper": "meshes/upper.boi.json", "lower": "meshes/lower.boi.json"},
               "masks": {"dir": "masks", "mode": "per-arch", "upper": UPPER, "lower": LOWER, "mouth": MOUTH}}
    json.dump(capture, open(os.path.join(a.out, "capture.json"), "w"), indent=1)

    bias = {name: int(rng.choice([-1, 1])) for name in names}
    phase = rng.uniform(0, 2 * math.pi, 8)

    def poses_at(i):
        """The arches' poses (r_u, t_u, r_l, t_l) at frame i (fractional within a shutter)."""
        s = i / 33.0  # the pace: one cycle of the head's drift every 34 frames, whatever the count
        # The head: a slow drift and nod.
        r_head = rot([1, 0, 0], math.radians(4 * math.sin(2 * math.pi * s + phase[0]))) @ \
            rot([0, 1, 0], math.radians(5 * math.sin(2 * math.pi * 0.7 * s + phase[1])))
        t_head = np.array([3 * math.sin(2 * math.pi * s + phase[2]), 2 * math.sin(2 * math.pi * 1.3 * s + phase[3]),
                           4 * math.sin(2 * math.pi * 0.5 * s + phase[4])])
        # The jaw: opening 2-26 degrees, the condyles sliding forwards past 8, a lateral swing
        # about the working side's condyle (the other one slides forwards, never back into the
        # fossa); opened further where the crowns would pass through each other (the teeth
        # guide the jaw).
        lateral = math.radians(3.5 * math.sin(2 * math.pi * s + phase[6]))
        open_deg = 14 - 12 * math.cos(2 * math.pi * 1.5 * s + phase[5])
        while True:
            r_jaw, origin = jaw_pose(open_deg, lateral)
            if clearance(upper_low, vl_probe @ r_jaw.T + origin) >= 0.0 or open_deg > 40:
                break
            open_deg += 0.25
        return r_head, t_head, r_head @ r_jaw, r_head @ origin + t_head

    if a.photos != "none":
        colours = other_photos.subject(rng)
        normals_u, normals_l = other_photos.face_normals(vu, fu), other_photos.face_normals(vl, fl)
    gt = []
    w, h = 960, 540
    for i in range(a.frames):
        r_u, t_u, r_l, t_l = poses_at(i)
        gt.append({"frame": i, "upper": pose_json(r_u, t_u), "lower": pose_json(r_l, t_l)})
        wu, wl = vu @ r_u.T + t_u, vl @ r_l.T + t_l
        for cam, name in zip(cams, names):
            labels = rasterise(cam, [(wu, fu, UPPER), (wl, fl, LOWER)], w, h)
            top, _ = project(cam, lip_u @ r_u.T + t_u)
            bottom, _ = project(cam, lip_l @ r_l.T + t_l)
            opening_px = fill_polygon(lip_opening(top, bottom, LIP_XS), w, h)
            out = np.where(opening_px, np.where(labels > 0, labels, MOUTH), 0).astype(np.uint8)
            if a.photos != "none":
                # The picture, drawn at twice the size over the shutter's poses; the labels
                # (the middle pose's) are the truth, and the masks are left to segment.
                big = dict(cam, scale=1.0)
                renders = []
                for di in ([-0.25, 0.0, 0.25] if a.photos == "hard" else [0.0]):
                    ru, tu, rl, tl = poses_at(i + di)
                    su, sl = vu @ ru.T + tu, vl @ rl.T + tl
                    look, fid = rasterise(big, [(su, fu, UPPER), (sl, fl, LOWER)], 2 * w, 2 * h, faces_too=True)
                    top2, _ = project(big, lip_u @ ru.T + tu)
                    bottom2, _ = project(big, lip_l @ rl.T + tl)
                    opening2 = fill_polygon(lip_opening(top2, bottom2, LIP_XS), 2 * w, 2 * h)
                    normals = np.concatenate([normals_u @ ru.T, normals_l @ rl.T])
                    renders.append(other_photos.shade(look, fid, normals, opening2, colours,
                                                      -cam["R"][2], a.photos == "hard", rng))
                picture = other_photos.photo(renders, colours, i, a.frames, a.photos == "hard", rng)
                for sub, image in [("images", picture), (os.path.join("gt", "masks"), out)]:
                    d = os.path.join(a.out, sub, name)
                    os.makedirs(d, exist_ok=True)
                    write_png(os.path.join(d, "%06d.png" % i), image)
                continue
            if a.noise == "tool":
                for lab in (UPPER, LOWER):
                    m = out == lab
                    grown = grow(m, bias[name])
                    if bias[name] > 0:
                        out[grown & ((out == MOUTH) | (out == 0))] = lab
                    else:
                        out[m & ~grown] = np.where(opening_px[m & ~grown], MOUTH, 0)
            elif a.noise == "rough":
                teeth = (out == UPPER) | (out == LOWER)
                edge = teeth ^ grow(teeth, -1)
                flip = edge & (rng.random(out.shape) < 0.3)
                out[flip] = np.where(opening_px[flip], MOUTH, 0)
                for _ in range(3):
                    y, x = rng.integers(0, h), rng.integers(0, w)
                    blob = (np.add.outer((np.arange(h) - y) ** 2, (np.arange(w) - x) ** 2) < rng.uniform(4, 16))
                    out[blob & teeth] = MOUTH
            d = os.path.join(a.out, "masks", name)
            os.makedirs(d, exist_ok=True)
            write_png(os.path.join(d, "%06d.png" % i), out)
    json.dump({"format": "jawtrack-tracks/1", "frames": gt}, open(os.path.join(a.out, "gt", "poses.json"), "w"))
    json.dump({"upper": gt[0]["upper"], "lower": gt[0]["lower"]}, open(os.path.join(a.out, "init.json"), "w"))


if __name__ == "__main__":
    main()
