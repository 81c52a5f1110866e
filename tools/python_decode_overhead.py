#!/usr/bin/env python3
"""The Python package's decode against the command-line tool's, on one file.

    tools/python_decode_overhead.py FILE.gsi [--gsi target/release/gsi] [--rounds 15]

Run with the Python that has the package installed (`pip install ./python`). Paired rounds,
alternating: the tool decoding FILE to PPM as a whole process (wall, and CPU from the OS's
accounting of the finished child), `gsi.decode(path)` in this process (wall and this
process's CPU time: reading the file, rendering, the numpy array), and a whole `python -c
"import gsi; gsi.decode(...)"` process (interpreter and numpy start-up included). Prints
medians in milliseconds.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import gsi


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed_process(cmd):
    c0, t0 = child_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0, child_cpu() - c0


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("file")
    p.add_argument("--gsi", default="target/release/gsi")
    p.add_argument("--rounds", type=int, default=15)
    args = p.parse_args()
    out = os.path.join(tempfile.mkdtemp(), "x.ppm")
    cli = [args.gsi, "decode", args.file, "-o", out, "--device", "cpu"]
    script = f"import gsi; gsi.decode({args.file!r})"
    whole_python = [sys.executable, "-c", script]
    gsi.decode(args.file)  # warm the page cache and rayon's pool
    rows = {"cli": [], "python call": [], "python process": []}
    for _ in range(args.rounds):
        rows["cli"].append(timed_process(cli))
        c0, t0 = time.process_time(), time.perf_counter()
        gsi.decode(args.file)
        rows["python call"].append((time.perf_counter() - t0, time.process_time() - c0))
        rows["python process"].append(timed_process(whole_python))
    cli_wall = statistics.median(w for w, _ in rows["cli"])
    cli_cpu = statistics.median(c for _, c in rows["cli"])
    print(f"{args.file}, {args.rounds} paired rounds, medians")
    print(f"{'':16} {'wall ms':>8} {'CPU ms':>8} {'wall/cli':>9} {'CPU/cli':>8}")
    for name, xs in rows.items():
        wall = statistics.median(w for w, _ in xs)
        cpu = statistics.median(c for _, c in xs)
        print(f"{name:16} {1e3 * wall:8.1f} {1e3 * cpu:8.1f} {wall / cli_wall:9.2f} "
              f"{cpu / cli_cpu:8.2f}")


if __name__ == "__main__":
    main()
