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

The view-* classes talk HTTP to `jawtrack view` (one server a probe, started on a free port and
always killed): there PANIC and ABORT are the server dying, HANG a reply that does not come in
time, ACCEPTED a 200 to a question that must be refused, and rejected any other reply or a
closed connection. A class whose tool is missing (video-names without ffmpeg) is skipped.
"""

import argparse
import atexit
import hashlib
import json
import os
import random
import re
import resource
import select
import shutil
import signal
import socket
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


def run(argv, cwd, limit=LIMIT_S, stdout=subprocess.DEVNULL):
    """Run argv; (outcome-ish, rc, stderr, peak RSS in bytes, seconds). stdout: where its
    standard output goes (a file, for a probe that reads it)."""

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (MEM_CAP, MEM_CAP))
        os.setsid()

    err = tempfile.TemporaryFile()
    started = time.time()
    p = subprocess.Popen(argv, cwd=cwd, stdout=stdout, stderr=err,
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
    def __init__(self, cls, name, setup, expect="reject", check=None, direct=False, needs=None):
        # setup(dir) -> (argv without the binary, size in bytes of the hostile input); with
        # direct, setup(dir) runs the probe itself -> (outcome, rc, stderr, peak RSS, input size).
        # needs() -> None, or why the probe cannot run here (it is skipped).
        self.cls, self.name, self.setup, self.expect, self.check = cls, name, setup, expect, check
        self.direct, self.needs = direct, needs


class SetupFailed(Exception):
    pass


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


def probe(cls, name, expect="reject", check=None, needs=None):
    def wrap(fn):
        PROBES.append(Probe(cls, name, fn, expect, check, needs=needs))
        return fn
    return wrap


def direct_probe(cls, name, needs=None):
    def wrap(fn):
        PROBES.append(Probe(cls, name, fn, direct=True, needs=needs))
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


# -- a synthetic capture and its rig, made once a run (issue 23's findings) ------------------
_CACHE = {}


def synthetic():
    """A 40-frame synthetic capture and the rig learned from its ground truth: (capture, rig)."""
    if "synthetic" not in _CACHE:
        keep = Path(tempfile.mkdtemp(prefix="jawtrack-probes-"))
        atexit.register(shutil.rmtree, keep, True)
        c, rig = keep / "cap", keep / "rig.json"
        subprocess.run([BINARY, "synth", str(c), "--frames", "40"], capture_output=True, check=True)
        subprocess.run([BINARY, "rig", "learn", str(c / "gt/poses.json"), "--mesh", str(c / "meshes/mandible.obj"),
                        "-o", str(rig)], capture_output=True, check=True)
        _CACHE["synthetic"] = (c, rig)
    return _CACHE["synthetic"]


def synthetic_copy(d):
    c = Path(d) / "cap"
    shutil.copytree(synthetic()[0], c)
    return c


def without_jaw(v):
    """A tracks file's records less their derived `jaw` (which a jawtrack may check apart)."""
    for f in v["frames"]:
        f.pop("jaw", None)


