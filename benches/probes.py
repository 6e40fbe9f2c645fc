#!/usr/bin/env python3
"""Hostile-input probes of a jawtrack binary, by class (issue 22's findings and more).

Each probe builds a small capture or file in a temp folder (from fixtures/tiny-capture, written
by another program), runs the binary on it with a time limit, and classifies what happened:

  rejected   a non-zero exit with a message, and no crash
  ran        exit 0 where running is a fine answer (e.g. a pose far out of view)
  ACCEPTED   exit 0 where the input is wrong and must be refused
  PANIC      a Rust panic (exit 101)
  ABORT      killed by a signal (SIGABRT from a failed allocation, SIGSEGV, ...)
  HANG       still running after the time limit
  OVER-MEM   rejected, but its peak memory exceeded 2x the input's size + 100 MB
  WRONG      exit 0 with a wrong result (a resumed tracks.json that differs, a replaced device)

Usage: benches/probes.py BINARY [--json OUT.json] [--only CLASS]
Memory is capped at 8 GiB per run (RLIMIT_AS), so an unbounded allocation shows as ABORT
instead of taking the machine down.
"""

import argparse
import json
import os
import random
import resource
import shutil
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "fixtures" / "tiny-capture"
LIMIT_S = 15.0
MEM_CAP = 8 << 30
BAD = {"ACCEPTED", "PANIC", "ABORT", "HANG", "OVER-MEM", "WRONG"}


def run(argv, cwd, limit=LIMIT_S):
    """Run argv; (outcome-ish, rc, stderr, peak RSS in bytes, seconds)."""

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (MEM_CAP, MEM_CAP))
        os.setsid()

    err = tempfile.TemporaryFile()
    started = time.time()
    p = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=err,
                         preexec_fn=cap, env={**os.environ, "RUST_BACKTRACE": "0"})
    hung = False
    while True:
        pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        if time.time() - started > limit:
            hung = True
            os.killpg(p.pid, signal.SIGKILL)
            pid, status, usage = os.wait4(p.pid, 0)
            break
        time.sleep(0.01)
    p.returncode = 0  # reaped here, not by Popen
    err.seek(0)
    stderr = err.read().decode("utf-8", "replace")
    rss = usage.ru_maxrss * 1024
    secs = time.time() - started
    if hung:
        return "HANG", None, stderr, rss, secs
    if os.WIFSIGNALED(status):
        return "ABORT", -os.WTERMSIG(status), stderr, rss, secs
    rc = os.WEXITSTATUS(status)
    if rc == 101 or "panicked at" in stderr:
        return "PANIC", rc, stderr, rss, secs
    return None, rc, stderr, rss, secs


class Probe:
    def __init__(self, cls, name, setup, expect="reject", check=None):
        # setup(dir) -> (argv without the binary, size in bytes of the hostile input)
        self.cls, self.name, self.setup, self.expect, self.check = cls, name, setup, expect, check


def capture(d):
    c = Path(d) / "c"
    shutil.copytree(FIXTURE, c)
    return c


def edit_json(path, fn):
    v = json.loads(Path(path).read_text())
    fn(v)
    Path(path).write_text(json.dumps(v))


def size(path):
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def pose(x=0.0, y=0.0, z=0.0):
    return {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [x, y, z]}


def track(c, *extra):
    return ["track", str(c), "-o", str(c.parent / "out.json"), "--backend", "cpu", *extra]


PROBES = []


def says(*words):
    def check(rc, stderr, d):
        return None if all(w.lower() in stderr.lower() for w in words) else "MISLEADING"
    return check


def probe(cls, name, expect="reject", check=None):
    def wrap(fn):
        PROBES.append(Probe(cls, name, fn, expect, check))
        return fn
    return wrap


