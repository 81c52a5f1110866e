"""The Python package against the command-line tool and against itself."""

import json
import threading
import time
import warnings

import numpy as np
import pytest
from PIL import Image

import gsi
from conftest import scene_image


# --- the same bytes and pixels as the command-line tool ---------------------------------


@pytest.mark.parametrize(
    "make",
    [
        lambda a: a,  # 8-bit RGB
        lambda a: a[:, :, 1],  # 8-bit grey
        lambda a: a[:, :, 0].astype(np.uint16) * 257 + 3,  # 16-bit grey
    ],
    ids=["rgb8", "grey8", "grey16"],
)
def test_encode_matches_the_cli(cli, tmp_path, image, make):
    array = make(image)
    png = tmp_path / "in.png"
    Image.fromarray(array).save(png)
    out = tmp_path / "out.gsi"
    cli("encode", png, "-o", out, "--gaussians", 120, "--effort", 2, "--seed", 7,
        "--device", "cpu", "--quiet")
    ours = gsi.encode(array, gaussians=120, effort=2, seed=7)
    assert ours == out.read_bytes()


def test_encode_bpp_and_alpha_match_the_cli(cli, tmp_path, image):
    png = tmp_path / "in.png"
    Image.fromarray(image).save(png)
    out = tmp_path / "out.gsi"
    cli("encode", png, "-o", out, "--bpp", 2.0, "--blend", "alpha", "--effort", 1,
        "--device", "cpu", "--quiet")
    assert gsi.encode(image, bpp=2.0, blend="alpha", effort=1) == out.read_bytes()


def test_encode_takes_the_cli_default_effort(cli, tmp_path, image):
    png = tmp_path / "in.png"
    Image.fromarray(image).save(png)
    out = tmp_path / "out.gsi"
    cli("encode", png, "-o", out, "--gaussians", 40, "--device", "cpu", "--quiet")
    assert gsi.encode(image, gaussians=40) == out.read_bytes()
    assert gsi.encode(image, gaussians=40, effort=1) != out.read_bytes()


def test_decode_matches_the_cli(cli, tmp_path, encoded):
    f = tmp_path / "x.gsi"
    f.write_bytes(encoded)
    for extra, size in [((), None), (("--width", 100), (100, None)), (("--height", 7), (None, 7))]:
        ppm = tmp_path / "x.ppm"
        cli("decode", f, "-o", ppm, "--device", "cpu", *extra)
        theirs = np.asarray(Image.open(ppm))
        kw = {} if size is None else {"width": size[0], "height": size[1]}
        ours = gsi.decode(encoded, **kw)
        assert ours.shape == theirs.shape and ours.dtype == np.uint8
        assert np.array_equal(ours, theirs)
    # A path works as well as the bytes.
    assert np.array_equal(gsi.decode(f), gsi.decode(encoded))
    assert np.array_equal(gsi.decode(str(f)), gsi.decode(encoded))


def test_info_is_the_clis_json(cli, tmp_path, dark_encoded):
    enhanced = gsi.enhance(dark_encoded)
    for data in (dark_encoded, enhanced):
        f = tmp_path / "x.gsi"
        f.write_bytes(data)
        theirs = json.loads(cli("info", f, "--json").stdout)
        assert gsi.info(data) == theirs
    assert gsi.info(enhanced)["enhancer"]["revertible"] is True


def test_enhance_matches_the_cli_and_reverts_exactly(cli, tmp_path, dark_encoded):
    f = tmp_path / "dark.gsi"
    f.write_bytes(dark_encoded)
    out = tmp_path / "enhanced.gsi"
    cli("enhance", f, "-o", out, "--device", "cpu", "--quiet")
    ours = gsi.enhance(dark_encoded)
    assert ours == out.read_bytes()
    assert ours != dark_encoded
    assert gsi.decode(ours).mean() > 2 * gsi.decode(dark_encoded).mean()
    assert gsi.revert(ours) == dark_encoded

    # An enhancer applied from another file, as --apply-from.
    other = gsi.encode(scene_image(seed=2, level=0.1), gaussians=150, effort=3)
    o = tmp_path / "other.gsi"
    o.write_bytes(other)
    applied = tmp_path / "applied.gsi"
    cli("enhance", o, "-o", applied, "--apply-from", out, "--quiet")
    assert gsi.enhance(other, apply_from=ours) == applied.read_bytes()

    # Options reach the fit: another exposure gives another file, as on the command line.
    brighter = tmp_path / "brighter.gsi"
    cli("enhance", f, "-o", brighter, "--exposure", 0.6, "--device", "cpu", "--quiet")
    assert gsi.enhance(dark_encoded, exposure=0.6) == brighter.read_bytes()
    kept = tmp_path / "kept.gsi"
    cli("enhance", f, "-o", kept, "--keep-speckle", "--device", "cpu", "--quiet")
    assert gsi.enhance(dark_encoded, speckle=True) == kept.read_bytes()
    assert gsi.info(kept.read_bytes())["enhancer"]["speckle"] is None
    assert gsi.enhance(f, discard_original=True) != ours
    with pytest.raises(gsi.Error, match="original colours"):
        gsi.revert(gsi.enhance(f, discard_original=True))


