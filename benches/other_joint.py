#!/usr/bin/env python3
"""Jaw motion from a joint model that is not jawtrack's, and its scorer (issue 21, item 4).

jawtrack's own synthetic motion (`synth`) comes from src/anatomy/joint.rs: condyles sliding on
an S-shaped eminence, the mandible turning about the line through them, keyed exercises. A rig
tuned on that alone may lean on its quirks. This program is written apart from it (plain
Python, no jawtrack code) and moves a mandible another way:

  - the condyles are found on the mesh (the most posterior-superior vertex on each side);
  - each condyle follows a straight-then-flattening guidance path (inclination 30-45 degrees,
    a parabola, not an S);
  - in lateral excursion the balancing condyle travels forward, down and medially (a Bennett
    angle of 8-16 degrees) while the working condyle side-shifts outwards at once (0.4-1.2 mm,
    the immediate side shift) and a little back;
  - opening is a rotation whose condylar travel grows smoothly with it (no hinge-only phase
    with a threshold), and protrusion and lateral excursion limit how far it opens;
  - the incisal and canine guidance add an opening that fades as the mouth opens;
  - the motion is 900 poses of border movements and chewing cycles, each cycle closing to a
    side: the three controls move at once most of the time.

Every constant is drawn per subject from --seed.

Usage:
  other_joint.py make --mandible M.obj [--frames 900] [--seed S] -o poses.json
  other_joint.py score --mandible M.obj --truth poses.json --reconstructed jaw.json [--json]

`make` writes a jawtrack-jaw/1 file (upper_from_lower; the mandible's own coordinates are the
rest bite). `score` prints, over the poses both files share, the largest vertex distance (mm)
between the mandible under the true and the reconstructed pose: mean, median, p95, max.
"""

import argparse
import json
import math
import random
import sys


def read_obj(path):
    verts = []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                x, y, z = (float(t) for t in line.split()[1:4])
                verts.append((x, y, z))
    if not verts:
        sys.exit(f"{path}: no vertices")
    return verts


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def apply(r, v):
    return tuple(sum(r[i][k] * v[k] for k in range(3)) for i in range(3))


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def add(a, b):
    return tuple(x + y for x, y in zip(a, b))


def scale(a, s):
    return tuple(x * s for x in a)


def norm(a):
    return math.sqrt(sum(x * x for x in a))


def unit(a):
    n = norm(a)
    return tuple(x / n for x in a)


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def axis_angle(axis, angle):
    x, y, z = unit(axis)
    c, s = math.cos(angle), math.sin(angle)
    t = 1 - c
    return [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]


def between(a, b):
    """The smallest rotation taking direction a to direction b."""
    a, b = unit(a), unit(b)
    c = cross(a, b)
    s = norm(c)
    if s < 1e-12:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    return axis_angle(c, math.atan2(s, dot(a, b)))


class Joint:
    def __init__(self, verts, rng):
        xs = [v[0] for v in verts]
        mid = 0.5 * (min(xs) + max(xs))
        half = 0.5 * (max(xs) - min(xs))
        # The condyles: on each side, beyond 60 % of the half-width, the most posterior-superior
        # vertex (the mesh is y up, z anterior, x the subject's left).
        def condyle(sign):
            side = [v for v in verts if sign * (v[0] - mid) > 0.6 * half]
            return max(side, key=lambda v: v[1] - v[2])

        self.left = condyle(+1.0)
        self.right = condyle(-1.0)
        u = rng.uniform
        self.inclination = math.radians(u(30.0, 45.0))
        self.flatten = u(0.010, 0.025)  # 1/mm: the path's slope falls with travel
        self.bennett = math.radians(u(8.0, 16.0))
        self.side_shift = u(0.4, 1.2)  # mm, immediate
        self.retrusion = u(0.2, 0.6)  # mm, working condyle back
        self.max_open = math.radians(u(27.0, 36.0))
        self.open_travel = u(12.0, 18.0)  # mm of condylar travel at full opening
        self.travel_power = u(1.3, 2.0)
        self.prot_travel = u(8.0, 12.0)
        self.lat_travel = u(8.0, 12.0)
        self.guidance = math.radians(u(2.0, 4.5))
        self.limit_prot = u(0.15, 0.35)
        self.limit_lat = u(0.1, 0.3)

    def path(self, rest, s, medial_sign, medial):
        """A condyle s mm along its guidance path from `rest`; `medial` in radians."""
        s = max(0.0, s)
        drop = s * math.tan(self.inclination) * max(0.2, 1.0 - self.flatten * s)
        return add(rest, (medial_sign * s * math.tan(medial), -drop, s))

    def motion(self, o, l, p):
        """(R, t) taking mandible points at rest to now, for controls o in [0,1], l in [-1,1],
        p in [0,1]."""
        o = min(max(o, 0.0), 1.0) * (1.0 - self.limit_prot * p) * (1.0 - self.limit_lat * abs(l))
        angle = o * self.max_open
        s_open = self.open_travel * o**self.travel_power
        s_common = s_open + self.prot_travel * p
        # Chin to the left (+x): the right condyle balances (forward, down, medially: +x),
        # the left one works (shifts left at once, a little back).
        lat_left, lat_right = max(-l, 0.0), max(l, 0.0)
        left = self.path(self.left, s_common + self.lat_travel * lat_left, -1.0, self.bennett * (lat_left > 0))
        right = self.path(self.right, s_common + self.lat_travel * lat_right, +1.0, self.bennett * (lat_right > 0))
        left = add(left, (self.side_shift * lat_right, 0.0, -self.retrusion * lat_right))
        right = add(right, (-self.side_shift * lat_left, 0.0, -self.retrusion * lat_left))
        # Guidance keeps the teeth apart in excursions, less so once they are apart anyway.
        guide = self.guidance * (p + 0.7 * abs(l)) * math.exp(-3.0 * o)
        axis0 = sub(self.left, self.right)
        axis = sub(left, right)
        align = between(axis0, axis)
        r = matmul(axis_angle(axis, angle + guide), align)
        mid0 = scale(add(self.left, self.right), 0.5)
        mid = scale(add(left, right), 0.5)
        t = sub(mid, apply(r, mid0))
        return r, t


