#!/usr/bin/env python3
"""Whole-process decode time of .gsi files against djpeg and dwebp at equal bytes.

For each .gsi file given, makes the JPEG (cjpeg -optimize) and the WebP (cwebp) of the
highest quality whose file is no larger than the .gsi file, from the PNG the .gsi was
encoded from, then decodes each file to PPM as a whole process, N rounds, the decoders
alternating within a round (so that a noisy neighbour slows every decoder alike), in the
reverse order every other round. CPU time is the finished child's user + system time
from the OS (os.wait4), wall time from a monotonic clock. Prints medians and the ratios
to djpeg, and with --gsi-before the median of the two builds' per-round differences;
with --json, writes them too.

Usage:
  tools/decode_speed.py --gsi target/release/gsi [--gsi-before OLD/gsi] \\
      --pair kodim23.gsi=kodim23.png [--pair ...] [--rounds 15] [--json out.json]

With `--pair NEW.gsi,OLD.gsi=SOURCE.png` the earlier build decodes OLD.gsi (the file its
own encoder wrote) and the JPEG and WebP budgets are NEW.gsi's size.

cjpeg, djpeg, cwebp and dwebp come from PATH (Debian: libjpeg-turbo-progs, webp);
Pillow converts the PNG for cjpeg.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time


def run_process(cmd):
    """(cpu seconds, wall seconds, what it printed on stdout and stderr) of one process,
    CPU time from the OS's accounting of the finished process; exits where it fails."""
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = p.stdout.read().decode(errors="replace")
    p.stdout.close()
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.monotonic() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(cmd)} failed: {out}")
    return usage.ru_utime + usage.ru_stime, wall, out


def run_timed(cmd):
    """(cpu seconds, wall seconds) of one process, its output discarded."""
    cpu, wall, _ = run_process(cmd)
    return cpu, wall


def best_under(make, budget, qualities):
    """The highest quality whose file `make(q)` writes in no more than `budget` bytes."""
    best = None
    lo, hi = 0, len(qualities) - 1
    while lo <= hi:
        mid = (lo + hi) // 2
        size = make(qualities[mid])
        if size <= budget:
            best = qualities[mid]
            lo = mid + 1
        else:
            hi = mid - 1
    if best is None:
        sys.exit("no quality fits the budget")
    make(best)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gsi", required=True)
    ap.add_argument("--gsi-before")
    ap.add_argument("--pair", action="append", required=True,
                    help="FILE.gsi=SOURCE.png, or FILE.gsi,BEFORE.gsi=SOURCE.png")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--json")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="gsi-decode-speed-")
    ppm_src = os.path.join(tmp, "src.ppm")
    out = os.path.join(tmp, "out.ppm")
    report = []
    for pair in a.pair:
        files, png = pair.split("=", 1)
        gsi_file, _, before_file = files.partition(",")
        before_file = before_file or gsi_file
        budget = os.path.getsize(gsi_file)
        subprocess.run([a.gsi, "decode", gsi_file, "-o", out], check=True)
        # cjpeg reads PPM, not PNG.
        from PIL import Image
        Image.open(png).convert("RGB").save(ppm_src)
        jpg = os.path.join(tmp, "a.jpg")
        webp = os.path.join(tmp, "a.webp")

        def make_jpg(q):
            subprocess.run(["cjpeg", "-optimize", "-quality", str(q), "-outfile", jpg, ppm_src],
                           check=True)
            return os.path.getsize(jpg)

        def make_webp(q):
            subprocess.run(["cwebp", "-quiet", "-q", str(q), png, "-o", webp], check=True)
            return os.path.getsize(webp)

        qj = best_under(make_jpg, budget, list(range(1, 101)))
        qw = best_under(make_webp, budget, list(range(0, 101)))
        decoders = {
            "gsi": [a.gsi, "decode", gsi_file, "-o", out, "--device", "cpu"],
            "djpeg": ["djpeg", "-outfile", out, jpg],
            "dwebp": ["dwebp", webp, "-ppm", "-o", out],
        }
        if a.gsi_before:
            decoders["gsi-before"] = [a.gsi_before, "decode", before_file, "-o", out, "--device", "cpu"]
        times = {k: [] for k in decoders}
        names = list(decoders)
        for r in range(a.rounds):
            # Forwards, then backwards: no decoder always runs after the same one.
            for k in names if r % 2 == 0 else reversed(names):
                times[k].append(run_timed(decoders[k]))
        row = {
            "file": gsi_file,
            "bytes": {"gsi": budget, "jpeg": os.path.getsize(jpg), "webp": os.path.getsize(webp)},
            "quality": {"jpeg": qj, "webp": qw},
            "rounds": a.rounds,
        }
        for k, ts in times.items():
            row[k] = {
                "cpu_ms": statistics.median(t[0] for t in ts) * 1e3,
                "wall_ms": statistics.median(t[1] for t in ts) * 1e3,
            }
        if a.gsi_before:
            # The two builds ran in the same rounds: the median of their per-round
            # differences moves less with the machine's load than either median does.
            diffs = [n[0] - b[0] for n, b in zip(times["gsi"], times["gsi-before"])]
            row["gsi_minus_before_cpu_ms"] = statistics.median(diffs) * 1e3
        report.append(row)
        print(f"{gsi_file}: {budget} B (JPEG q{qj} {row['bytes']['jpeg']} B, "
              f"WebP q{qw} {row['bytes']['webp']} B), medians of {a.rounds} rounds")
        for k in decoders:
            r = row[k]
            print(f"  {k:10} CPU {r['cpu_ms']:6.1f} ms  wall {r['wall_ms']:6.1f} ms  "
                  f"CPU/djpeg {r['cpu_ms'] / row['djpeg']['cpu_ms']:5.2f}")
        if a.gsi_before:
            print(f"  gsi - gsi-before, CPU, median of the paired rounds: "
                  f"{row['gsi_minus_before_cpu_ms']:+.2f} ms")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
