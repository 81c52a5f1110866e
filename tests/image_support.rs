//! The decoder as an embedder meets it: the one-call decode, the buffer `Reader` with its
//! limits, and `image::open` of a `.gsi` file through `gsi::image_support`.

use gsi::format::{BitDepths, WriteOptions};
use gsi::model::Blend;
use gsi::synth::{random_scene, SceneSpec};
use gsi::{Limits, PixelFormat, Reader};

/// A 48×32 file of 60 random Gaussians, and what the decoder's float renderer makes of it
/// at `w × h` in 8-bit RGB.
fn file(blend: Blend) -> Vec<u8> {
    let scene = random_scene(11, SceneSpec::new(48, 32, 60, blend));
    let records = gsi::format::Records::from_scene(&scene, BitDepths::default());
    gsi::format::to_bytes(&records, &WriteOptions::default()).unwrap()
}

fn reference(bytes: &[u8], w: u32, h: u32) -> Vec<u8> {
    let f = gsi::format::read_file(bytes, Limits::default()).unwrap();
    gsi::render(&f.records.to_scene(), w, h).unwrap().to_rgb8()
}

#[test]
fn one_call_decode_gives_the_renderers_pixels_at_any_size() {
    for blend in [Blend::Sum, Blend::Alpha] {
        let bytes = file(blend);
        for (w, h) in [(48, 32), (97, 13), (1, 1), (300, 200)] {
            let img = gsi::decode(&bytes[..], w, h).unwrap();
            assert_eq!(
                (img.width, img.height, img.format),
                (w, h, PixelFormat::Rgb8)
            );
            assert_eq!(img.data, reference(&bytes, w, h), "{blend:?} {w}x{h}");
        }
    }
}

#[test]
fn reader_fills_a_callers_buffer_in_each_format() {
    let bytes = file(Blend::Alpha);
    let mut r = Reader::new(&bytes[..]).unwrap();
    assert_eq!(r.output_size(), (48, 32));
    r.set_output_size(70, 41).unwrap();
    let rgb = reference(&bytes, 70, 41);

    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    r.read_image(&mut buf).unwrap();
    assert_eq!(buf, rgb);

    r.set_pixel_format(PixelFormat::Rgba8);
    let mut rgba = vec![0u8; r.output_buffer_size().unwrap()];
    assert_eq!(rgba.len(), 70 * 41 * 4);
    r.read_image(&mut rgba).unwrap();
    for (a, b) in rgba.chunks_exact(4).zip(rgb.chunks_exact(3)) {
        assert_eq!((&a[..3], a[3]), (b, 255));
    }

    r.set_pixel_format(PixelFormat::RgbF32);
    let mut raw = vec![0u8; r.output_buffer_size().unwrap()];
    r.read_image(&mut raw).unwrap();
    let want = gsi::render(r.scene(), 70, 41).unwrap().data;
    let got: Vec<f32> = raw
        .chunks_exact(4)
        .map(|b| f32::from_ne_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(got, want);

    // A buffer of the wrong size is an error, not a panic.
    let err = r.read_image(&mut raw[1..]).unwrap_err();
    assert_eq!(err.kind(), gsi::ErrorKind::InvalidValue);
}

#[test]
fn limits_bound_the_render_as_well_as_the_file() {
    let bytes = file(Blend::Sum);
    let limits = Limits {
        max_output_pixels: 10_000,
        ..Limits::default()
    };
    let mut r = Reader::with_limits(&bytes[..], limits).unwrap();
    assert_eq!(
        r.set_output_size(101, 100).unwrap_err().kind(),
        gsi::ErrorKind::LimitExceeded
    );
    assert!(r.set_output_size(100, 100).is_ok());
    assert_eq!(
        r.set_output_size(0, 100).unwrap_err().kind(),
        gsi::ErrorKind::InvalidValue
    );
    // The default limits refuse what no reasonable output needs, on the CPU as on the GPU.
    let huge = gsi::decode(&bytes[..], 1 << 16, 1 << 16).unwrap_err();
    assert_eq!(huge.kind(), gsi::ErrorKind::LimitExceeded);
    let scene = r.scene().clone();
    assert_eq!(
        gsi::render(&scene, 1 << 16, 1 << 16).unwrap_err().kind(),
        gsi::ErrorKind::LimitExceeded
    );
}

#[test]
fn image_open_reads_a_gsi_file() {
    gsi::image_support::register();
    // A second registration is refused, not a panic.
    assert!(!gsi::image_support::register());
    let dir = std::env::temp_dir().join(format!("gsi-image-open-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bytes = file(Blend::Alpha);

    let path = dir.join("scene.gsi");
    std::fs::write(&path, &bytes).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (48, 32));
    assert_eq!(img.into_raw(), reference(&bytes, 48, 32));

    // Found by its signature too, whatever the file is called.
    let odd = dir.join("scene.bin");
    std::fs::write(&odd, &bytes).unwrap();
    let img = image::ImageReader::open(&odd)
        .unwrap()
        .with_guessed_format()
        .unwrap()
        .decode()
        .unwrap();
    assert_eq!(img.to_rgb8().into_raw(), reference(&bytes, 48, 32));

    // A damaged file is an image error, not a panic.
    let mut bad = bytes.clone();
    let last = bad.len() - 20;
    bad[last] ^= 0xff;
    let broken = dir.join("broken.gsi");
    std::fs::write(&broken, &bad).unwrap();
    assert!(matches!(
        image::open(&broken),
        Err(image::ImageError::Decoding(_))
    ));

    // The caller's image limits hold.
    let mut reader = image::ImageReader::open(&path).unwrap();
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(40);
    reader.limits(limits);
    assert!(matches!(reader.decode(), Err(image::ImageError::Limits(_))));
    std::fs::remove_dir_all(&dir).unwrap();
}