# -- poses far out of view (a panic at bf99878: raster.rs:105) -----------------------------
for arch in ("upper", "lower"):
    for x in (100, 150, 300, 1e3, 1e4, 1e5, -100, -1e4):
        def setup(d, arch=arch, x=x):
            c = capture(d)
            edit_json(c / "init.json", lambda v: v.__setitem__(arch, pose(x, -10 if arch == "lower" else 0)))
            return track(c, "--frames", "0..1"), 0
        probe("pose out of view", f"track, init {arch} x = {x:g} mm", expect="any")(setup)
    for x in (100, 1e3, 1e5):
        def setup(d, arch=arch, x=x):
            c = capture(d)
            p = Path(d) / "p.json"
            p.write_text(json.dumps(pose(x)))
            return ["energy", str(c), "--frame", "0", f"--{arch}", str(p), "--backend", "cpu"], 0
        probe("pose out of view", f"energy --{arch} x = {x:g} mm", expect="any")(setup)

# -- non-finite and huge numbers in poses and pixels (hangs at bf99878) ---------------------
for arch in ("upper", "lower"):
    for t in (1e308, 1e200, 1e7, -1e308):
        def setup(d, arch=arch, t=t):
            c = capture(d)
            edit_json(c / "init.json", lambda v: v.__setitem__(arch, pose(t)))
            return track(c, "--frames", "0..1"), 0
        probe("huge numbers", f"init {arch} translation {t:g}")(setup)
    for px in (1e6, 1e308, -1e308):
        def setup(d, arch=arch, px=px):
            c = capture(d)

            def f(v):
                v[arch]["points"][0]["pixels"]["left"] = [px, px]
            edit_json(c / "init.json", f)
            return track(c, "--frames", "0..1"), 0
        probe("huge numbers", f"bootstrap {arch} pixel {px:g}", check=says("init.json"))(setup)
for field, value in (("fx", 1e308), ("fx", 0), ("fx", -5), ("cx", 1e308), ("width", 1), ("height", 1),
                     ("width", 10**12), ("height", -3)):
    def setup(d, field=field, value=value):
        c = capture(d)
        edit_json(c / "cameras/left.json", lambda v: v.__setitem__(field, value))
        return ["validate", str(c)], 0
    probe("huge numbers", f"camera {field} = {value:g}")(setup)


def jaw_file(d, extreme):
    # A jawtrack-jaw/1 file of 60 varied poses, one of them extreme.
    rng = random.Random(7)
    poses = []
    for i in range(60):
        a = rng.uniform(0, 0.3)
        c, s = __import__("math").cos(a), __import__("math").sin(a)
        t = [rng.uniform(-1, 1), -10 - 5 * a, rng.uniform(-1, 1) + 3 * a]
        if i == 30:
            t[0] = extreme
        poses.append({"frame": i, "rotation": [[1, 0, 0], [0, c, -s], [0, s, c]], "translation": t})
    p = Path(d) / "jaw.json"
    p.write_text(json.dumps({"format": "jawtrack-jaw/1", "poses": poses}))
    return p


for extreme in (1e308, 1e9):
    for cmd in (["rig", "learn"], ["envelope", "learn"], ["rig", "compare"]):
        def setup(d, extreme=extreme, cmd=cmd):
            p = jaw_file(d, extreme)
            out = ["-o", str(Path(d) / "rig.json")] if cmd[1] == "learn" else []
            return [*cmd, str(p), "--mesh", str(MANDIBLE), *out], 0
        probe("huge numbers", f"{' '.join(cmd)} with a pose at x = {extreme:g}")(setup)