def test_a_bright_image_is_left_unchanged_with_a_warning(encoded):
    with pytest.warns(gsi.NotLowLightWarning, match="not a low-light image"):
        assert gsi.enhance(encoded) == encoded
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gsi.enhance(encoded, force=True, iterations=5) != encoded


def test_a_black_image_is_left_unchanged_with_a_warning():
    black = gsi.encode(np.zeros((24, 32, 3), np.uint8), gaussians=20, effort=1)
    with pytest.warns(gsi.NotLowLightWarning, match="the image is black.*nothing to lift"):
        assert gsi.enhance(black) == black


def test_errors_carry_the_clis_message(cli, tmp_path, encoded):
    cases = {
        "garbage": b"not a gsi file at all",
        "truncated": encoded[: len(encoded) // 2],
        "empty": b"",
    }
    for name, data in cases.items():
        f = tmp_path / f"{name}.gsi"
        f.write_bytes(data)
        stderr = cli("decode", f, "-o", tmp_path / "x.png", check=False).stderr.decode()
        for call in (gsi.decode, gsi.info, gsi.read, gsi.revert, gsi.enhance):
            with pytest.raises(gsi.Error) as e:
                call(data)
            assert isinstance(e.value, ValueError)
            assert str(e.value) in stderr, (name, call.__name__, str(e.value), stderr)
    with pytest.raises(gsi.Error, match="no such file|No such file"):
        gsi.decode(tmp_path / "missing.gsi")


# --- images in ---------------------------------------------------------------------------


def test_every_dtype_and_shape_gives_the_same_file(image):
    want = gsi.encode(image, gaussians=60, effort=1)
    f32 = image.astype(np.float32) / np.float32(255)
    assert gsi.encode(f32, gaussians=60, effort=1) == want
    rgba = np.concatenate([image, np.full(image.shape[:2] + (1,), 17, np.uint8)], axis=2)
    assert gsi.encode(rgba, gaussians=60, effort=1) == want
    # Non-contiguous views: a flipped view and a Fortran-ordered copy.
    flipped = image[:, ::-1]
    assert not flipped.flags.c_contiguous
    assert gsi.encode(flipped, gaussians=60, effort=1) == gsi.encode(
        np.ascontiguousarray(flipped), gaussians=60, effort=1
    )
    assert gsi.encode(np.asfortranarray(image), gaussians=60, effort=1) == want
    # Grey replicated, in two shapes.
    grey = image[:, :, 0]
    g = gsi.encode(grey, gaussians=60, effort=1)
    assert gsi.encode(grey[:, :, None], gaussians=60, effort=1) == g
    assert gsi.encode(np.repeat(grey[:, :, None], 3, axis=2), gaussians=60, effort=1) == g
    # 16-bit samples are v / 65535, as a float image of the same values.
    u16 = image.astype(np.uint16) * 250
    assert gsi.encode(u16, gaussians=60, effort=1) == gsi.encode(
        u16.astype(np.float32) / np.float32(65535), gaussians=60, effort=1
    )
    # float64 is taken as float32.
    assert gsi.encode(f32.astype(np.float64), gaussians=60, effort=1) == want


def test_bad_images_and_options_raise(image):
    bad = [
        (np.zeros((0, 0, 3), np.uint8), {}),
        (np.zeros((4, 4, 2), np.uint8), {}),
        (np.zeros((4, 4, 3), np.int64), {}),
        (np.full((4, 4, 3), 1.5, np.float32), {}),
        (np.full((4, 4, 3), np.nan, np.float32), {}),
        (image, {"gaussians": 0}),
        (image, {"bpp": -1.0}),
        (image, {"bpp": 1.0, "gaussians": 10}),
        (image, {"effort": 10}),
        (image, {"blend": "over"}),
        (image, {"device": "tpu"}),
    ]
    for array, kw in bad:
        with pytest.raises(gsi.Error):
            gsi.encode(array, **kw)


def test_a_one_pixel_image_round_trips():
    one = np.array([[[200, 40, 10]]], np.uint8)
    with pytest.raises(gsi.Error, match="cannot be met"):
        gsi.encode(one)  # 1 bpp is 1 bit: no file is that small
    data = gsi.encode(one, gaussians=1)
    out = gsi.decode(data)
    assert out.shape == (1, 1, 3)
    assert np.abs(out.astype(int) - one.astype(int)).max() <= 2
    assert gsi.decode(data, width=5).shape == (5, 5, 3)


# --- pixels out and Gaussians as arrays ---------------------------------------------------


def test_decode_at_any_size_and_in_float(encoded):
    for w, h in [(1, 1), (13, 200), (640, 480)]:
        assert gsi.decode(encoded, width=w, height=h).shape == (h, w, 3)
    assert gsi.decode(encoded, width=32).shape == (24, 32, 3)
    assert gsi.decode(encoded, height=96).shape == (96, 128, 3)
    f = gsi.decode(encoded, dtype=np.float32)
    assert f.dtype == np.float32 and np.isfinite(f).all()
    # uint8 is floor(clamp(c) * 255 + 0.5) of the float render.
    want = np.floor(np.clip(f, 0, 1) * np.float32(255) + np.float32(0.5)).astype(np.uint8)
    assert np.array_equal(gsi.decode(encoded), want)
    assert gsi.decode(encoded, dtype=np.float64).dtype == np.float64
    out = gsi.decode(encoded)
    out[0, 0] = 0  # writable
    for bad in [dict(width=0), dict(width=100000, height=100000), dict(dtype=np.int32)]:
        with pytest.raises(gsi.Error):
            gsi.decode(encoded, **bad)


def test_read_and_render_agree_with_decode(encoded, dark_encoded):
    enhanced = gsi.enhance(dark_encoded)
    alpha = gsi.encode(scene_image(), gaussians=80, effort=1, blend="alpha")
    for data in (encoded, enhanced, alpha):
        s = gsi.read(data)
        n = gsi.info(data)["gaussians"]
        assert s["positions"].shape == (n, 2) and s["positions"].dtype == np.float32
        assert s["cov"].shape == (n, 3) and s["covariance"].shape == (n, 2, 2)
        assert s["colors"].shape == (n, 3)
        assert np.array_equal(s["covariance"], s["covariance"].transpose(0, 2, 1))
        assert (np.linalg.det(s["covariance"].astype(np.float64)) >= 0).all()
        for size in [(None, None), (100, 75), (31, None)]:
            kw = dict(width=size[0], height=size[1])
            assert np.array_equal(gsi.render(s, *size), gsi.decode(data, **kw))
        assert np.array_equal(
            gsi.render(s, dtype=np.float32), gsi.decode(data, dtype=np.float32)
        )
    assert gsi.read(enhanced)["tone"] is not None and gsi.read(encoded)["tone"] is None
    assert gsi.read(alpha)["blend"] == "alpha" and gsi.read(alpha)["opacity"] is not None


@pytest.mark.parametrize(
    "name, weights",
    [
        ("sum-lsr-3000.gsi", "per-pixel"),
        ("columns-sum-lsr-800.gsi", "columns"),
        ("columns32-sum-lsr-800.gsi", "columns-32"),
    ],
)
def test_read_keeps_the_weight_rule_of_older_files(name, weights):
    from pathlib import Path

    data = (Path(__file__).resolve().parents[2] / "corpus" / "valid" / name).read_bytes()
    s = gsi.read(data)
    assert s["weights"] == weights
    assert np.array_equal(gsi.render(s, dtype=np.float32), gsi.decode(data, dtype=np.float32))
    other = dict(s, weights="columns" if weights == "per-pixel" else "per-pixel")
    assert not np.array_equal(
        gsi.render(other, dtype=np.float32), gsi.decode(data, dtype=np.float32)
    )
    with pytest.raises(gsi.Error, match="weights"):
        gsi.render(dict(s, weights="rows"))


def test_an_edited_scene_renders_the_edit(encoded):
    s = gsi.read(encoded)
    s["colors"][:] = 0
    assert gsi.render(s).max() == 0
    s = gsi.read(encoded)
    keep = s["positions"][:, 0] < 0.5  # only the left half's Gaussians
    half = {k: (v[keep] if isinstance(v, np.ndarray) and len(v) == len(keep) else v)
            for k, v in s.items()}
    right = gsi.render(half)[:, 48:]
    assert right.mean() < gsi.decode(encoded)[:, 48:].mean() / 2
    s["positions"][0, 0] = np.nan
    with pytest.raises(gsi.Error, match="finite"):
        gsi.render(s)


# --- the call itself ---------------------------------------------------------------------


def test_progress_is_reported_and_its_exceptions_raised(image):
    seen = []
    gsi.encode(image, gaussians=60, effort=1, progress=seen.append)
    assert seen and all(d["stage"] == "encode" for d in seen)
    assert 0 <= seen[-1]["work"] <= 1 and seen[-1]["gaussians"] > 0

    def fail(d):
        raise RuntimeError("stop")

    with pytest.raises(RuntimeError, match="stop"):
        gsi.encode(image, gaussians=60, effort=1, progress=fail)


def test_the_gil_is_released(image):
    big = scene_image(h=240, w=320)
    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=tick)
    t.start()
    start = time.perf_counter()
    try:
        gsi.encode(big, gaussians=400, effort=2)
    finally:
        end = time.perf_counter()
        done.set()
        t.join()
    during = [x for x in ticks if start < x < end]
    # The other thread ran all through the encode, not only before and after it.
    assert len(during) > 10 and (end - start) > 0.05
