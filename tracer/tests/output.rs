//! EXR and PNG output: round trips, what other readers see, tile validation, previews.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::path::PathBuf;

use exr::prelude::{
    read_all_flat_layers_from_file, AnyChannel, AnyChannels, Compression, Encoding, FlatSamples,
    Image, ImageAttributes, IntegerBounds, Layer, LayerAttributes, Vec2, WritableImage,
};
use glam::{Vec3, Vec4};
use tracer::film::{Layers, TileRect, NO_HIT_DEPTH};
use tracer::output::{
    aces_filmic, check_finite, decode_exr, encode_exr, encode_exr_layers, encode_preview_png,
    read_exr, srgb_oetf, validate_tile, write_exr, write_preview_png, ExrCompression, ExrMetadata,
    ImageLayer, OutputError, CHANNEL_NAMES, DENOISED_CHANNELS,
};

/// A fresh, empty folder for one test.
fn temp_dir(test: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("output-tests")
        .join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every value of every layer, as bits (equality would let -0.0 pass for 0.0).
fn bits(l: &Layers) -> Vec<u32> {
    (l.beauty.iter().flat_map(|v| v.to_array()))
        .chain(l.albedo.iter().flat_map(|v| v.to_array()))
        .chain(l.normal.iter().flat_map(|v| v.to_array()))
        .chain(l.depth.iter().copied())
        .map(f32::to_bits)
        .collect()
}

/// Layers whose every value differs and is hard to round: fractions, negatives, tiny and
/// huge numbers, the no-hit depth.
fn sample_layers(rect: TileRect) -> Layers {
    let mut l = Layers::new(rect);
    for i in 0..rect.area() {
        let f = i as f32;
        l.beauty[i] = Vec4::new(f * 0.1 + 1e-3, 1.0 / (f + 3.0), f * 17.25, (i % 2) as f32);
        l.albedo[i] = Vec3::new(0.2 + f * 1e-4, 0.5, 0.7 - f * 1e-5);
        l.normal[i] = Vec3::new(f.sin(), f.cos(), -0.0).normalize_or_zero();
        l.depth[i] = if i % 3 == 0 {
            NO_HIT_DEPTH
        } else {
            1.5 + f * 0.01
        };
    }
    l.beauty[0].x = 1e-40; // a denormal survives f32 storage exactly
    l.albedo[0].y = -0.25;
    l
}

fn meta() -> ExrMetadata {
    ExrMetadata::new()
        .with(ExrMetadata::VERSION, "0.1.0")
        .with(ExrMetadata::SPP, "64")
        .with(ExrMetadata::SETTINGS, r#"{"spp":64,"max_depth":8}"#)
        .with(ExrMetadata::FEATURES, "lights,textures")
}

/// An EXR written by the `exr` crate directly, with only the given channels.
fn foreign_exr(frame: (u32, u32), rect: TileRect, channels: &[&str]) -> Vec<u8> {
    let n = rect.area();
    let list = channels
        .iter()
        .map(|&name| AnyChannel::new(name, FlatSamples::F32(vec![0.5; n])))
        .collect();
    let attributes = LayerAttributes {
        layer_position: Vec2(rect.x as i32, rect.y as i32),
        ..LayerAttributes::default()
    };
    let layer = Layer::new(
        Vec2(rect.width as usize, rect.height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let display = IntegerBounds::new(Vec2(0, 0), Vec2(frame.0 as usize, frame.1 as usize));
    let image = Image::new(ImageAttributes::new(display), layer);
    let mut out = std::io::Cursor::new(Vec::new());
    image.write().to_buffered(&mut out).unwrap();
    out.into_inner()
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = temp_dir("round_trip");
    let path = dir.join("frame.0001.exr");
    let layers = sample_layers(TileRect::new(0, 0, 37, 21));
    write_exr(&path, (37, 21), &layers, &meta()).unwrap();

    let back = read_exr(&path).unwrap();
    assert_eq!(back.frame_size, (37, 21));
    assert_eq!(back.layers.rect, layers.rect);
    assert_eq!(bits(&back.layers), bits(&layers));
    assert_eq!(back.layers, layers);

    for (name, value) in &meta().attributes {
        assert_eq!(
            back.attribute(name),
            Some(value.as_str()),
            "attribute {name}"
        );
    }
    assert!(back.attribute("software").unwrap().starts_with("Tessera "));
}

#[test]
fn uncompressed_exr_round_trips_exactly_and_says_so() {
    let layers = sample_layers(TileRect::new(3, 2, 37, 21));
    let encode =
        |c| encode_exr_layers((64, 32), &layers, &meta(), &ImageLayer::RENDERED, c).unwrap();
    let (zip, raw) = (
        encode(ExrCompression::Zip),
        encode(ExrCompression::Uncompressed),
    );
    let back = decode_exr(&raw).unwrap();
    assert_eq!((back.frame_size, back.layers.rect), ((64, 32), layers.rect));
    assert_eq!(bits(&back.layers), bits(&layers));
    assert_eq!(back.attribute(ExrMetadata::SPP), Some("64"));
    // 13 f32 channels of 37x21 pixels are 40 KB raw; ZIP must have done something.
    assert!(raw.len() > 13 * 4 * 37 * 21, "{} bytes", raw.len());
    assert!(
        zip.len() < raw.len() * 3 / 4,
        "{} against {}",
        zip.len(),
        raw.len()
    );
    // What another reader sees.
    let dir = temp_dir("uncompressed");
    std::fs::write(dir.join("raw.exr"), &raw).unwrap();
    let image = read_all_flat_layers_from_file(dir.join("raw.exr")).unwrap();
    assert_eq!(
        image.layer_data[0].encoding.compression,
        Compression::Uncompressed
    );
}

#[test]
fn region_keeps_the_frame_as_display_window_and_the_region_as_data_window() {
    let dir = temp_dir("region");
    let path = dir.join("region.exr");
    let rect = TileRect::new(5, 3, 7, 4);
    write_exr(&path, (20, 10), &sample_layers(rect), &meta()).unwrap();

    let back = read_exr(&path).unwrap();
    assert_eq!(back.frame_size, (20, 10));
    assert_eq!(back.layers.rect, rect);

    // What another reader sees: OpenEXR's windows are inclusive pixel bounds.
    let image = read_all_flat_layers_from_file(&path).unwrap();
    assert_eq!(image.attributes.display_window.position, Vec2(0, 0));
    assert_eq!(image.attributes.display_window.size, Vec2(20, 10));
    assert_eq!(image.attributes.display_window.max(), Vec2(19, 9));
    let layer = &image.layer_data[0];
    assert_eq!(layer.attributes.layer_position, Vec2(5, 3));
    assert_eq!(layer.size, Vec2(7, 4));
}

#[test]
fn an_independent_reader_sees_the_channel_names_in_f32_zip() {
    let dir = temp_dir("independent");
    let path = dir.join("frame.exr");
    let layers = sample_layers(TileRect::new(0, 0, 8, 5));
    write_exr(&path, (8, 5), &layers, &meta()).unwrap();

    let image = read_all_flat_layers_from_file(&path).unwrap();
    assert_eq!(image.layer_data.len(), 1, "one part");
    let layer = &image.layer_data[0];
    assert_eq!(layer.encoding.compression, Compression::ZIP16);
    let mut names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    names.sort();
    let mut expected: Vec<String> = CHANNEL_NAMES.iter().map(|s| s.to_string()).collect();
    expected.sort();
    assert_eq!(names, expected);
    for channel in &layer.channel_data.list {
        assert!(
            matches!(channel.sample_data, FlatSamples::F32(_)),
            "{} is not f32",
            channel.name
        );
    }
    // Spot check: pixel 7 of `R` and of `Z` as the independent reader decodes them.
    let channel = |name: &str| {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.eq(name))
            .unwrap();
        c.sample_data.values_as_f32().collect::<Vec<f32>>()
    };
    assert_eq!(channel("R")[7], layers.beauty[7].x);
    assert_eq!(channel("N.Y")[7], layers.normal[7].y);
    assert_eq!(channel("Z")[7], layers.depth[7]);
    let other = &layer.attributes.other;
    assert!(
        other.keys().any(|k| k.eq("tessera/spp")),
        "custom attributes: {other:?}"
    );
}

#[test]
fn attributes_keep_utf8_long_names_and_standard_text_attributes() {
    let meta = ExrMetadata::new()
        .with("comments", "rendered by the farm")
        .with("tessera/a-name-longer-than-thirty-one-bytes", "long")
        .with("tessera/camera", "Caméra ✓");
    let layers = sample_layers(TileRect::new(0, 0, 2, 2));
    let back = decode_exr(&encode_exr((2, 2), &layers, &meta).unwrap()).unwrap();
    assert_eq!(back.attribute("comments"), Some("rendered by the farm"));
    assert_eq!(
        back.attribute("tessera/a-name-longer-than-thirty-one-bytes"),
        Some("long")
    );
    assert_eq!(back.attribute("tessera/camera"), Some("Caméra ✓"));
    let sorted = back.attributes.windows(2).all(|w| w[0].0 <= w[1].0);
    assert!(sorted, "{:?}", back.attributes);

    let overridden = ExrMetadata::new().with("software", "mine");
    let back = decode_exr(&encode_exr((2, 2), &layers, &overridden).unwrap()).unwrap();
    assert_eq!(back.attribute("software"), Some("mine"));
}

#[test]
fn metadata_set_replaces_and_bad_names_are_refused() {
    let mut meta = ExrMetadata::new().with("a", "1");
    meta.set("a", "2");
    assert_eq!(meta.attributes, [("a".to_string(), "2".to_string())]);
    assert_eq!(meta.get("a"), Some("2"));

    let layers = sample_layers(TileRect::new(0, 0, 2, 2));
    let refused = |meta: ExrMetadata| match encode_exr((2, 2), &layers, &meta) {
        Err(OutputError::BadAttribute { name, .. }) => name,
        other => panic!("expected BadAttribute, got {other:?}"),
    };
    assert_eq!(
        refused(ExrMetadata::new().with("dataWindow", "0")),
        "dataWindow"
    );
    assert_eq!(refused(ExrMetadata::new().with("", "x")), "");
    assert_eq!(
        refused(ExrMetadata::new().with("x".repeat(256), "x")),
        "x".repeat(256)
    );
    let twice = ExrMetadata {
        attributes: vec![("k".into(), "1".into()), ("k".into(), "2".into())],
    };
    assert_eq!(refused(twice), "k");
}

#[test]
fn encoding_refuses_layers_that_do_not_match_their_rectangle() {
    let mut layers = sample_layers(TileRect::new(0, 0, 4, 4));
    assert!(matches!(
        encode_exr((3, 4), &layers, &meta()),
        Err(OutputError::BadWindow(m)) if m.contains("outside")
    ));
    assert!(matches!(
        encode_exr((0, 4), &layers, &meta()),
        Err(OutputError::BadWindow(_))
    ));
    let empty = Layers::new(TileRect::new(0, 0, 0, 4));
    assert!(matches!(
        encode_exr((4, 4), &empty, &meta()),
        Err(OutputError::BadWindow(_))
    ));
    layers.depth.pop();
    let err = encode_exr((4, 4), &layers, &meta()).unwrap_err();
    assert!(matches!(
        err,
        OutputError::LayerSize {
            layer: "depth",
            len: 15,
            expected: 16,
            ..
        }
    ));
}

#[test]
fn rgba_only_files_read_with_default_layers() {
    let rect = TileRect::new(1, 2, 3, 2);
    let back = decode_exr(&foreign_exr((6, 6), rect, &["R", "G", "B", "A"])).unwrap();
    assert_eq!(back.frame_size, (6, 6));
    assert_eq!(back.layers.rect, rect);
    assert!(back.layers.beauty.iter().all(|&b| b == Vec4::splat(0.5)));
    assert!(back.layers.albedo.iter().all(|&a| a == Vec3::ZERO));
    assert!(back.layers.normal.iter().all(|&n| n == Vec3::ZERO));
    assert!(back.layers.depth.iter().all(|&d| d == NO_HIT_DEPTH));

    let rgb = decode_exr(&foreign_exr((6, 6), rect, &["R", "G", "B"])).unwrap();
    assert!(
        rgb.layers
            .beauty
            .iter()
            .all(|&b| b == Vec4::new(0.5, 0.5, 0.5, 1.0)),
        "opaque"
    );

    let err = decode_exr(&foreign_exr((6, 6), rect, &["Y"])).unwrap_err();
    assert!(matches!(&err, OutputError::MissingChannel { channel, .. } if channel == "R"));
    assert!(err.to_string().contains("channels present: Y"), "{err}");
}

#[test]
fn validate_tile_accepts_a_worker_tile() {
    let rect = TileRect::new(64, 32, 64, 16);
    let layers = sample_layers(rect);
    let bytes = encode_exr((200, 100), &layers, &meta()).unwrap();
    assert_eq!(validate_tile(&bytes, rect, (200, 100)).unwrap(), layers);
}

#[test]
fn validate_tile_rejects_corrupt_bytes() {
    let rect = TileRect::new(0, 0, 16, 16);
    let bytes = encode_exr((16, 16), &sample_layers(rect), &meta()).unwrap();
    let corrupt = |b: &[u8]| match validate_tile(b, rect, (16, 16)) {
        Err(e @ OutputError::Corrupt(_)) => e.to_string(),
        other => panic!("expected Corrupt, got {other:?}"),
    };
    let message = corrupt(&[]);
    assert!(
        message.starts_with("not a readable OpenEXR image: "),
        "{message}"
    );
    corrupt(b"not an exr file at all");
    corrupt(&bytes[..bytes.len() / 2]);
    corrupt(&bytes[..bytes.len() - 1]);
    let mut bad_magic = bytes.clone();
    bad_magic[0] ^= 0xff;
    corrupt(&bad_magic);
}

#[test]
fn validate_tile_rejects_a_wrong_window() {
    let rect = TileRect::new(16, 0, 16, 16);
    let bytes = encode_exr((64, 32), &sample_layers(rect), &meta()).unwrap();

    let wrong_place = TileRect::new(0, 0, 16, 16);
    let err = validate_tile(&bytes, wrong_place, (64, 32)).unwrap_err();
    assert!(matches!(err, OutputError::WrongDataWindow { found, .. } if found == rect));
    assert_eq!(
        err.to_string(),
        "data window is 16x16 at (16, 0) but the tile is 16x16 at (0, 0)"
    );

    let wrong_size = TileRect::new(16, 0, 16, 8);
    assert!(matches!(
        validate_tile(&bytes, wrong_size, (64, 32)),
        Err(OutputError::WrongDataWindow { .. })
    ));
    let err = validate_tile(&bytes, rect, (64, 64)).unwrap_err();
    assert!(
        matches!(
            err,
            OutputError::WrongFrameSize {
                found: (64, 32),
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn validate_tile_rejects_missing_channels() {
    let rect = TileRect::new(0, 0, 8, 8);
    let bytes = foreign_exr((8, 8), rect, &["A", "B", "G", "R"]);
    let err = validate_tile(&bytes, rect, (8, 8)).unwrap_err();
    assert!(
        matches!(&err, OutputError::MissingChannel { channel, .. } if channel == "albedo.R"),
        "{err}"
    );
    let all_but_z: Vec<&str> = CHANNEL_NAMES
        .iter()
        .copied()
        .filter(|&c| c != "Z")
        .collect();
    let err = validate_tile(&foreign_exr((8, 8), rect, &all_but_z), rect, (8, 8)).unwrap_err();
    assert!(err.to_string().starts_with("no channel `Z`"), "{err}");
}

#[test]
fn validate_tile_rejects_nan_and_infinity_naming_channel_and_pixel() {
    let rect = TileRect::new(10, 20, 4, 3);
    let mut layers = sample_layers(rect);
    layers.albedo[4 + 2].y = f32::NAN; // row 1, column 2 of the tile
    let bytes = encode_exr((40, 40), &layers, &meta()).unwrap();
    let err = validate_tile(&bytes, rect, (40, 40)).unwrap_err();
    assert!(
        matches!(
            err,
            OutputError::NonFinite {
                channel: "albedo.G",
                x: 12,
                y: 21,
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(
        err.to_string(),
        "channel `albedo.G` holds NaN at pixel (12, 21)"
    );
    let before_upload = check_finite(&layers).unwrap_err();
    assert_eq!(
        before_upload.to_string(),
        err.to_string(),
        "workers can check first"
    );

    let mut layers = sample_layers(rect);
    layers.depth[11] = f32::INFINITY;
    let bytes = encode_exr((40, 40), &layers, &meta()).unwrap();
    let err = validate_tile(&bytes, rect, (40, 40)).unwrap_err();
    assert_eq!(err.to_string(), "channel `Z` holds inf at pixel (13, 22)");
}

#[test]
fn read_errors_name_the_file() {
    let dir = temp_dir("read_errors");
    let missing = dir.join("missing.exr");
    let err = read_exr(&missing).unwrap_err();
    assert!(matches!(err, OutputError::Io { .. }));
    assert!(err.to_string().contains("missing.exr"), "{err}");

    let garbage = dir.join("garbage.exr");
    std::fs::write(&garbage, b"garbage").unwrap();
    let err = read_exr(&garbage).unwrap_err();
    assert!(
        err.to_string()
            .contains("garbage.exr: not a readable OpenEXR image"),
        "{err}"
    );
}

#[test]
fn writes_are_atomic_and_leave_only_the_file() {
    let dir = temp_dir("atomic");
    let layers = sample_layers(TileRect::new(0, 0, 4, 4));
    write_exr(&dir.join("f.exr"), (4, 4), &layers, &meta()).unwrap();
    write_exr(&dir.join("f.exr"), (4, 4), &layers, &meta()).unwrap();
    write_preview_png(&dir.join("f.png"), (4, 4), &layers, 0.0).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["f.exr", "f.png"]);
}

#[test]
fn aces_curve_is_zero_at_zero_monotone_and_saturates_below_one() {
    assert_eq!(aces_filmic(0.0), 0.0);
    let grey = 0.18_f64;
    let expected = grey * (2.51 * grey + 0.03) / (grey * (2.43 * grey + 0.59) + 0.14);
    assert!((aces_filmic(0.18) as f64 - expected).abs() < 1e-6);
    assert!((expected - 0.266_899).abs() < 1e-6);
    let mut last = 0.0;
    for i in 1..100_000 {
        let y = aces_filmic(i as f32 * 1e-4);
        assert!(y >= last && y <= 1.0);
        last = y;
    }
    assert_eq!(aces_filmic(1e6), 1.0);
}

#[test]
fn png_preview_has_the_frame_size_and_transparent_outside_the_region() {
    let dir = temp_dir("png");
    let path = dir.join("preview.png");
    let rect = TileRect::new(2, 1, 3, 2);
    let mut layers = Layers::new(rect);
    layers.beauty.fill(Vec4::new(0.18, 0.0, 100.0, 0.0));
    write_preview_png(&path, (8, 4), &layers, 0.0).unwrap();

    let png = image::open(&path).unwrap().to_rgba8();
    assert_eq!(png.dimensions(), (8, 4));
    let grey = (srgb_oetf(aces_filmic(0.18)) * 255.0).round() as u8;
    assert_eq!(
        grey, 141,
        "mid-grey 0.18 -> ACES 0.2669 -> sRGB 0.5535 -> 141"
    );
    assert_eq!(png.get_pixel(2, 1).0, [grey, 0, 255, 255]);
    assert_eq!(png.get_pixel(4, 2).0, [grey, 0, 255, 255]);
    assert_eq!(png.get_pixel(0, 0).0[3], 0, "outside the region");
    assert_eq!(png.get_pixel(5, 1).0[3], 0, "right of the region");
    assert_eq!(png.get_pixel(2, 3).0[3], 0, "below the region");

    // One stop up doubles the linear value before the curve.
    let bytes = encode_preview_png((8, 4), &layers, 1.0).unwrap();
    let brighter = image::load_from_memory(&bytes).unwrap().to_rgba8();
    let expected = (srgb_oetf(aces_filmic(0.36)) * 255.0).round() as u8;
    assert_eq!(brighter.get_pixel(3, 2).0[0], expected);
}

/// Layers of `rect` with a denoised beauty unlike the noisy one.
fn denoised_layers(rect: TileRect) -> Layers {
    let mut l = sample_layers(rect);
    l.denoised = (0..rect.area())
        .map(|i| Vec3::new(0.25 + i as f32 * 1e-3, 0.5, 1e-7))
        .collect();
    l
}

#[test]
fn the_denoised_layer_round_trips_beside_the_noisy_beauty() {
    let rect = TileRect::new(0, 0, 24, 17);
    let layers = denoised_layers(rect);
    let bytes = encode_exr((24, 17), &layers, &meta()).unwrap();
    let back = decode_exr(&bytes).unwrap();
    assert_eq!(back.layers, layers);
    assert_eq!(
        bits(&back.layers),
        bits(&layers),
        "the noisy layers are kept"
    );

    // An independent reader sees the denoised channels by their names.
    let path = temp_dir("denoised").join("frame.exr");
    write_exr(&path, (24, 17), &layers, &meta()).unwrap();
    let image = read_all_flat_layers_from_file(&path).unwrap();
    let names: Vec<String> = image.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for name in DENOISED_CHANNELS.iter().chain(CHANNEL_NAMES.iter()) {
        assert!(names.iter().any(|n| n == name), "{name} in {names:?}");
    }

    // Layers without it write no denoised channels, and read back without it.
    let plain = sample_layers(rect);
    let back = decode_exr(&encode_exr((24, 17), &plain, &meta()).unwrap()).unwrap();
    assert!(back.layers.denoised.is_empty());
}

#[test]
fn a_tile_with_a_denoised_layer_is_refused() {
    let rect = TileRect::new(8, 0, 8, 8);
    let bytes = encode_exr((32, 8), &denoised_layers(rect), &meta()).unwrap();
    let err = validate_tile(&bytes, rect, (32, 8)).unwrap_err();
    assert!(err.to_string().contains("denoised"), "{err}");
}

#[test]
fn the_preview_shows_the_denoised_beauty_where_there_is_one() {
    let rect = TileRect::new(0, 0, 4, 4);
    let mut layers = sample_layers(rect);
    let noisy = encode_preview_png((4, 4), &layers, 0.0).unwrap();
    layers.denoised = vec![Vec3::new(0.18, 0.18, 0.18); rect.area()];
    let clean = encode_preview_png((4, 4), &layers, 0.0).unwrap();
    assert_ne!(noisy, clean);
    let image = image::load_from_memory(&clean).unwrap().to_rgba8();
    let grey = image.get_pixel(2, 2).0;
    assert_eq!(grey[0], grey[1]);
    assert_eq!(grey[1], grey[2]);
    let expected = (srgb_oetf(aces_filmic(0.18)) * 255.0).round() as u8;
    assert_eq!(grey[0], expected);
}

#[test]
fn frames_written_in_bands_need_the_denoised_layer_they_declare() {
    use tracer::output::{write_frame_in_bands, ExrTarget};
    let dir = temp_dir("denoised-bands");
    let path = dir.join("frame.exr");
    let frame = (16, 40);
    let whole = denoised_layers(TileRect::new(0, 0, 16, 40));
    let target = ExrTarget {
        path: &path,
        meta: &meta(),
        layers: &ImageLayer::ALL,
        compression: ExrCompression::Zip,
    };
    write_frame_in_bands(frame, 16, Some(target), None, |band| {
        Ok::<_, OutputError>(whole.crop(band))
    })
    .unwrap();
    assert_eq!(read_exr(&path).unwrap().layers, whole);

    let err = write_frame_in_bands(frame, 16, Some(target), None, |band| {
        Ok::<_, OutputError>(sample_layers(band))
    })
    .unwrap_err();
    assert!(err.to_string().contains("denoised"), "{err}");
}