# -- settings (panics, hangs and aborts at bf99878) ----------------------------------------
SETTINGS = [
    ("search.samples", 0), ("search.samples", 10**9), ("search.samples", -1),
    ("search.scales", []), ("search.scales", [-1]), ("search.scales", [0]), ("search.scales", [1e308]),
    ("search.fd_step_mm", 0), ("search.fd_step_rad", 0), ("search.fd_step_mm", 1e308),
    ("search.line_tolerance", 0), ("search.line_tolerance", -1), ("search.line_max_mm", 0),
    ("search.lambda", 1e308), ("search.lambda", -1), ("search.max_rounds", 10**9),
    ("search.sample_rounds", 10**9), ("search.min_gain", -1), ("search.cross_weight", 1e308),
    ("search.mouth_weight", -1), ("search.sample_mm", 0),
    ("jaw_prior_grid", [1000, 1000, 1000]), ("jaw_prior_fine_grid", [1000, 1000, 1000]),
    ("jaw_prior_nearest", 10**9), ("restarts", 10**6), ("restarts", 0), ("per_arch_passes", 10**9),
    ("combined_passes", 0), ("confidence_window", 0), ("confidence_window", 10**12),
    ("low_confidence_ratio", -1), ("contact_weight", 1e308), ("contact_tolerance_mm", -1),
    ("jaw_manifold_weight", -5), ("settle_mm", -1),
]
for field, value in SETTINGS:
    def setup(d, field=field, value=value):
        c = capture(d)
        head, *rest = field.split(".")
        v = {head: {rest[0]: value}} if rest else {head: value}
        return track(c, "--frames", "0..1", "--settings", json.dumps(v)), 0
    probe("settings", f"{field} = {json.dumps(value)}")(setup)
for field, value in (("network.hidden", 10**8), ("network.hidden", 0), ("alpha", -1), ("alpha", 1e308),
                     ("network.max_iterations", 10**12), ("network.memory", 0), ("encode_steps", 10**9)):
    def setup(d, field=field, value=value):
        head, *rest = field.split(".")
        v = {head: {rest[0]: value}} if rest else {head: value}
        s = Path(d) / "rig-settings.json"
        s.write_text(json.dumps(v))
        return ["rig", "learn", str(jaw_file(d, 0.5)), "--mesh", str(MANDIBLE), "-o", str(Path(d) / "rig.json"),
                "--settings", str(s)], 0
    probe("settings", f"rig {field} = {value:g}")(setup)

# -- pipes and devices in place of files (hangs), unbounded reads (aborts) ------------------
for rel in ("capture.json", "cameras/left.json", "init.json", "meshes/upper.stl",
            "meshes/upper.boi.json", "masks/left/000000.png"):
    for cmd in ("validate", "track"):
        def setup(d, rel=rel, cmd=cmd):
            c = capture(d)
            (c / rel).unlink()
            os.mkfifo(c / rel)
            return (["validate", str(c)] if cmd == "validate" else track(c, "--frames", "0..1")), 0
        probe("pipes and devices", f"{cmd}: a FIFO as {rel}")(setup)
    def setup(d, rel=rel):
        c = capture(d)
        (c / rel).unlink()
        os.symlink("/dev/zero", c / rel)
        return ["validate", str(c), "--allow-outside"], 0
    probe("unbounded reads", f"{rel} linked to /dev/zero (--allow-outside)")(setup)
for ext, header in (
        ("ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
                b"property float y\nproperty float z\nelement face 4000000000\n"
                b"property list uchar int vertex_indices\nend_header\n"),
        ("ply", b"ply\nformat ascii 1.0\nelement vertex 999999999999\nproperty float x\nend_header\n1\n"),
        ("stl", b"\0" * 80 + struct.pack("<I", 0xFFFFFFFF) + b"\0" * 100),
        ("stl", b"solid x\n" + b"facet normal 0 0 0\n" * 10),
        ("obj", b"v 1 2 3\n" * 3 + b"f 1 2 99999999999\n"),
        ("obj", b""),
):
    def setup(d, ext=ext, header=header):
        c = capture(d)
        m = c / "meshes" / f"upper.{ext}"
        m.write_bytes(header)
        edit_json(c / "capture.json", lambda v: v["meshes"].__setitem__("upper", f"meshes/upper.{ext}"))
        return ["validate", str(c)], len(header)
    probe("unbounded reads", f"{ext} header {header[:40]!r}...")(setup)
