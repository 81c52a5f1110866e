"""Encode (and optionally enhance) a folder of images on a dask.distributed cluster.

    python examples/dask_folder.py PHOTOS OUT [--bpp 1.0] [--enhance]
        [--scheduler tcp://host:8786] [--workers 2]

Without --scheduler a LocalCluster of worker processes on this machine does the work; with
one, the same code runs on a real cluster (every worker needs `pip install ./python`).
Each file is one task: read, encode, enhance when asked, returned as bytes and written here,
through a temporary file renamed into place. A file that fails is reported with its one-line
reason and the others go on; the exit status is 1 when any failed.

The outputs are byte-identical to `gsi.encode` / `gsi.enhance` called in one process (and
to `gsi encode` / `gsi enhance` on the same machine): every random choice is seeded.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

import gsi

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm"}


def load(path: str) -> np.ndarray:
    """An image file as an array, as `gsi encode` reads it (upright, 8 or 16 bit)."""
    from PIL import Image, ImageOps

    with Image.open(path) as im:
        im = ImageOps.exif_transpose(im)
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):
            return np.asarray(im, dtype=np.uint16)
        return np.asarray(im.convert("RGB"))


def process(path: str, bpp: float, enhance: bool) -> Tuple[str, Optional[bytes], Optional[str]]:
    """One task: `(path, file bytes, None)`, or `(path, None, why)` when it failed."""
    try:
        data = gsi.encode(load(path), bpp=bpp)
        if enhance:
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", gsi.NotLowLightWarning)
                data = gsi.enhance(data)
        return path, data, None
    except Exception as e:  # noqa: BLE001 - every failure is reported, none is fatal
        return path, None, f"{type(e).__name__}: {e}"


def write_atomic(path: Path, data: bytes) -> None:
    """Write through a synced temporary file in the same folder, then rename."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def run(
    client, paths: List[str], out: Path, bpp: float = 1.0, enhance: bool = False
) -> Dict[str, str]:
    """Map [`process`] over `paths` on `client`; write `<stem>.gsi` files to `out` as
    results arrive. Returns the failures, by path."""
    from dask.distributed import as_completed

    out.mkdir(parents=True, exist_ok=True)
    futures = client.map(process, paths, bpp=bpp, enhance=enhance, pure=False)
    failed = {}
    for future in as_completed(futures):
        path, data, why = future.result()
        if why is not None:
            failed[path] = why
            continue
        write_atomic(out / (Path(path).stem + ".gsi"), data)
    return failed


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--bpp", type=float, default=1.0)
    p.add_argument("--enhance", action="store_true")
    p.add_argument("--scheduler", help="address of a running scheduler (default: a LocalCluster)")
    p.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    args = p.parse_args(argv)
    from dask.distributed import Client, LocalCluster

    paths = sorted(
        str(f) for f in args.folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES
    )
    if args.scheduler:
        client = Client(args.scheduler)
    else:
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True)
        client = Client(cluster)
    with client:
        failed = run(client, paths, args.out, args.bpp, args.enhance)
    for path, why in sorted(failed.items()):
        print(f"gsi: {path}: {why}", file=sys.stderr)
    print(f"{len(paths) - len(failed)} of {len(paths)} files written to {args.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
