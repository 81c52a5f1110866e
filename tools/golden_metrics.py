#!/usr/bin/env python3
"""Golden PSNR / SSIM / MS-SSIM values for tests/metrics.rs, from an independent code path.

PSNR is numpy; SSIM is scikit-image's structural_similarity with the conventions of
shared/data/README.md (Gaussian window 11, sigma 1.5, population covariance, data range
255, per channel, averaged); MS-SSIM (scikit-image has none) is written below from
Wang et al. 2003 on top of scipy.ndimage.gaussian_filter, with the crate's documented
conventions: 2x2 average pooling (odd row/column dropped), cs at scales 1..m-1, SSIM at
scale m, weights (0.0448, 0.2856, 0.3001, 0.2363, 0.1333) cut to the m scales with
side >= 11 * 2^(m-1) and renormalised, factors clamped at 0, per channel then averaged.

Pairs: three LOL eval15 pairs (low vs high), and three Kodak images vs a deterministic
perturbation that tests/metrics.rs reproduces exactly (no JPEG codec needed):
    out[y, x, c] = clip(in[y, x, c] + ((7x + 13y + 5c) % 21) - 10, 0, 255)
plus top-left crops of one Kodak pair (perturbed after cropping) small enough for fewer
than five MS-SSIM scales: 150x90 (4 scales), 60x47 (3), 40x30 (2), 21x25 (1).

    pip install scikit-image pillow
    python3 tools/golden_metrics.py [DATA_DIR]   # default: ../shared/data from the repo

Prints Rust constants to paste into tests/metrics.rs.
"""

import os
import sys

import numpy as np
from PIL import Image
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

WEIGHTS = np.array([0.0448, 0.2856, 0.3001, 0.2363, 0.1333])
LOL = ["1.png", "22.png", "111.png"]
KODAK = ["kodim01.png", "kodim04.png", "kodim23.png"]


def load(path):
    return np.asarray(Image.open(path).convert("RGB")).astype(np.float64)


def perturb(img):
    h, w, _ = img.shape
    y, x, c = np.meshgrid(np.arange(h), np.arange(w), np.arange(3), indexing="ij")
    return np.clip(img + ((7 * x + 13 * y + 5 * c) % 21) - 10, 0, 255)


def psnr(a, b):
    mse = np.mean((a - b) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def ssim(a, b):
    return structural_similarity(
        a, b, channel_axis=2, data_range=255, gaussian_weights=True,
        sigma=1.5, use_sample_covariance=False,
    )


def ssim_cs(x, y, data_range=255.0):
    """Mean SSIM and mean cs of one channel, from the definition (reflect, crop 5)."""
    f = lambda v: gaussian_filter(v, sigma=1.5, truncate=3.5, mode="reflect")
    mx, my = f(x), f(y)
    vx, vy, vxy = f(x * x) - mx * mx, f(y * y) - my * my, f(x * y) - mx * my
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    cs = (2 * vxy + c2) / (vx + vy + c2)
    s = (2 * mx * my + c1) / (mx * mx + my * my + c1) * cs
    crop = (slice(5, -5), slice(5, -5))
    return s[crop].mean(), cs[crop].mean()


def pool(v):
    h, w = v.shape[0] // 2 * 2, v.shape[1] // 2 * 2
    return v[:h, :w].reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))


def ms_ssim(a, b):
    side = min(a.shape[:2])
    m = sum(1 for j in range(5) if side >> j >= 11)
    w = WEIGHTS[:m] / WEIGHTS[:m].sum()
    out = []
    for c in range(3):
        x, y, val = a[..., c], b[..., c], 1.0
        for j in range(m):
            s, cs = ssim_cs(x, y)
            val *= max(s if j == m - 1 else cs, 0.0) ** w[j]
            x, y = pool(x), pool(y)
        out.append(val)
    return float(np.mean(out))


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    data = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "..", "shared", "data")
    rows = []
    for n in LOL:
        lo = load(os.path.join(data, "LOL/eval15/low", n))
        hi = load(os.path.join(data, "LOL/eval15/high", n))
        rows.append((f"LOL/eval15/low/{n}", f"LOL/eval15/high/{n}", 0, 0, hi, lo))
    for n in KODAK:
        k = load(os.path.join(data, "kodak", n))
        rows.append((f"kodak/{n}", "", 0, 0, k, perturb(k)))
    k = load(os.path.join(data, "kodak", KODAK[0]))
    for cw, ch in [(150, 90), (60, 47), (40, 30), (21, 25)]:
        c = k[:ch, :cw]
        rows.append((f"kodak/{KODAK[0]}", "", cw, ch, c, perturb(c)))
    print("/// (image, reference or \"\" for the perturbed image itself, top-left crop width and")
    print("/// height or 0 for none, PSNR, SSIM, MS-SSIM),")
    print("/// from tools/golden_metrics.py (scikit-image", end=" ")
    import skimage
    print(f"{skimage.__version__}).")
    print("#[rustfmt::skip]")
    print("const GOLDEN: [(&str, &str, u32, u32, f64, f64, f64); %d] = [" % len(rows))
    for img, ref, cw, ch, r, o in rows:
        print(f'    ("{img}", "{ref}", {cw}, {ch}, {psnr(r, o):.10f}, {ssim(r, o):.10f}, {ms_ssim(r, o):.10f}),')
    print("];")


if __name__ == "__main__":
    main()
