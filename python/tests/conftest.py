"""Shared fixtures: small deterministic images, and the `gsi` command-line tool whose bytes
and pixels the package must reproduce.

The tool is `$GSI_CLI` when set (CI sets it, so these tests cannot skip there), else the
newest of `target/{debug,release}/gsi` in the repository; without one the tests that
compare with it are skipped, saying so.
"""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import gsi

REPO = Path(__file__).resolve().parents[2]


def find_cli():
    named = os.environ.get("GSI_CLI")
    if named:
        path = Path(named)
        if not path.is_absolute():
            path = REPO / path
        if not path.exists():
            raise FileNotFoundError(f"GSI_CLI={named}: no such file")
        return path
    found = [REPO / "target" / p / "gsi" for p in ("debug", "release")]
    found = [p for p in found if p.exists()]
    return max(found, key=lambda p: p.stat().st_mtime) if found else None


@pytest.fixture(scope="session")
def cli():
    path = find_cli()
    if path is None:
        pytest.skip("no gsi binary: build it (cargo build) or set GSI_CLI")

    def run(*args, check=True):
        return subprocess.run(
            [str(path), *map(str, args)], capture_output=True, check=check, timeout=600
        )

    return run


def scene_image(h=48, w=64, seed=0, level=1.0):
    """An 8-bit RGB test image with edges, gradients and texture, scaled by `level`."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack(
        [
            0.5 + 0.4 * np.sin(x / 7.0),
            0.3 + 0.5 * (y / h),
            0.2 + 0.6 * ((x - w / 2) ** 2 + (y - h / 2) ** 2 < (h / 3) ** 2),
        ],
        axis=2,
    )
    img += 0.05 * rng.standard_normal(img.shape).astype(np.float32)
    return np.clip(img * level * 255 + 0.5, 0, 255).astype(np.uint8)


@pytest.fixture(scope="session")
def image():
    return scene_image()


@pytest.fixture(scope="session")
def encoded(image):
    return gsi.encode(image, gaussians=150, effort=3)


@pytest.fixture(scope="session")
def dark_encoded():
    """A low-light file (mean luma about 0.06), as stage 2 is meant for."""
    return gsi.encode(scene_image(seed=1, level=0.12), gaussians=150, effort=3)
