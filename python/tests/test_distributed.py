"""examples/dask_folder.py on a dask LocalCluster of two worker processes: the files it
writes are byte-identical to the single-process calls, and a file that fails is reported
while the others are written.

dask.distributed is optional: without it this module is skipped, unless
GSI_REQUIRE_DASK=1 (CI installs it and sets that, so the test cannot skip there).
"""

import os
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import gsi
from conftest import scene_image

if os.environ.get("GSI_REQUIRE_DASK") != "1":
    pytest.importorskip("distributed")
from dask.distributed import Client, LocalCluster  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import dask_folder as example  # noqa: E402


def test_a_folder_on_a_local_cluster(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    images = {
        "bright": scene_image(seed=3),
        "dark": scene_image(seed=4, level=0.1),
        "grey": scene_image(seed=5)[:, :, 0],
    }
    for name, array in images.items():
        Image.fromarray(array).save(folder / f"{name}.png")
    (folder / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n but not really")
    paths = sorted(str(p) for p in folder.iterdir())
    out = tmp_path / "out"

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        failed = example.run(client, paths, out, bpp=3.0, enhance=True)

    assert list(failed) == [str(folder / "broken.png")]
    assert "UnidentifiedImageError" in failed[str(folder / "broken.png")]
    for name in images:
        data = gsi.encode(example.load(str(folder / f"{name}.png")), bpp=3.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", gsi.NotLowLightWarning)
            want = gsi.enhance(data)
        assert (out / f"{name}.gsi").read_bytes() == want, name
    # The dark one was enhanced, the bright one left as encoded.
    assert gsi.info(out / "dark.gsi")["enhancer"] is not None
    assert gsi.info(out / "bright.gsi")["enhancer"] is None
    assert sorted(p.name for p in out.iterdir()) == ["bright.gsi", "dark.gsi", "grey.gsi"]