for args in (["synth", "OUT", "--frames", "1000000000"], ["synth", "OUT", "--frames", "-1"],
             ["track", "C", "-o", "O", "--simplify-mm", "NaN"], ["track", "C", "-o", "O", "--max-triangles", "0"],
             ["track", "C", "-o", "O", "--mask-reduce", "0"], ["track", "C", "-o", "O", "--frames", "5..2"],
             ["energy", "C", "--frame", "4000000000"], ["energy", "C", "--frame", "0", "--lambda", "NaN"]):
    def setup(d, args=args):
        c = capture(d)
        sub = {"OUT": str(Path(d) / "s"), "C": str(c), "O": str(Path(d) / "o.json")}
        return [sub.get(a, a) for a in args] + (["--backend", "cpu"] if args[0] in ("track", "energy") else []), 0
    probe("flags", " ".join(args))(setup)

# -- paths that leave the capture ------------------------------------------------------------
OUTSIDE = [
    ("meshes.upper absolute", lambda c: ("meshes", "upper", str((c / "meshes/upper.stl").resolve()))),
    ("meshes.upper ../..", lambda c: ("meshes", "upper", "../../" + c.parent.name + "/c/meshes/upper.stl")),
    ("masks.dir absolute", lambda c: ("masks", "dir", str((c / "masks").resolve()))),
    ("masks.dir ..", lambda c: ("masks", "dir", "../c/masks")),
    ("boi.upper /etc/passwd", lambda c: ("boi", "upper", "/etc/passwd")),
    ("boi.upper ../../../../etc/passwd", lambda c: ("boi", "upper", "../../../../../../etc/passwd")),
]
for name, edit in OUTSIDE:
    for cmd in ("validate", "track"):
        def setup(d, edit=edit, cmd=cmd):
            c = capture(d)
            obj, key, value = edit(c)
            edit_json(c / "capture.json", lambda v: v[obj].__setitem__(key, value))
            return (["validate", str(c)] if cmd == "validate" else track(c, "--frames", "0..1")), 0
        probe("paths out of the capture", f"{cmd}: {name}")(setup)
for rel in ("meshes/upper.stl", "cameras/left.json", "masks/left", "init.json"):
    def setup(d, rel=rel):
        c = capture(d)
        outside = Path(d) / "elsewhere"
        shutil.move(str(c / rel), outside)
        os.symlink(outside, c / rel)
        return ["validate", str(c)], 0
    probe("paths out of the capture", f"{rel} a link out of the folder")(setup)


SECRET = "SECRET-" + "0123456789" * 20


def foreign_echo(rc, stderr, d):
    # A short token of it may be quoted (at most 60 characters); not the file's text.
    return "ECHOED" if "root:x:0" in stderr or SECRET[:61] in stderr else None


def setup_echo(d):
    c = capture(d)
    secret = Path(d) / "c" / "meshes" / "upper.ply"
    secret.write_text((SECRET + "\n") * 3)
    edit_json(c / "capture.json", lambda v: v["meshes"].__setitem__("upper", "meshes/upper.ply"))
    return ["validate", str(c)], 0


probe("paths out of the capture", "error quotes a foreign file's first line", check=foreign_echo)(setup_echo)

# -- the journal ----------------------------------------------------------------------------
def _set(record, path, value):
    at = record
    for k in path[:-1]:
        at = at[k]
    at[path[-1]] = value
    return record


# Each edit takes the head line and the frame records (dicts) and gives the journal's lines.
JOURNAL_EDITS = [
    ("a line with frame 999", lambda h, r: [h, dump(r[0]), dump(_set(r[1], ["frame"], 999))]),
    ("a duplicated line", lambda h, r: [h, dump(r[0]), dump(r[0]), dump(r[1])]),
    ("a translation of 1e308", lambda h, r: [h, dump(r[0]), dump(_set(r[1], ["upper", "translation", 0], 1e308))]),
    ("garbage in the middle", lambda h, r: [h, dump(r[0]), "}{ not json", dump(r[1])]),
    ("frames out of order", lambda h, r: [h, dump(r[1]), dump(r[0])]),
    ("another run's fingerprint", lambda h, r: ['{"fingerprint":"0000000000000000"}', dump(r[0]), dump(r[1])]),
    ("no fingerprint", lambda h, r: [dump(r[0]), dump(r[1])]),
    ("a rotation that is not one", lambda h, r: [h, dump(r[0]), dump(_set(r[1], ["lower", "rotation", 0, 0], 5))]),
]


