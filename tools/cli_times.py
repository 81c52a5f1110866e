#!/usr/bin/env python3
"""Whole-process times of `gsi decode`, `gsi encode` and `gsi enhance` on each `--device`.

What a user waits for, start-up included: each command is run as its own process, the
devices taking turns round by round (reversed every other round), and the medians of the
wall time and of the finished process's CPU time (user + system, from the OS) reported.
`cpu2` is `--device cpu` pinned to two cores with `taskset`, the development machine's
count. On a machine with a GPU (the `device` tool's, through `tools/gpu-kit.sh`):

    python3 tools/cli_times.py --gsi .gpukit/gsi --out "$OUT/cli.json" \\
        --decode k23.gsi --decode k23.gsi:--width,4243 \\
        --encode kodim01.png:1 --enhance 119.png:1.1

`--decode FILE[:ARGS]` decodes FILE to PPM (ARGS comma-separated, added to the command);
`--encode IMAGE:BPP` encodes IMAGE at BPP bits per pixel; `--enhance IMAGE:BPP` encodes
IMAGE on the first device once, then enhances that file. The last line each command
prints (an encode's size and PSNR) is kept in the JSON beside its times.
"""
import argparse
import json
import os
import statistics
import tempfile

from decode_speed import run_process


def run(cmd, device):
    """Run `cmd` with `--device`, return (wall s, CPU s, last line of its output)."""
    pin = ["taskset", "-c", "0,1"] if device == "cpu2" else []
    dev = "cpu" if device == "cpu2" else device
    cpu, wall, out = run_process(pin + cmd + ["--device", dev])
    out = out.strip()
    return wall, cpu, out.splitlines()[-1] if out else ""


def split(spec):
    path, _, rest = spec.partition(":")
    return path, rest


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gsi", required=True, help="the gsi binary")
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--devices", default="gpu,cpu,cpu2")
    ap.add_argument("--decode", action="append", default=[], metavar="FILE[:ARGS]")
    ap.add_argument("--encode", action="append", default=[], metavar="IMAGE:BPP")
    ap.add_argument("--enhance", action="append", default=[], metavar="IMAGE:BPP")
    ap.add_argument("--decode-rounds", type=int, default=11)
    ap.add_argument("--encode-rounds", type=int, default=1)
    ap.add_argument("--enhance-rounds", type=int, default=3)
    args = ap.parse_args()
    devices = args.devices.split(",")
    tmp = tempfile.mkdtemp()
    jobs = []  # (label, command without --device, rounds)
    for spec in args.decode:
        path, extra = split(spec)
        extra = [a for a in extra.split(",") if a]
        cmd = [args.gsi, "decode", path, "-o", os.path.join(tmp, "out.ppm")] + extra
        jobs.append((f"decode {os.path.basename(path)} {' '.join(extra)}".strip(), cmd, args.decode_rounds))
    for spec in args.encode:
        path, bpp = split(spec)
        cmd = [args.gsi, "encode", path, "-o", os.path.join(tmp, "enc.gsi"), "--bpp", bpp]
        jobs.append((f"encode {os.path.basename(path)} at {bpp} bpp", cmd, args.encode_rounds))
    for spec in args.enhance:
        path, bpp = split(spec)
        stored = os.path.join(tmp, os.path.basename(path) + ".gsi")
        run([args.gsi, "encode", path, "-o", stored, "--bpp", bpp, "--quiet"], devices[0])
        cmd = [args.gsi, "enhance", stored, "-o", os.path.join(tmp, "enh.gsi")]
        jobs.append((f"enhance {os.path.basename(path)} ({bpp} bpp)", cmd, args.enhance_rounds))
    results = []
    for label, cmd, rounds in jobs:
        times = {d: [] for d in devices}
        lines = {}
        for r in range(rounds):
            for d in devices if r % 2 == 0 else devices[::-1]:
                wall, cpu, line = run(cmd, d)
                times[d].append((wall, cpu))
                lines[d] = line
        for d in devices:
            wall = statistics.median(t[0] for t in times[d])
            cpu = statistics.median(t[1] for t in times[d])
            print(f"{label:40s} {d:5s} wall {wall * 1e3:9.1f} ms  CPU {cpu * 1e3:9.1f} ms  | {lines[d]}", flush=True)
            results.append(dict(job=label, device=d, rounds=rounds, wall_s=wall, cpu_s=cpu, last_line=lines[d]))
    with open(args.out, "w") as f:
        json.dump(dict(commit=os.environ.get("GSI_COMMIT"), devices=devices, results=results), f, indent=1)


if __name__ == "__main__":
    main()
