"""gsi: images stored as 2D Gaussians.

numpy in, numpy out: :func:`encode` fits Gaussians to an image and returns a ``.gsi``
file's bytes, :func:`decode` renders a file at any size, :func:`enhance` and :func:`revert`
run stage 2 (zero-shot low-light enhancement inside the file) and undo it, :func:`info`
describes a file as ``gsi info --json`` does, and :func:`read` / :func:`render` give the
Gaussians as arrays and render a scene edited in numpy.

Everything is the Rust library's own code (the command-line tool's too): the same image
and options give the bytes ``gsi encode`` writes, and the same file the pixels ``gsi
decode`` writes. The GIL is released while encoding, enhancing and rendering, so threads
run in parallel; the library itself also uses every core.

    >>> import numpy as np, gsi
    >>> image = np.random.default_rng(0).random((48, 64, 3), dtype=np.float32)
    >>> data = gsi.encode(image, gaussians=200)
    >>> gsi.decode(data).shape
    (48, 64, 3)
    >>> gsi.decode(data, width=128).shape
    (96, 128, 3)
"""

from __future__ import annotations

import json
import os
import warnings
from typing import Any, Callable, Dict, Optional, Sequence, Union

import numpy as np

from . import _gsi
from ._gsi import Error

__all__ = [
    "Error",
    "NotLowLightWarning",
    "encode",
    "decode",
    "enhance",
    "revert",
    "info",
    "read",
    "render",
]

Data = Union[bytes, bytearray, memoryview, str, "os.PathLike[str]"]
Progress = Callable[[Dict[str, Any]], None]


class NotLowLightWarning(UserWarning):
    """:func:`enhance` left an image unchanged: no meaningful part of it is under-exposed
    (the message says which share of the image, at which level), or it is black (no value
    reaches half an 8-bit step). ``force=True`` enhances it anyway."""


def _bytes(data: Data) -> bytes:
    """The bytes of a file given as bytes-like or as a path."""
    if isinstance(data, bytes):
        return data
    if isinstance(data, (bytearray, memoryview)):
        return bytes(data)
    if isinstance(data, (str, os.PathLike)):
        try:
            with open(data, "rb") as f:
                return f.read()
        except OSError as e:
            raise Error(f"{os.fspath(data)}: {e.strerror or e}") from None
    raise TypeError(f"expected bytes or a path, not {type(data).__name__}")


