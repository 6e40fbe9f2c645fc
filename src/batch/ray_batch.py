#!/usr/bin/env python3
"""Run a jawtrack batch on a Ray cluster (written by `jawtrack batch ray`).

Reads commands.json beside it: one `jawtrack track ... --resume` per chunk, then one
`jawtrack merge` per take. Each chunk is a Ray task; a task that fails or whose worker dies is
retried, and `--resume` continues its chunk after its last finished frame. The merges run
once every chunk has succeeded. The batch folder and the captures must be on a file system
every node sees, at the same paths (as for Slurm).

    python3 ray_batch.py DIR [--address auto] [--cpus 1] [--gpus 0] [--retries 3]
"""

import argparse
import json
import os
import subprocess
import sys

import ray


def run_logged(jawtrack, args, workdir, log, threads):
    """Run jawtrack with args in workdir, appending its output to log; raise if it fails."""
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    with open(log, "ab") as out:
        code = subprocess.run(
            [jawtrack] + args, cwd=workdir, env=env, stdout=out, stderr=out,
            stdin=subprocess.DEVNULL,
        ).returncode
    if code != 0:
        raise RuntimeError(f"jawtrack {args[0]} exited with {code}: see {log}")
    return log


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dir", help="the batch folder (jawtrack batch ray's -o)")
    p.add_argument("--address", default=None, help="the Ray cluster (default: start one here)")
    p.add_argument("--cpus", type=int, default=1, help="cores per chunk (its energy's threads)")
    p.add_argument("--gpus", type=float, default=0, help="GPUs per chunk")
    p.add_argument("--retries", type=int, default=3, help="times a failed chunk is run again")
    p.add_argument("--jawtrack", default=None, help="the jawtrack binary on the nodes")
    a = p.parse_args()

    with open(os.path.join(a.dir, "commands.json")) as f:
        commands = json.load(f)
    jawtrack = a.jawtrack or os.environ.get("JAWTRACK") or commands["jawtrack"]
    workdir, logs = commands["workdir"], os.path.join(a.dir, "logs")
    os.makedirs(logs, exist_ok=True)

    ray.init(address=a.address, include_dashboard=False, logging_level="ERROR")
    task = ray.remote(num_cpus=a.cpus, num_gpus=a.gpus, max_retries=a.retries,
                      retry_exceptions=True)(run_logged)
    pending = [
        task.remote(jawtrack, args, workdir, os.path.join(logs, f"ray-track-{i}.log"), a.cpus)
        for i, args in enumerate(commands["tasks"])
    ]
    failed = 0
    for i, ref in enumerate(pending):
        try:
            ray.get(ref)
            print(f"task {i} finished", flush=True)
        except Exception as e:  # noqa: BLE001 - every failure is reported, then counted
            print(f"task {i} FAILED: {e}", file=sys.stderr, flush=True)
            failed += 1
    if failed:
        print(f"{failed} chunks failed; run this again to resume them", file=sys.stderr)
        return 1
    merges = [
        task.remote(jawtrack, args, workdir, os.path.join(logs, f"ray-merge-{i}.log"), a.cpus)
        for i, args in enumerate(commands["merges"])
    ]
    for args, ref in zip(commands["merges"], merges):
        try:
            ray.get(ref)
            print(f"merged -> {args[args.index('-o') + 1]}", flush=True)
        except Exception as e:  # noqa: BLE001
            print(f"merge FAILED: {e}", file=sys.stderr, flush=True)
            failed += 1
    ray.shutdown()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