def dump(v):
    return json.dumps(v, separators=(",", ":"))


def tracked_journal(d):
    """A capture, its output path, the journal head and the records of its first two frames."""
    c = capture(d)
    out = c.parent / "out.json"
    subprocess.run([BINARY, *track(c, "--frames", "0..2")], capture_output=True, check=True)
    tj = json.loads(out.read_text())
    out.unlink()
    return c, out, dump({"fingerprint": tj.get("fingerprint", "")}), tj["frames"]


for name, edit in JOURNAL_EDITS:
    def setup(d, edit=edit):
        c, out, head, records = tracked_journal(d)
        Path(str(out) + ".journal").write_text("\n".join(edit(head, records)) + "\n")
        return track(c, "--resume"), 0
    probe("journal", f"--resume with {name}")(setup)


def identical(rc, stderr, d):
    a, b = Path(d) / "whole.json", Path(d) / "out.json"
    return None if a.read_bytes() == b.read_bytes() else "WRONG"


def setup_identical(d):
    c = capture(d)
    subprocess.run([BINARY, *track(c)], capture_output=True, check=True)
    shutil.move(str(c.parent / "out.json"), Path(d) / "whole.json")
    subprocess.run([BINARY, *track(c, "--frames", "0..1")], capture_output=True, check=True)
    return track(c, "--resume"), 0


probe("journal", "a resumed run's tracks.json, byte for byte", expect="any", check=identical)(setup_identical)

# -- output ---------------------------------------------------------------------------------


def still_device(rc, stderr, d):
    m = os.lstat(Path(d) / "dev")
    return None if stat.S_ISCHR(m.st_mode) or stat.S_ISFIFO(m.st_mode) else "WRONG"


for kind in ("char", "fifo"):
    def setup(d, kind=kind):
        c = capture(d)
        dev = Path(d) / "dev"
        if kind == "char":
            os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 7))  # a private /dev/full
        else:
            os.mkfifo(dev)
        return ["track", str(c), "-o", str(dev), "--force", "--frames", "0..1", "--backend", "cpu"], 0
    probe("output", f"-o a {kind} device --force", check=still_device)(setup)

# -- wrong input silently accepted at bf99878 ------------------------------------------------


def setup_field(d):
    c = capture(d)
    edit_json(c / "capture.json", lambda v: v["frames"].__setitem__("step", 2))
    return ["validate", str(c)], 0


probe("silently accepted", "capture.json frames.step (unknown field)", expect="any",
      check=lambda rc, e, d: None if ("step" in e) else "ACCEPTED")(setup_field)


def gt(d, poses):
    c = capture(d)
    (c / "gt").mkdir()
    (c / "gt" / "poses.json").write_text(json.dumps(poses))
    return ["validate", str(c)], 0


probe("silently accepted", "gt with a frame twice")(
    lambda d: gt(d, {"format": "jawtrack-tracks/1", "frames": [
        {"frame": 0, "upper": pose(), "lower": pose(0, -10)}, {"frame": 0, "upper": pose(), "lower": pose(0, -10)}]}))
probe("silently accepted", "gt format \"x\"")(
    lambda d: gt(d, {"format": "x", "frames": [{"frame": 0, "upper": pose(), "lower": pose(0, -10)}]}))


