#!/usr/bin/env python3
"""How much of a NIQE difference is grain: NIQE of images as they are, and with Gaussian
noise of a fraction of one 8-bit step added.

NIQE scores a patch's local statistics against those of pristine photographs, in which
smooth areas still carry sensor grain. A Gaussian render is smooth to the last bit, and
a power curve applied after the rounding to 8 bits turns each step of the shadows into
several, a grain that NIQE reads as texture. This script measures how far that alone moves
the score: if noise too faint to see (sigma = 0.5 of a step) moves a set's median NIQE
more than the difference between two methods, NIQE cannot rank them.

    python3 tools/niqe_grain.py DIR [DIR ...] [--sigma 0.5,1] [--gsi target/release/gsi]

Each DIR holds PNG files; prints per-image NIQE and the median per DIR and sigma. The
noise is seeded (numpy's default generator, seed 0), rounded and clamped to 8 bits.
Needs numpy and Pillow.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import tempfile

import numpy as np
from PIL import Image

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ap = argparse.ArgumentParser()
ap.add_argument('dirs', nargs='+')
ap.add_argument('--sigma', default='0.5,1')
ap.add_argument('--gsi', default=os.path.join(root, 'target', 'release', 'gsi'))
args = ap.parse_args()
sigmas = [0.0] + [float(s) for s in args.sigma.split(',')]


def niqe(path):
    out = subprocess.run([args.gsi, 'compare', path, '--no-reference', '--json'],
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out)['niqe']


with tempfile.TemporaryDirectory() as tmp:
    for d in args.dirs:
        files = sorted(glob.glob(os.path.join(d, '*.png')))
        if not files:
            raise SystemExit(f'no PNG files in {d}')
        rng = np.random.default_rng(0)
        scores = {s: [] for s in sigmas}
        for f in files:
            rgb = np.asarray(Image.open(f).convert('RGB')).astype(np.float64)
            row = []
            for s in sigmas:
                if s == 0.0:
                    path = f
                else:
                    noisy = np.clip(np.round(rgb + rng.normal(0.0, s, rgb.shape)), 0, 255)
                    path = os.path.join(tmp, 'noisy.png')
                    Image.fromarray(noisy.astype(np.uint8)).save(path)
                scores[s].append(niqe(path))
                row.append(f'{scores[s][-1]:.2f}')
            print(f'{d} {os.path.basename(f)}: NIQE ' + ' / '.join(row)
                  + ' (noise sigma ' + ' / '.join(f'{s:g}' for s in sigmas) + ')')
        print(f'{d}: median NIQE ' + ', '.join(
            f'{statistics.median(scores[s]):.3f} at sigma {s:g}' for s in sigmas))
