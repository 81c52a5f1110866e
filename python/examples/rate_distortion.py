"""PSNR against bits per pixel for a folder of images.

    python examples/rate_distortion.py FOLDER [--bpp 0.25 0.5 1.0] [--effort N]
        [--plot rd.png]

Loads every image in FOLDER with Pillow, encodes it at each budget, decodes it and measures
PSNR on 8-bit RGB against the original; prints one line per image and budget, and the mean
per budget. With matplotlib installed, the curves are plotted into --plot (default
rd.png); without it, the plot is skipped and said so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np
from PIL import Image

import gsi


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def measure(folder: Path, budgets: List[float], effort: Optional[int]) -> Dict[str, List[tuple]]:
    """`{image name: [(bpp as stored, PSNR), ...]}`."""
    curves = {}
    for path in sorted(folder.iterdir()):
        try:
            image = np.asarray(Image.open(path).convert("RGB"))
        except OSError:
            continue  # not an image
        points = []
        for bpp in budgets:
            data = gsi.encode(image, bpp=bpp, effort=effort)
            stored = 8 * len(data) / (image.shape[0] * image.shape[1])
            points.append((stored, psnr(image, gsi.decode(data))))
            print(f"{path.name:24} {bpp:5.2f} bpp asked  {stored:.3f} stored  "
                  f"{points[-1][1]:6.2f} dB")
        curves[path.name] = points
    return curves


def plot(curves: Dict[str, List[tuple]], out: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return False
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, points in curves.items():
        x, y = zip(*points)
        ax.plot(x, y, marker="o", label=name)
    ax.set_xlabel("bits per pixel")
    ax.set_ylabel("PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"plot written to {out}")
    return True


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path)
    p.add_argument("--bpp", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    p.add_argument("--effort", type=int, default=None, help="1..9 (default: gsi's)")
    p.add_argument("--plot", type=Path, default=Path("rd.png"))
    args = p.parse_args(argv)
    curves = measure(args.folder, args.bpp, args.effort)
    if not curves:
        print(f"no images in {args.folder}", file=sys.stderr)
        return 1
    for i, bpp in enumerate(args.bpp):
        mean = np.mean([points[i][1] for points in curves.values()])
        print(f"mean at {bpp} bpp: {mean:.2f} dB over {len(curves)} images")
    plot(curves, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
