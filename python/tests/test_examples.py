"""The rate-distortion example runs on a folder and measures what it prints."""

import sys
from pathlib import Path

import numpy as np
from PIL import Image

from conftest import scene_image

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import rate_distortion  # noqa: E402


def test_rate_distortion_on_a_folder(tmp_path, capsys):
    for seed in (0, 1):
        Image.fromarray(scene_image(seed=seed)).save(tmp_path / f"{seed}.png")
    (tmp_path / "notes.txt").write_text("not an image")
    plot = tmp_path / "rd.png"
    assert rate_distortion.main([str(tmp_path), "--bpp", "2", "4", "--effort", "1",
                                 "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    means = [float(line.split(":")[1].split()[0]) for line in out.splitlines()
             if line.startswith("mean at")]
    assert len(means) == 2 and means[1] > means[0] > 20
    try:
        import matplotlib  # noqa: F401
        assert plot.exists() and Image.open(plot).size[0] > 100
    except ImportError:
        assert "no plot" in out