def _rgb(image: Any) -> np.ndarray:
    """An H×W×3 C-contiguous array of uint8, uint16 or float32, from what :func:`encode`
    takes: H×W (grey, replicated as ``gsi encode`` does), H×W×1, H×W×3 or H×W×4 (alpha
    dropped, as ``gsi encode`` does), in any memory layout."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4):
        raise Error(f"image of shape {a.shape}: expected H×W, H×W×1, H×W×3 or H×W×4")
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    elif a.shape[2] == 4:
        a = a[:, :, :3]
    if a.dtype == np.float64:
        a = a.astype(np.float32)
    if a.dtype not in (np.uint8, np.uint16, np.float32):
        raise Error(f"image of dtype {a.dtype}: expected uint8, uint16 or float in [0, 1]")
    return np.ascontiguousarray(a)


def encode(
    image: Any,
    *,
    bpp: Optional[float] = None,
    gaussians: Optional[int] = None,
    target_psnr: Optional[float] = None,
    effort: Optional[int] = None,
    blend: str = "sum",
    seed: int = 0,
    device: str = "cpu",
    progress: Optional[Progress] = None,
) -> bytes:
    """Fit Gaussians to ``image`` and return the ``.gsi`` file's bytes.

    ``image`` is H×W (grey) or H×W×3 (H×W×4: alpha dropped), ``uint8``, ``uint16`` or float
    in [0, 1]. The budget is one of ``bpp`` (bits per pixel of the whole file), ``gaussians``
    or ``target_psnr`` (dB); 1 bpp when none is given. ``effort`` runs from 1 (fast) to 9
    (thorough), ``gsi encode``'s default when not given; ``blend`` is ``"sum"`` or
    ``"alpha"``; ``device`` is ``"cpu"``, ``"gpu"`` (any adapter) or ``"auto"`` (a hardware
    GPU when there is one). The same image, options
    and seed give the same bytes as ``gsi encode`` on the same machine.

    ``progress``, if given, is called with a dict (``stage``, ``work`` in [0, 1],
    ``iteration``, ``total``, ``gaussians``, ``psnr``) every few iterations; an exception it
    raises is raised when the encode returns.
    """
    a = _rgb(image)
    bits = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16, np.dtype(np.float32): 32}[a.dtype]
    height, width = a.shape[0], a.shape[1]
    return _gsi.encode(
        a.tobytes(),
        bits,
        width,
        height,
        bpp=bpp,
        gaussians=gaussians,
        target_psnr=target_psnr,
        effort=effort,
        blend=blend,
        seed=seed,
        device=device,
        progress=progress,
    )


def decode(
    data: Data,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    dtype: Any = np.uint8,
) -> np.ndarray:
    """Render a ``.gsi`` file (bytes or a path) as an H×W×3 array.

    At the stored size by default; given one of ``width`` and ``height``, the other follows
    the aspect ratio. ``dtype`` ``uint8`` gives the pixels ``gsi decode`` writes;
    ``float32`` (or ``float64``) gives the blended values before rounding, not clamped
    (``sum`` blending may leave [0, 1]).
    """
    dt = np.dtype(dtype)
    if dt not in (np.uint8, np.float32, np.float64):
        raise Error(f"dtype {dt}: expected uint8, float32 or float64")
    pixels, w, h = _gsi.decode(_bytes(data), width, height, dt != np.uint8)
    return _pixels(pixels, w, h, dt)


def _pixels(pixels: bytearray, w: int, h: int, dt: np.dtype) -> np.ndarray:
    if dt == np.uint8:
        return np.frombuffer(pixels, dtype=np.uint8).reshape(h, w, 3)
    out = np.frombuffer(pixels, dtype=np.float32).reshape(h, w, 3)
    return out.astype(dt) if dt != np.float32 else out


def enhance(
    data: Data,
    *,
    exposure: Union[None, float, str] = None,
    iterations: Optional[int] = None,
    experts: Optional[int] = None,
    learning_rate: Optional[float] = None,
    weights: Optional[Sequence[float]] = None,
    tone: Optional[float] = None,
    local: bool = True,
    shadow_colour: bool = False,
    speckle: bool = False,
    denoise: bool = False,
    force: bool = False,
    discard_original: bool = False,
    apply_from: Optional[Data] = None,
    seed: int = 0,
    device: str = "cpu",
    progress: Optional[Progress] = None,
) -> bytes:
    """Stage 2: enhance a low-light file's colours in the file, and return its bytes.

    The options and defaults are ``gsi enhance``'s: ``exposure`` the mean luma to show the
    result at (default middle grey; ``"auto"`` meters it), ``tone`` the tone curve's power,
    ``local=False`` no gain map, ``shadow_colour=True`` no chroma map (the colour of
    regions within the noise of black kept), ``speckle=True`` the Gaussians fitted to noise
    kept, ``denoise=True`` smoothing across neighbours first,
    ``discard_original=True`` a smaller file that cannot be reverted, ``apply_from`` the
    enhancer stored in another file instead of fitting one. A file with no meaningful
    under-exposed part, or a black one, is returned unchanged with a
    :class:`NotLowLightWarning` unless ``force=True``. ``progress`` is called with a dict
    (``stage``, ``work``, ``iteration``, ``total``, ``loss``) every iteration.
    """
    raw = _bytes(data)
    out, why = _gsi.enhance(
        raw,
        exposure=exposure,
        iterations=iterations,
        experts=experts,
        learning_rate=learning_rate,
        weights=None if weights is None else [float(w) for w in weights],
        tone=tone,
        local=local,
        shadow_colour=shadow_colour,
        speckle=speckle,
        denoise=denoise,
        force=force,
        discard_original=discard_original,
        apply_from=None if apply_from is None else _bytes(apply_from),
        seed=seed,
        device=device,
        progress=progress,
    )
    if why is not None:
        warnings.warn(why, NotLowLightWarning, stacklevel=2)
    return out


def revert(data: Data) -> bytes:
    """Undo :func:`enhance`: the file as it was before, byte for byte (an error when its
    original colours were discarded or it was never enhanced)."""
    return _gsi.revert(_bytes(data))


def info(data: Data) -> Dict[str, Any]:
    """What ``gsi info --json`` prints for the file, as a dict (the same keys and values)."""
    return json.loads(_gsi.info(_bytes(data)))


def read(data: Data) -> Dict[str, Any]:
    """The Gaussians of a file as numpy arrays, as the renderer sees them.

    Keys: ``width`` and ``height`` (the stored size), ``blend`` (``"sum"`` or
    ``"alpha"``), ``cov_param`` (``"cholesky"``: ``(l11, l21, l22)``, or
    ``"log-scale-rotation"``: ``(ln σ1, ln σ2, θ)``), ``positions`` (N×2 float32, ``(u, v)``
    = ``(x / W, y / H)``), ``cov`` (N×3, the covariance parameters as stored),
    ``covariance`` (N×2×2, the matrix in the same normalized units, under the format's
    clamps), ``colors`` (N×3, sRGB-encoded), ``opacity`` (N, or None: all 1), ``tone``
    (None, or the tone curve every blended value goes through: a ``uint16`` array of 1 or 3
    rows of knots) and ``weights`` (``"columns-32"``, the rule of the files written since
    format 1.5, ``"columns"``, that of files written by format 1.4, or ``"per-pixel"``:
    how a Gaussian's weight at a pixel is computed, which moves rare 8-bit values by one
    step). :func:`render` of this dict, edited or not, renders it; ``covariance``
    is derived and not read back.
    """
    d = _gsi.read(_bytes(data))

    def rows(name: str, k: int) -> np.ndarray:
        return np.frombuffer(d[name], dtype=np.float32).reshape(-1, k).copy()

    s = rows("covariance", 3)
    covariance = np.stack([s[:, 0], s[:, 1], s[:, 1], s[:, 2]], axis=1).reshape(-1, 2, 2)
    tone = None
    if d["tone"] is not None:
        curves, values = d["tone"]
        tone = np.frombuffer(values, dtype=np.uint16).reshape(curves, -1).copy()
    return {
        "width": d["width"],
        "height": d["height"],
        "blend": d["blend"],
        "cov_param": d["cov_param"],
        "weights": d["weights"],
        "positions": rows("positions", 2),
        "cov": rows("cov", 3),
        "covariance": covariance,
        "colors": rows("colors", 3),
        "opacity": None
        if d["opacity"] is None
        else np.frombuffer(d["opacity"], dtype=np.float32).copy(),
        "tone": tone,
    }


def render(
    scene: Dict[str, Any],
    width: Optional[int] = None,
    height: Optional[int] = None,
    *,
    dtype: Any = np.uint8,
) -> np.ndarray:
    """Render a scene (a dict as :func:`read` returns it) as an H×W×3 array.

    ``width`` and ``height`` default to the scene's stored size, and one of them alone
    keeps its aspect ratio, as in :func:`decode`; ``render(read(f), w, h)`` gives exactly
    ``decode(f, width=w, height=h)``. Values are taken as float32; ``opacity`` and
    ``tone`` may be None, and ``weights`` left out is ``"columns-32"``.
    """
    dt = np.dtype(dtype)
    if dt not in (np.uint8, np.float32, np.float64):
        raise Error(f"dtype {dt}: expected uint8, float32 or float64")
    def f32(name: str, k: int) -> bytes:
        a = np.asarray(scene[name], dtype=np.float32)
        if a.ndim != 2 or a.shape[1] != k:
            raise Error(f"{name} of shape {a.shape}: expected N×{k}")
        return np.ascontiguousarray(a).tobytes()

    opacity = scene.get("opacity")
    if opacity is not None:
        opacity = np.ascontiguousarray(np.asarray(opacity, dtype=np.float32).reshape(-1)).tobytes()
    tone = scene.get("tone")
    if tone is not None:
        t = np.asarray(tone)
        if t.dtype != np.uint16 or t.ndim != 2:
            raise Error(f"tone of dtype {t.dtype} and shape {t.shape}: expected uint16, curves×knots")
        tone = (t.shape[0], t.reshape(-1).tolist())
    pixels, w, h = _gsi.render(
        int(scene["width"]),
        int(scene["height"]),
        str(scene["blend"]),
        str(scene["cov_param"]),
        str(scene.get("weights", "columns-32")),
        f32("positions", 2),
        f32("cov", 3),
        f32("colors", 3),
        opacity,
        tone,
        width,
        height,
        dt != np.uint8,
    )
    return _pixels(pixels, w, h, dt)