def digest(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def limit_child():
    resource.setrlimit(resource.RLIMIT_AS, (MEM_CAP, MEM_CAP))
    os.setsid()


# -- the view server ------------------------------------------------------------------------


class Server:
    """`jawtrack view RIG --capture CAP --port 0`, under the same memory cap; always killed."""

    def __init__(self, d):
        c, rig = synthetic()
        self.err = tempfile.TemporaryFile()
        self.argv = [BINARY, "view", str(rig), "--capture", str(c), "--port", "0"]
        self.p = subprocess.Popen(self.argv, cwd=d, stdout=subprocess.PIPE, stderr=self.err,
                                  preexec_fn=limit_child, env={**os.environ, "RUST_BACKTRACE": "0"})
        self.status = self.usage = None
        self.port = None
        out, deadline = b"", time.time() + LIMIT_S
        while self.port is None and time.time() < deadline and self.alive():
            if select.select([self.p.stdout], [], [], 0.1)[0]:
                chunk = os.read(self.p.stdout.fileno(), 4096)
                if not chunk:
                    break
                out += chunk
                m = re.search(rb"jawtrack view: http://[^:/]+:(\d+)/", out)
                if m:
                    self.port = int(m.group(1))
        if self.port is None:
            self.close()
            raise SetupFailed(f"view did not start: {out[-200:]!r} {self.stderr()[-300:]}")

    def alive(self):
        if self.status is None:
            pid, status, usage = os.wait4(self.p.pid, os.WNOHANG)
            if pid:
                self.status, self.usage = status, usage
                self.p.returncode = 0  # reaped here, not by Popen
        return self.status is None

    def hwm(self):
        """The server's peak resident memory so far (bytes)."""
        if self.alive():
            try:
                for line in Path(f"/proc/{self.p.pid}/status").read_text().splitlines():
                    if line.startswith("VmHWM:"):
                        return int(line.split()[1]) * 1024
            except OSError:
                pass
        return self.usage.ru_maxrss * 1024 if self.usage else 0

    def rc(self):
        if self.alive():
            return None
        return -os.WTERMSIG(self.status) if os.WIFSIGNALED(self.status) else os.WEXITSTATUS(self.status)

    def stderr(self):
        self.err.seek(0)
        return self.err.read().decode("utf-8", "replace")

    def crash(self):
        """PANIC or ABORT when the server died (or a thread of it panicked), else None."""
        time.sleep(0.2)  # let a dying server finish dying
        rc = self.rc()
        if rc == 101 or "panicked at" in self.stderr():
            return "PANIC"
        if rc is not None:
            return "ABORT"  # killed by a signal, or it stopped serving
        return None

    def close(self):
        if self.alive():
            try:
                os.killpg(self.p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            pid, status, usage = os.wait4(self.p.pid, 0)
            self.usage = usage
            self.p.returncode = 0
        if self.p.stdout:
            self.p.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def request_bytes(port, method, path, body=None, headers=None):
    hdrs = {"Host": f"127.0.0.1:{port}", "Connection": "close"}
    data = b""
    if body is not None:
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        hdrs["Content-Type"] = "application/json"
        hdrs["Content-Length"] = str(len(data))
    for k, v in (headers or {}).items():
        if v is None:
            hdrs.pop(k, None)
        else:
            hdrs[k] = v
    head = f"{method} {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in hdrs.items()) + "\r\n"
    return head.encode() + data


def read_reply(s, deadline):
    """What the server sends until it closes, its Content-Length is met, or the deadline."""
    got = b""
    while True:
        left = deadline - time.time()
        if left <= 0:
            raise socket.timeout()
        s.settimeout(left)
        try:
            chunk = s.recv(1 << 16)
        except (ConnectionResetError, BrokenPipeError):
            return got
        if not chunk:
            return got
        got += chunk
        head, sep, rest = got.partition(b"\r\n\r\n")
        if sep:
            m = re.search(rb"(?im)^content-length:\s*(\d+)", head)
            if m and len(rest) >= int(m.group(1)):
                return got


def parse_reply(got):
    m = re.match(rb"HTTP/1\.[01] (\d{3})", got)
    body = got.partition(b"\r\n\r\n")[2].decode("utf-8", "replace")
    return (int(m.group(1)) if m else None), " ".join(body.split())[:160]


def http(port, method, path, body=None, headers=None, timeout=10.0):
    """One request on a new connection: (status, body text, seconds). The status is None when the
    connection closed without a reply, "timeout" when no reply came in time."""
    started = time.time()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
            s.sendall(request_bytes(port, method, path, body, headers))
            got = read_reply(s, started + timeout)
    except socket.timeout:
        return "timeout", "", time.time() - started
    except OSError as e:
        return None, str(e), time.time() - started
    status, text = parse_reply(got)
    return status, text, time.time() - started


def answer(srv, what, status, text, secs, n=0):
    """A direct probe's result from one reply: a 200 is ACCEPTED."""
    crash = srv.crash()
    outcome = crash or ("HANG" if status == "timeout" else "ACCEPTED" if status == 200 else "rejected")
    note = f"{what}: {status} {text} ({secs:.2f} s)"
    if crash:
        panics = [line for line in srv.stderr().splitlines() if "panicked" in line]
        note += f"; the server {'exited with ' + str(srv.rc()) if srv.rc() is not None else 'panicked'}"
        note += f": {panics[0]}" if panics else ""
    return outcome, srv.rc(), srv.stderr() + "\n" + note, srv.hwm(), n


PAGE_POSE = {"target": [10, 0, 0], "from": [0, 0, 0]}


def control(srv, method="POST", path="/api/pose", body=PAGE_POSE):
    """The page's own request must be answered, or the probe says nothing."""
    status, text, _ = http(srv.port, method, path, body if method == "POST" else None)
    if status != 200:
        raise SetupFailed(f"the page's own {method} {path} was answered {status} {text}")


def served(cls, name, method, path, body=None, headers=None, timeout=10.0, needs_control=True):
    """A direct probe of one request to a fresh server."""
    def fn(d):
        with Server(d) as srv:
            if needs_control:
                control(srv)
            status, text, secs = http(srv.port, method, path, body, headers, timeout)
            return answer(srv, f"{method} {path}", status, text, secs)
    direct_probe(cls, name)(fn)


# -- view-numbers: huge numbers in the page's questions ------------------------------------
served("view-numbers", "POST /api/ik target [1e308, 0, 0]", "POST", "/api/ik",
       {"part": "lower", "vertex": 0, "target": [1e308, 0, 0], "from": [0, 0, 0]})
served("view-numbers", "POST /api/ik from [1e308, 0, 0]", "POST", "/api/ik",
       {"part": "lower", "vertex": 0, "target": [0, -10, 0], "from": [1e308, 0, 0]})
served("view-numbers", "POST /api/pose from [1e308, 0, 0]", "POST", "/api/pose",
       {"target": [10, 0, 0], "from": [1e308, 0, 0]})
served("view-numbers", "POST /api/pose target [1e308, 0, 0]", "POST", "/api/pose",
       {"target": [1e308, 0, 0], "from": [0, 0, 0]})
for args in (["--point", "0,0,0", "--target", "1e308,0,0"],
             ["--point", "0,0,0", "--target", "0,-10,0", "--from", "1e308,0,0"],
             ["--point", "1e308,0,0", "--target", "0,-10,0"]):
    probe("view-numbers", "rig ik " + " ".join(args))(lambda d, args=args: (["rig", "ik", str(synthetic()[1]), *args], 0))

# -- view-origin: requests a page of another site (or a rebound name) can make --------------


def origin_probe(name, method, path, headers, body=None):
    def fn(d):
        with Server(d) as srv:
            control(srv, method, path, PAGE_POSE if method == "POST" else None)
            hdrs = {k: v.format(port=srv.port) for k, v in headers.items()}
            status, text, secs = http(srv.port, method, path, body, hdrs)
            return answer(srv, f"{method} {path} {hdrs}", status, text, secs)
    direct_probe("view-origin", name)(fn)


origin_probe("GET /api/scene with Host: evil.example", "GET", "/api/scene", {"Host": "evil.example"})
origin_probe("GET /api/scene with Host: evil.example:PORT (DNS rebinding)", "GET", "/api/scene",
             {"Host": "evil.example:{port}"})
origin_probe("POST /api/pose with Origin: http://evil.example", "POST", "/api/pose",
             {"Origin": "http://evil.example"}, PAGE_POSE)
origin_probe("POST /api/pose as Content-Type text/plain (a simple cross-site request)", "POST", "/api/pose",
             {"Content-Type": "text/plain"}, PAGE_POSE)

# -- view-slow: slow and large clients ------------------------------------------------------


def slow_then_get(d, first):
    with Server(d) as srv:
        hold = socket.create_connection(("127.0.0.1", srv.port), timeout=5)
        try:
            hold.sendall(first(srv.port))
            time.sleep(0.2)
            status, text, secs = http(srv.port, "GET", "/", timeout=5.0)
        finally:
            hold.close()
        crash = srv.crash()
        hung = status == "timeout" or secs > 3.0
        outcome = crash or ("HANG" if hung else "ran" if status == 200 else "rejected")
        note = f"GET / on a second connection: {status} after {secs:.2f} s"
        return outcome, srv.rc(), srv.stderr() + "\n" + note, srv.hwm(), 0


direct_probe("view-slow", "a body announced as 4000000 bytes, 1 sent, held open; then GET /")(
    lambda d: slow_then_get(d, lambda port: request_bytes(
        port, "POST", "/api/pose", None, {"Content-Type": "application/json", "Content-Length": "4000000"}) + b"{"))
direct_probe("view-slow", "a head never finished, held open; then GET /")(
    lambda d: slow_then_get(d, lambda port: b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"))


def setup_long_header(d):
    with Server(d) as srv:
        s = socket.create_connection(("127.0.0.1", srv.port), timeout=5)
        closed, got, sent = False, b"", 0
        started = time.time()
        try:
            s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{srv.port}\r\nX-Long: ".encode())
            chunk = b"a" * (1 << 20)
            for i in range(300):
                s.sendall(chunk)
                sent += 1
                # Stop early once it is known (or slow): the probe stays within seconds.
                if i % 8 == 7 and (srv.hwm() > 300 << 20 or time.time() - started > 6.0):
                    break
            else:
                s.sendall(b"\r\n\r\n")
        except (BrokenPipeError, ConnectionResetError):
            closed = True
        except socket.timeout:
            pass  # it stopped reading: its reply tells
        try:
            got = read_reply(s, time.time() + 5.0)
            closed = True
        except socket.timeout:
            pass
        finally:
            s.close()
        hwm = srv.hwm()
        status, text = parse_reply(got)
        crash = srv.crash()
        if crash:
            outcome = crash
        elif hwm > 300 << 20:
            outcome = "OVER-MEM"
        elif status == 200:
            outcome = "ACCEPTED"
        elif status is not None or closed:
            outcome = "rejected"
        else:
            outcome = "HANG"
        note = (f"header line, {sent} MB of 300 sent: {status} {text} (closed {closed}, "
                f"{time.time() - started:.2f} s)")
        return outcome, srv.rc(), srv.stderr() + "\n" + note, hwm, 0


direct_probe("view-slow", "a 300 MB header line (peak over 300 MB is OVER-MEM)")(setup_long_header)
served("view-slow", "POST /api/animation of 600 s at 1000 fps", "POST", "/api/animation",
       {"keys": [{"time": 0, "params": [0, 0, 0]}, {"time": 600, "params": [10, 0, 0]}], "fps": 1000},
       timeout=12.0)

# -- yaml-alias: a billion laughs in an OpenCV FileStorage file -----------------------------


def setup_yaml_alias(d):
    y = Path(d) / "cam0.yml"
    lines = ["%YAML:1.0", "---", "a0: &a0 [" + ", ".join(["1.0"] * 10) + "]"]
    lines += [f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 10) + "]" for k in range(1, 12)]
    y.write_text("\n".join(lines) + "\n")
    return ["import", "cameras", str(Path(d) / "cap"), str(y)], size(y)


probe("yaml-alias", "12 levels of 10 aliases each (10^12 numbers expanded)")(setup_yaml_alias)

# -- colmap-many, colmap-points: COLMAP models -----------------------------------------------
COLMAP = ROOT / "fixtures" / "calib" / "colmap"


def colmap_images():
    """The fixture's image lines (without their POINTS2D lines), and camera 1's pose."""
    lines = [x for x in (COLMAP / "images.txt").read_text().splitlines() if x and not x.startswith("#")]
    images = [x for x in lines if x.endswith(".png")]
    return images, " ".join(images[0].split()[1:8])


def setup_colmap_many(d):
    m = Path(d) / "model"
    m.mkdir()
    shutil.copy(COLMAP / "cameras.txt", m / "cameras.txt")
    _, pose1 = colmap_images()
    with open(m / "images.txt", "w") as f:
        for i in range(20000):
            f.write(f"{i + 1} {pose1} 1 c{i}/000000.png\n\n")
    return ["import", "cameras", str(Path(d) / "cap"), str(m)], size(m / "images.txt")


def setup_colmap_points(d):
    m = Path(d) / "model"
    m.mkdir()
    shutil.copy(COLMAP / "cameras.txt", m / "cameras.txt")
    images, pose1 = colmap_images()
    images.append(f"4 {pose1} 1 cam3/000000.png")
    (m / "images.txt").write_text("\n".join(images) + "\n")
    return ["import", "cameras", str(Path(d) / "cap"), str(m)], size(m / "images.txt")


probe("colmap-many", "images.txt with 20000 images (cameras c0..c19999) of one camera")(setup_colmap_many)
probe("colmap-points", "images.txt without its POINTS2D lines (4 images)")(setup_colmap_points)

# -- video-names: video file names ffmpeg would read as options ------------------------------


def no_ffmpeg():
    return None if shutil.which("ffmpeg") else "ffmpeg is not on PATH"


def tiny_video():
    if "video" not in _CACHE:
        keep = Path(tempfile.mkdtemp(prefix="jawtrack-probes-video-"))
        atexit.register(shutil.rmtree, keep, True)
        subprocess.run(["ffmpeg", "-nostdin", "-loglevel", "error", "-y", "-f", "lavfi", "-i",
                        "testsrc=size=64x48:rate=24:duration=0.5", "-c:v", "libx264", "-pix_fmt", "yuv420p",
                        "-f", "mp4", "./-i"], cwd=keep, capture_output=True, check=True)
        _CACHE["video"] = keep / "-i"
    return _CACHE["video"]


def video_in(d, name="-i"):
    shutil.copy(tiny_video(), Path(d) / name)


def pngs(d):
    return len(list((Path(d) / "cap" / "images" / "cam0").glob("*.png")))


def logs(d):
    return sorted(p.name for p in Path(d).glob("*.log"))


def twelve_frames(rc, stderr, d):
    # A file named -i is a fine video: refusing it, or writing other than its 12 frames, is WRONG.
    return None if rc == 0 and pngs(d) == 12 and not logs(d) else "WRONG"


def no_report(rc, stderr, d):
    return "WRONG" if logs(d) else None


def no_images(rc, stderr, d):
    return "WRONG" if (Path(d) / "cap" / "images").exists() else None


def nothing_written(rc, stderr, d):
    return None if sorted(os.listdir(d)) == ["-i"] else "WRONG"


def setup_video(d, *args, name="-i"):
    video_in(d, name)
    return ["import", "video", "cap", *args], 0


probe("video-names", "cam0=-i (a video named -i), 12 frames", expect="any", check=twelve_frames,
      needs=no_ffmpeg)(lambda d: setup_video(d, "cam0=-i"))
probe("video-names", "cam0=-report (no ffmpeg report written)", expect="any", check=no_report,
      needs=no_ffmpeg)(lambda d: setup_video(d, "cam0=-report", name="-report"))
probe("video-names", "--first 18446744073709551615", check=no_images,
      needs=no_ffmpeg)(lambda d: setup_video(d, "cam0=-i", "--first", "18446744073709551615"))
probe("video-names", "cam0=-i cam0=-i (two videos for one camera)", check=nothing_written,
      needs=no_ffmpeg)(lambda d: setup_video(d, "cam0=-i", "cam0=-i"))

# -- overwrite: export onto its own inputs ---------------------------------------------------
BEFORE = {}


def unchanged(rel):
    def check(rc, stderr, d):
        return None if digest(Path(d) / rel) == BEFORE.get((d, rel)) else "WRONG"
    return check


def setup_overwrite(d, flag, rel, spelled=None):
    # Without the `jaw` fields the export would run (the control of accepted-silently), so
    # only the output's check can stop it.
    c = synthetic_copy(d)
    edit_json(c / "gt/poses.json", without_jaw)
    BEFORE[(d, rel)] = digest(Path(d) / rel)
    return ["export", str(c), str(c / "gt/poses.json"), flag, spelled or str(Path(d) / rel)], 0


probe("overwrite", "export --gltf the capture's meshes/upper.obj", check=unchanged("cap/meshes/upper.obj"))(
    lambda d: setup_overwrite(d, "--gltf", "cap/meshes/upper.obj"))
probe("overwrite", "export --gltf cap/./meshes/../meshes/upper.obj (another spelling)",
      check=unchanged("cap/meshes/upper.obj"))(
    lambda d: setup_overwrite(d, "--gltf", "cap/meshes/upper.obj", f"{d}/cap/./meshes/../meshes/upper.obj"))
probe("overwrite", "export --csv the tracks it reads (gt/poses.json)", check=unchanged("cap/gt/poses.json"))(
    lambda d: setup_overwrite(d, "--csv", "cap/gt/poses.json"))
probe("overwrite", "export --csv the capture's capture.json", check=unchanged("cap/capture.json"))(
    lambda d: setup_overwrite(d, "--csv", "cap/capture.json"))


def setup_same_out(d):
    c = synthetic_copy(d)
    x = str(Path(d) / "x.out")
    return ["export", str(c), str(c / "gt/poses.json"), "--csv", x, "--gltf", x], 0


probe("overwrite", "export --csv X --gltf X")(setup_same_out)

# -- accepted-silently: wrong numbers that pass -----------------------------------------------
for field, value in (("fx", 1e-300), ("fy", 1e-300), ("distortion", [1e308, 0, 0, 0, 0])):
    def setup(d, field=field, value=value):
        c = capture(d)
        edit_json(c / "cameras/left.json", lambda v: v.__setitem__(field, value))
        return ["validate", str(c)], 0
    probe("accepted-silently", f"camera {field} = {json.dumps(value)}")(setup)


def setup_tracks(d, edit):
    t = Path(d) / "tracks.json"
    edit_json(shutil.copy(synthetic()[0] / "gt/poses.json", t), edit)
    return ["export", str(synthetic()[0]), str(t), "--csv", str(Path(d) / "out.csv")], 0


def frame0_twice(v, keep_jaw):
    if not keep_jaw:
        without_jaw(v)
    v["frames"].insert(1, json.loads(json.dumps(v["frames"][0])))


# The control: synth's own ground truth must export, or the probes below are refused for
# another reason (the jaw check's rotation angle, an unclamped acos, is NaN for two rotations a
# rounding apart).
probe("accepted-silently", "control: export synth's own gt/poses.json (must run)", expect="any",
      check=lambda rc, e, d: None if rc == 0 else "WRONG")(lambda d: setup_tracks(d, lambda v: None))
probe("accepted-silently", "export: tracks with frame 0 twice")(lambda d: setup_tracks(d, lambda v: frame0_twice(v, True)))
probe("accepted-silently", "export: tracks with frame 0 twice (no jaw fields: the duplicate alone)",
      check=says("twice"))(lambda d: setup_tracks(d, lambda v: frame0_twice(v, False)))
probe("accepted-silently", "export: frames[0].jaw translation [500, 0, 0] (not lower against upper)")(
    lambda d: setup_tracks(d, lambda v: v["frames"][0]["jaw"].__setitem__("translation", [500, 0, 0])))

# -- messages: what the user is told ----------------------------------------------------------


def setup_rvec(d, rvec):
    y = Path(d) / "cam0.yml"
    text = (ROOT / "fixtures/calib/opencv4/cam0.yml").read_text()
    text, k = re.subn(r"(?ms)^R: !!opencv-matrix.*?(?=^T:)", f"rvec: {rvec}\n", text)
    assert k == 1, "cam0.yml has no R matrix before T"
    y.write_text(text)
    return ["import", "cameras", str(Path(d) / "cap"), str(y)], 0


probe("messages", "rvec [1e308, 0., 0.] in place of R: no NaN in the message",
      check=lambda rc, e, d: "WRONG" if "nan" in e.lower() else None)(
    lambda d: setup_rvec(d, "[1e308, 0., 0.]"))


# -- skin: `jawtrack skin` on hostile face sequences and tracks (issue 35) -------------------
IDENTITY = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]


def skin_set():
    """Two face sequences of 200 frames (fixtures/face-python) and a model learned from the
    first, made once a run: (set folder, model)."""
    if "skin" not in _CACHE:
        keep = Path(tempfile.mkdtemp(prefix="jawtrack-probes-skin-"))
        atexit.register(shutil.rmtree, keep, True)
        subprocess.run([sys.executable, str(ROOT / "fixtures/face-python/make.py"), str(keep / "set"), "2", "200"],
                       capture_output=True, check=True)
        subprocess.run([BINARY, "skin", "learn", str(keep / "set/p1"), "-o", str(keep / "model.json")],
                       capture_output=True, check=True)
        _CACHE["skin"] = (keep / "set", keep / "model.json")
    return _CACHE["skin"]


def face_copy(d):
    """A copy of the second subject (the one the model did not learn from) in d."""
    face = Path(d) / "p2"
    shutil.copytree(skin_set()[0] / "p2", face)
    return face


def skin_tracks(face):
    """A tracks.json of the face's true jaw poses: every third frame ok, the rest low-confidence."""
    poses = sorted(json.loads((face / "jaw.json").read_text())["poses"], key=lambda p: p["frame"])
    return {"format": "jawtrack-tracks/1", "frames": [
        {"frame": p["frame"], "upper": pose(), "lower": {"rotation": p["rotation"], "translation": p["translation"]},
         "status": "ok" if k % 3 == 0 else "low-confidence"} for k, p in enumerate(poses)]}


def setup_fill(d, edit):
    face = face_copy(d)
    tracks = skin_tracks(face)
    edit(tracks)
    t = Path(d) / "tracks.json"
    t.write_text(json.dumps(tracks))
    return ["skin", "fill", str(skin_set()[1]), str(face), "--tracks", str(t), "--out", str(Path(d) / "out.json")], size(t)


def setup_predict(d, edit):
    face = face_copy(d)
    edit(face)
    return ["skin", "predict", str(skin_set()[1]), str(face), "--out", str(Path(d) / "out.json")], 0


def far_frame(face):
    # Frame 1005's OBJ, its vertex count kept, every vertex at 3e38 (finite, in f32 range).
    obj = face / "frames" / "001005.obj"
    n = sum(1 for line in obj.read_text().splitlines() if line.startswith("v "))
    obj.write_text("v 3e38 3e38 3e38\n" * n)


def mandible_outside(face):
    # mandible.obj a link to a file beside the face sequence, not in it.
    outside = face.parent / "outside.obj"
    shutil.move(str(face / "mandible.obj"), outside)
    (face / "mandible.obj").symlink_to(outside)


def setup_one_subject(d):
    shutil.copytree(skin_set()[0] / "p1", Path(d) / "oneset" / "p1")
    return ["skin", "eval", "oneset"], 0


def names_set(rc, stderr, d):
    # The error must name the set folder it was given, not `.` (its subject's parent, say).
    return "MISLEADING" if "error: .:" in stderr or "oneset" not in stderr else None


def shift_one_ok(tracks):
    # The sixth ok record's lower translation 25 mm off in y; the rest are the truth.
    ok = [f for f in tracks["frames"] if f["status"] == "ok"]
    ok[5]["lower"]["translation"][1] += 25.0


def setup_wrong_ok(d):
    # Must run, and say on stdout that the wrong frame was left out of the calibration.
    argv, n = setup_fill(d, shift_one_ok)
    with tempfile.TemporaryFile() as out:
        crash, rc, stderr, rss, _ = run([BINARY, *argv], d, stdout=out)
        out.seek(0)
        said = [line for line in out.read().decode("utf-8", "replace").splitlines()
                if "left out of the calibration" in line]
    outcome = crash or ("ran" if rc == 0 and said else "WRONG")
    note = said[0] if said else "stdout does not say `left out of the calibration`"
    return outcome, rc, stderr + "\n" + note, rss, n


probe("skin", "fill: tracks format \"other-tracks/2\"", check=says("format"))(
    lambda d: setup_fill(d, lambda t: t.__setitem__("format", "other-tracks/2")))
probe("skin", "fill: tracks with a frame record twice", check=says("twice"))(
    lambda d: setup_fill(d, lambda t: t["frames"].insert(1, json.loads(json.dumps(t["frames"][0])))))
probe("skin", "predict: frame 1005's OBJ with every vertex at 3e38", check=says("beyond"))(
    lambda d: setup_predict(d, far_frame))
probe("skin", "predict: mandible.obj a link outside the face sequence (no --allow-outside hint)",
      check=lambda rc, e, d: "MISLEADING" if "--allow-outside" in e else None)(
    lambda d: setup_predict(d, mandible_outside))
probe("skin", "eval: a set of one subject (the error names the set)", check=names_set)(setup_one_subject)
direct_probe("skin", "fill: one wrong ok record (lower y + 25 mm): runs, left out of the calibration")(
    setup_wrong_ok)


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
    skipped = set()
    for p in PROBES:
        if a.only and a.only != p.cls:
            continue
        why = p.needs() if p.needs else None
        if why:
            if p.cls not in skipped:
                print(f"-- skipped [{p.cls}]: {why}", flush=True)
                skipped.add(p.cls)
            continue
        with tempfile.TemporaryDirectory() as d:
            try:
                if p.direct:
                    started = time.time()
                    outcome, rc, stderr, rss, n = p.setup(d)
                    secs = time.time() - started
                else:
                    argv, n = p.setup(d)
            except (subprocess.CalledProcessError, SetupFailed) as e:
                detail = str(e) + (f": {e.stderr[-300:]!r}" if getattr(e, "stderr", None) else "")
                rows.append(dict(cls=p.cls, name=p.name, outcome="SETUP-FAILED", detail=detail))
                print(f"!! SETUP-FAILED [{p.cls}] {p.name}: {detail[:300]}", flush=True)
                continue
            if not p.direct:
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