def setup_mask(d, mode, trunc=False, palette=False):
    from PIL import Image
    c = capture(d)
    p = c / "masks/left/000000.png"
    im = Image.open(p)
    if palette:
        im = im.convert("P")
    else:
        im = im.convert(mode)
    if mode == "I;16":
        im = Image.open(p).convert("I").point(lambda v: v * 256).convert("I;16")
    im.save(p)
    if trunc:
        b = p.read_bytes()
        p.write_bytes(b[: len(b) // 2])
    return ["validate", str(c)], size(p)


probe("silently accepted", "gray+alpha mask")(lambda d: setup_mask(d, "LA"))
for quick in ("", "--quick"):
    for label, kw in (("16-bit", dict(mode="I;16")), ("RGB", dict(mode="RGB")),
                      ("truncated", dict(mode="L", trunc=True))):
        def setup(d, kw=kw, quick=quick):
            argv, n = setup_mask(d, **kw)
            return argv + ([quick] if quick else []), n
        probe("silently accepted", f"validate {quick} {label} mask".replace("  ", " "))(setup)


def setup_obj0(d):
    c = capture(d)
    (c / "meshes/upper.obj").write_bytes(b"")
    edit_json(c / "capture.json", lambda v: v["meshes"].__setitem__("upper", "meshes/upper.obj"))
    return ["validate", str(c)], 0


probe("misleading messages", "a 0-byte OBJ", check=lambda rc, e, d: "MISLEADING" if "no group named" in e else None)(setup_obj0)
probe("misleading messages", "a palette mask", check=lambda rc, e, d: "MISLEADING" if "found Rgb8" in e else None)(
    lambda d: setup_mask(d, "P", palette=True))


def setup_face(d):
    c = capture(d)
    (c / "meshes/upper.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 2 9\n")
    (c / "meshes/upper.boi.json").write_text("[0]")
    edit_json(c / "capture.json", lambda v: v["meshes"].__setitem__("upper", "meshes/upper.obj"))
    return ["validate", str(c)], 0


probe("misleading messages", "OBJ face 2 refers to vertex 9 (numbered from 1)",
      check=lambda rc, e, d: None if ("vertex 9" in e and "face 2" in e) else "MISLEADING")(setup_face)

# -- large files rejected late: peak memory against the file's size -------------------------


def setup_big_obj(d):
    c = capture(d)
    m = c / "meshes" / "upper.obj"
    with open(m, "w") as f:
        n = 1_200_000
        for i in range(n):
            f.write(f"v {i % 97} {i % 89} {i % 83}\n")
        for i in range(1, n - 2, 2):
            f.write(f"f {i} {i + 1} {i + 2}\n")
        f.write(f"f 1 2 {n + 5}\n")
    (c / "meshes" / "upper.boi.json").write_text("[0]")
    edit_json(c / "capture.json", lambda v: v["meshes"].__setitem__("upper", "meshes/upper.obj"))
    return ["validate", str(c)], size(m)


def setup_big_json(d):
    c = capture(d)
    edit_json(c / "capture.json", lambda v: v.__setitem__("producer", "x" * 40_000_000))
    edit_json(c / "capture.json", lambda v: v["frames"].__setitem__("count", -1))
    return ["validate", str(c)], size(c / "capture.json")


def setup_png_bomb(d):
    import zlib
    c = capture(d)
    w = h = 20000
    raw = zlib.compress(b"\0" * (w + 1) * h, 9)

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
           + chunk(b"IDAT", raw) + chunk(b"IEND", b""))
    (c / "masks/left/000001.png").write_bytes(png)
    return ["validate", str(c)], len(png)


def setup_big_journal(d):
    c, out, head, records = tracked_journal(d)
    line = dump(records[0])
    with open(str(out) + ".journal", "w") as f:
        f.write(head + "\n" + line + "\n")
        f.write(line.replace('"frame":0', '"frame":1')[:-1] + " " * 50_000_000 + "}\n")
        f.write("}{ garbage\n" + line + "\n")
    return track(c, "--resume"), size(str(out) + ".journal")


probe("large files", "a large OBJ whose last face is wrong")(setup_big_obj)
probe("large files", "a large capture.json with a wrong count")(setup_big_json)
probe("large files", "a 20000x20000 mask (a PNG bomb) in a smaller camera")(setup_png_bomb)
probe("large files", "a large journal with garbage in the middle")(setup_big_journal)

# -- mutated files, through the binary (what fuzzing does in-process) -------------------------
MUTATED = ["capture.json", "cameras/left.json", "init.json", "meshes/upper.boi.json",
           "meshes/upper.stl", "masks/left/000000.png"]
for rel in MUTATED:
    for k in range(12):
        def setup(d, rel=rel, k=k):
            c = capture(d)
            rng = random.Random(f"{rel}{k}")
            b = bytearray((c / rel).read_bytes())
            for _ in range(rng.randint(1, 6)):
                i = rng.randrange(len(b) + 1)
                op = rng.randrange(3)
                if op == 0 and i < len(b):
                    b[i] = rng.randrange(256)
                elif op == 1:
                    b[i:i] = bytes(rng.choice(b"0123456789e-+.[]{}\",:9") for _ in range(rng.randint(1, 8)))
                else:
                    del b[i:i + rng.randint(1, 32)]
            (c / rel).write_bytes(bytes(b))
            return track(c, "--frames", "0..1"), len(b)
        probe("mutated files", f"{rel} #{k}", expect="any")(setup)


def main():
    global BINARY
    ap = argparse.ArgumentParser()
    ap.add_argument("binary")
    ap.add_argument("--json")
    ap.add_argument("--only")
    a = ap.parse_args()
    BINARY = os.path.abspath(a.binary)
    global MANDIBLE
    keep = tempfile.TemporaryDirectory()
    subprocess.run([BINARY, "synth", f"{keep.name}/s", "--frames", "2"], capture_output=True, check=True)
    MANDIBLE = Path(keep.name) / "s" / "meshes" / "mandible.obj"
    rows = []
    for p in PROBES:
        if a.only and a.only != p.cls:
            continue
        with tempfile.TemporaryDirectory() as d:
            try:
                argv, n = p.setup(d)
            except subprocess.CalledProcessError as e:
                rows.append(dict(cls=p.cls, name=p.name, outcome="SETUP-FAILED", detail=str(e)))
                continue
            crash, rc, stderr, rss, secs = run([BINARY, *argv], d)
            if rc == 2 and "unexpected argument '--allow-outside'" in stderr:
                # A jawtrack from before the flag read such paths anyway: probe it without.
                argv = [x for x in argv if x != "--allow-outside"]
                crash, rc, stderr, rss, secs = run([BINARY, *argv], d)
            if crash:
                outcome = crash
            elif rc == 0:
                outcome = "ran" if p.expect == "any" else "ACCEPTED"
            else:
                outcome = "rejected"
                if rss > 2 * n + (100 << 20):
                    outcome = "OVER-MEM"
            if p.check and crash is None:
                outcome = p.check(rc, stderr, d) or outcome
            lines = stderr.strip().splitlines()
            errors = [line for line in lines if line.startswith("error")]
            last = (errors or lines or [""])[-1][:400]
            rows.append(dict(cls=p.cls, name=p.name, outcome=outcome, rc=rc, peak_mb=round(rss / 2**20, 1),
                             input_mb=round(n / 2**20, 1),
                             seconds=round(secs, 2), message=last))
            mark = "!!" if outcome in BAD or outcome in ("ECHOED", "MISLEADING", "SETUP-FAILED") else "  "
            print(f"{mark} {outcome:9} {rss / 2**20:7.1f} MB (input {n / 2**20:.1f} MB) {secs:5.1f} s  "
                  f"[{p.cls}] {p.name}: {last[:100]}",
                  flush=True)
    classes = {}
    for r in rows:
        classes.setdefault(r["cls"], []).append(r)
    print("\n| class | probes | bad | outcomes | peak memory (max) |\n| --- | --- | --- | --- | --- |")
    for cls, rs in classes.items():
        counts = {}
        for r in rs:
            counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
        bad = sum(v for k, v in counts.items() if k in BAD or k in ("ECHOED", "MISLEADING"))
        peak = max((r.get("peak_mb", 0) for r in rs), default=0)
        print(f"| {cls} | {len(rs)} | {bad} | {', '.join(f'{k} {v}' for k, v in sorted(counts.items()))} | {peak} MB |")
    print(f"\n{len(rows)} probes, {sum(1 for r in rows if r['outcome'] in BAD or r['outcome'] in ('ECHOED', 'MISLEADING'))} bad")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


BINARY = None
MANDIBLE = None
if __name__ == "__main__":
    main()