def smooth(a, b, f):
    e = 0.5 - 0.5 * math.cos(math.pi * f)
    return tuple(x + (y - x) * e for x, y in zip(a, b))


def trajectory(frames, rng):
    """Keyed controls: the border movements, then chewing cycles that close to a side, then
    free combinations; cosine easing between keys."""
    u = rng.uniform
    keys = [(0, 0, 0), (1, 0, 0), (0, 0, 0), (0.05, 1, 0), (0, 0, 0), (0.05, -1, 0), (0, 0, 0),
            (0.02, 0, 1), (0, 0, 0), (0.5, 0, 0.8), (0, 0, 0)]
    for _ in range(10):
        side = rng.choice([-1.0, 1.0])
        keys += [(u(0.35, 0.7), u(-0.15, 0.15), u(0.0, 0.2)),
                 (u(0.15, 0.35), side * u(0.4, 0.8), u(0.0, 0.15)),
                 (u(0.0, 0.05), side * u(0.1, 0.3), 0.0)]
    for _ in range(8):
        keys.append((u(0.0, 0.9), u(-0.8, 0.8), u(0.0, 0.8)))
    keys.append((0, 0, 0))
    segments = len(keys) - 1
    out = []
    for k in range(frames):
        pos = k / max(frames - 1, 1) * segments
        i = min(int(pos), segments - 1)
        out.append(smooth(keys[i], keys[i + 1], pos - i))
    return out


def make(args):
    verts = read_obj(args.mandible)
    rng = random.Random(args.seed)
    joint = Joint(verts, rng)
    poses = []
    for frame, (o, l, p) in enumerate(trajectory(args.frames, rng)):
        r, t = joint.motion(o, l, p)
        poses.append({"frame": frame, "rotation": [list(row) for row in r], "translation": list(t)})
    doc = {"format": "jawtrack-jaw/1", "poses": poses}
    with open(args.output, "w") as f:
        json.dump(doc, f)
    print(f"{args.output}: {len(poses)} poses; condyles {fmt(joint.left)} {fmt(joint.right)}")


def fmt(v):
    return "(" + ", ".join(f"{x:.1f}" for x in v) + ")"


def read_poses(path):
    with open(path) as f:
        doc = json.load(f)
    if "poses" in doc:
        return {p["frame"]: (p["rotation"], p["translation"]) for p in doc["poses"]}
    out = {}
    for fr in doc["frames"]:
        if "jaw" in fr:
            out[fr["frame"]] = (fr["jaw"]["rotation"], fr["jaw"]["translation"])
    return out


def score(args):
    verts = read_obj(args.mandible)
    truth = read_poses(args.truth)
    rec = read_poses(args.reconstructed)
    frames = sorted(set(truth) & set(rec))
    if not frames:
        sys.exit("no frame in both files")
    errors = []
    for fr in frames:
        (ra, ta), (rb, tb) = truth[fr], rec[fr]
        worst = 0.0
        for v in verts:
            a = add(apply(ra, v), ta)
            b = add(apply(rb, v), tb)
            worst = max(worst, norm(sub(a, b)))
        errors.append(worst)
    errors.sort()
    n = len(errors)
    pick = lambda q: errors[min(n - 1, int(round(q * (n - 1))))]
    result = {"poses": n, "mean": sum(errors) / n, "median": pick(0.5), "p95": pick(0.95), "max": errors[-1]}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{n} poses: max vertex distance mean {result['mean']:.3f} mm, median {result['median']:.3f}, "
              f"p95 {result['p95']:.3f}, max {result['max']:.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub_ = ap.add_subparsers(dest="cmd", required=True)
    m = sub_.add_parser("make")
    m.add_argument("--mandible", required=True)
    m.add_argument("--frames", type=int, default=900)
    m.add_argument("--seed", type=int, default=0)
    m.add_argument("-o", "--output", required=True)
    s = sub_.add_parser("score")
    s.add_argument("--mandible", required=True)
    s.add_argument("--truth", required=True)
    s.add_argument("--reconstructed", required=True)
    s.add_argument("--json", action="store_true")
    args = ap.parse_args()
    (make if args.cmd == "make" else score)(args)


if __name__ == "__main__":
    main()
